"""``imubench allan|fit|gap`` over many recordings: each command's per-file call as one
task per recording and channel (:func:`~imubench.batchrun.runner.run_recordings`), the
per-recording reports the command writes for one file, and one table.

Written into ``--out-dir``:

- ``allan``: ``<recording>.<channel>.<stat>.json`` (what ``allan --json`` writes for that
  channel) and ``allan.csv`` / ``allan.json`` (one row per recording, channel and tau);
- ``fit``: ``<recording>.toml`` and ``<recording>.json`` (what ``fit -o --json`` write)
  and ``fit.csv`` / ``fit.json`` (one row per recording and channel);
- ``gap``: ``<recording>.gap.json`` (what ``gap --json`` writes), with ``--report DIR``
  ``DIR/<recording>/``, and ``gap.csv`` / ``gap.json`` (one row per recording and channel).

A channel's task runs the same function a one-file run calls, restricted to that channel;
the channels are then put back in the order the one-file run uses, so the reports are
identical to it (the model file's ``created`` time stamp aside).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import functools
import json
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from imubench.batch import UNITS
from imubench.batchrun.runner import (
    BatchError,
    Outcome,
    Plan,
    Work,
    expand_inputs,
    report_stem,
    run_recordings,
)
from imubench.commands import write_json
from imubench.recording.options import InputOptions, input_options


# -- common -------------------------------------------------------------------------------
def _check_options(args: argparse.Namespace, single_only: Sequence[tuple[str, str]],
                   spec: Path) -> Path:
    """The output directory; BatchError for options that name one file's outputs, and
    first for a ``spec`` that names no recording (a glob that matches nothing was told
    it needs --out-dir)."""
    expand_inputs(spec)
    for attr, flag in single_only:
        if getattr(args, attr) not in (None, [], False):
            raise BatchError(f"{flag} names one recording's output; with a directory or glob "
                             "the reports go to --out-dir")
    if args.out_dir is None:
        raise BatchError("a directory or glob of recordings needs --out-dir DIR for the "
                         "table and the per-recording reports")
    try:
        args.out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BatchError(f"--out-dir {args.out_dir}: cannot create ({exc.strerror})") from None
    return Path(args.out_dir)


def _cell(value: Any) -> Any:
    if value is None:
        return ""
    if isinstance(value, list | tuple):
        return " ".join(str(v) for v in value)
    return value


def write_table(rows: list[dict[str, Any]], out_dir: Path, name: str,
                meta: dict[str, Any]) -> tuple[Path, Path]:
    """``name.csv`` (columns in first-seen order) and ``name.json`` (``meta`` + rows)."""
    columns: dict[str, None] = {}
    for r in rows:
        columns.update(dict.fromkeys(r))
    csv_path, json_path = out_dir / f"{name}.csv", out_dir / f"{name}.json"
    with csv_path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(columns))
        w.writeheader()
        for r in rows:
            w.writerow({k: _cell(v) for k, v in r.items()})
    write_json({**meta, "rows": rows}, str(json_path))
    return csv_path, json_path


def _with_unit(row: dict[str, Any]) -> dict[str, Any]:
    """``row`` with the unit of its channel's values after ``channel`` (``unit``)."""
    if row.get("channel") not in UNITS:
        return row
    out: dict[str, Any] = {}
    for k, v in row.items():
        out[k] = v
        if k == "channel":
            out["unit"] = UNITS[v]
    return out


def _table_units(label: str, channels: list[str]) -> dict[str, Any]:
    """The units of a table's numbers: per channel for the fitted parameters (``fit``,
    ``gap``), the deviations in the row's ``unit`` (``allan``)."""
    from imubench.noisefit.units import param_units

    common = {"rate_hz": "Hz", "tau_s": "s", "unit": "the unit of the row's channel"}
    if label == "allan":
        return {**common, "dev": "unit", "ci_low": "unit", "ci_high": "unit"}
    return {**common, **{ch: param_units(ch) for ch in channels if ch != "temp"}}


def _finish(label: str, outcomes: list[Outcome], rows: list[dict[str, Any]], out_dir: Path,
            args: argparse.Namespace) -> int:
    """Table, summary, errors; exit status 0 when every task succeeded, else 2."""
    failed = [(o.recording, ch, msg) for o in outcomes for ch, msg in o.errors.items()]
    channels = sorted({r["channel"] for r in rows if r.get("channel") in UNITS})
    rows = [_with_unit(r) for r in rows]
    for rec, ch, msg in failed:
        rows.append({"recording": str(rec), "channel": ch or None, "error": msg})
    meta = {"command": label, "recordings": [str(o.recording) for o in outcomes],
            "tasks": sum(len(o.results) + len(o.errors) for o in outcomes),
            "workers": args.workers, "scheduler": args.scheduler, "failed": len(failed),
            "units": _table_units(label, channels)}
    csv_path, json_path = write_table(rows, out_dir, label, meta)
    print(f"{label}: {len(outcomes)} recording(s), {meta['tasks']} task(s), {len(failed)} "
          f"failed; table {csv_path} and {json_path}")
    for rec, ch, msg in failed:
        where = f"{rec}" + (f" {ch}" if ch else "")
        if not ch and msg.startswith(f"{Path(rec).resolve()}:"):
            where, msg = str(rec), msg[len(str(Path(rec).resolve())) + 2:]  # named once
        print(f"imubench {label}: error: {where}: {msg}", file=sys.stderr)
    return 2 if failed else 0


def _run(label: str, args: argparse.Namespace, spec: Path, plan: Plan,
         work: Work) -> list[Outcome]:
    return run_recordings(expand_inputs(spec), plan, work, workers=args.workers,
                          scheduler=args.scheduler, label=label)


# -- allan --------------------------------------------------------------------------------
def allan_plan(column: str | None, options: InputOptions, path: Path, name: str
               ) -> list[str]:
    """``--column`` if given (checked), else every gyro/accel channel with data."""
    from imubench.recording import load_recording

    chans = [c for c in load_recording(path, options).channels if c != "temp"]
    if column is not None:
        if column not in [*chans, "temp"]:
            raise BatchError(f"{name}: no channel {column!r}; channels are {chans}")
        return [column]
    if not chans:
        raise BatchError(f"{name}: no channel with data")
    return chans


def allan_work(args: argparse.Namespace, path: Path, name: str, channel: str
               ) -> dict[str, Any]:
    """``imubench allan PATH --column CHANNEL --json``'s document."""
    from imubench.commands.allan import analyse, load_channel, with_units

    data, rate, _, unit = load_channel(path, channel, input_options(args))
    return with_units(dict(analyse(args, data, rate).to_dict()), channel, unit,
                      args.data_type)


def allan_rows(rec: Path, channel: str, doc: dict[str, Any]) -> Iterable[dict[str, Any]]:
    for k in range(len(doc["tau_s"])):
        yield {"recording": str(rec), "channel": channel, "stat": doc["stat"],
               **{f: doc[f][k] for f in ("m", "tau_s", "n", "alpha", "dev", "ci_low",
                                         "ci_high", "edf", "gaps")}}


def run_allan_batch(args: argparse.Namespace) -> int:
    out_dir = _check_options(args, (("json", "--json"),), args.input)
    outcomes = _run("allan", args, args.input,
                    functools.partial(allan_plan, args.column, input_options(args)),
                    functools.partial(allan_work, args))
    rows: list[dict[str, Any]] = []
    for o in outcomes:
        for ch in o.channels:
            if ch in o.results:
                doc = o.results[ch]
                write_json(doc, str(out_dir / f"{report_stem(o.recording)}.{ch}.{args.stat}"
                                               ".json"))
                rows.extend(allan_rows(o.recording, ch, doc))
    return _finish("allan", outcomes, rows, out_dir, args)


# -- fit ----------------------------------------------------------------------------------
def fit_plan(channels: str | None, options: InputOptions, path: Path, name: str
             ) -> list[str]:
    """The channels ``imubench fit`` fits, in its order."""
    from imubench.noisefit.errors import FitError
    from imubench.noisefit.recording_fit import parse_channels
    from imubench.recording import load_recording

    chans = parse_channels(channels, load_recording(path, options).channels)
    if not chans:
        raise FitError(f"{name}: no gyro or accel channel with data to fit")
    return chans


def fit_work(terms: str, method: str, fit_temperature: bool, options: InputOptions,
             path: Path, name: str, channel: str) -> Any:
    """``fit_recording``'s work for one channel (a RecordingFit with one fit)."""
    from imubench.noisefit.recording_fit import fit_loaded
    from imubench.recording import load_recording

    return fit_loaded(load_recording(path, options), name, channels=[channel], terms=terms,
                      method=method, fit_temperature=fit_temperature)


def fit_rows(rec: Path, result: Any) -> Iterable[dict[str, Any]]:
    from imubench.noisefit.fit import PARAM_KEYS

    for ch, f in result.fits.items():
        row: dict[str, Any] = {"recording": str(rec), "channel": ch, "rate_hz": f.rate_hz,
                               "method": f.method, "present": list(f.present)}
        for key in PARAM_KEYS:
            row[key] = f.params.get(key)
            lo, hi = f.ci.get(key, (None, None))
            row[f"{key}_ci95_low"], row[f"{key}_ci95_high"] = lo, hi
        tr = f.temperature  # --fit-temperature's response, when one was taken out
        row["temp_coeff"] = None if tr is None else tr.temp_coeff
        row["temp_coeff_se"] = None if tr is None else tr.temp_coeff_se
        row["temp_ref"] = None if tr is None else tr.temp_ref_c
        yield row


def run_fit_batch(args: argparse.Namespace) -> int:

    out_dir = _check_options(args, (("output", "-o"), ("json", "--json"),
                                    ("kalibr", "--kalibr")), args.recording)
    options = input_options(args)
    outcomes = _run("fit", args, args.recording,
                    functools.partial(fit_plan, args.channels, options),
                    functools.partial(fit_work, args.terms, args.method, args.fit_temperature,
                                      options))
    rows: list[dict[str, Any]] = []
    for o in outcomes:
        done = [ch for ch in o.channels if ch in o.results]
        if not done:
            continue
        first = o.results[done[0]]
        merged = dataclasses.replace(first, fits={ch: o.results[ch].fits[ch] for ch in done})
        stem = report_stem(o.recording)
        (out_dir / f"{stem}.toml").write_text(merged.noise_model().to_toml(),
                                              encoding="utf-8")
        write_json(merged.to_dict(), str(out_dir / f"{stem}.json"))
        rows.extend(fit_rows(o.recording, merged))
    return _finish("fit", outcomes, rows, out_dir, args)


# -- gap ----------------------------------------------------------------------------------
def gap_plan(channels: list[str] | None, options: InputOptions, path: Path, name: str
             ) -> list[str]:
    from imubench.gap.recording import pick_channels
    from imubench.recording import load_recording

    return pick_channels(load_recording(path, options), channels)


def gap_work(args: argparse.Namespace, path: Path, name: str, channel: str
             ) -> tuple[dict[str, Any], Any]:
    """``diagnose_recording`` of one channel: (its JSON document, its diagnosis)."""
    from lsm6ds_sim.model import load_model

    from imubench.commands.gap import gap_options
    from imubench.gap import diagnose_recording
    from imubench.recording import load_recording

    rec = dataclasses.replace(load_recording(path, input_options(args)), path=Path(name))
    out, diags = diagnose_recording(rec, load_model(args.model), [channel],
                                    gap_options(args), [],
                                    effects_requested=args.effects is not None)
    return out, diags[channel]


def gap_rows(rec: Path, doc: dict[str, Any]) -> Iterable[dict[str, Any]]:
    for ch, c in doc["channels"].items():
        yield {"recording": str(rec), "channel": ch, "verdict": c["verdict"],
               "significant": c["significant"], "gap_before": c["gap_before"],
               "gap_after": c["gap_after"], "gap_excess_before": c["gap_excess_before"],
               "gap_excess_after": c["gap_excess_after"]}


def run_gap_batch(args: argparse.Namespace) -> int:
    from imubench.commands.gap import gap_units

    out_dir = _check_options(args, (("json", "--json"), ("holdout", "--holdout")), args.real)
    if args.jobs is not None:
        raise BatchError("--jobs runs one recording's channels in local processes; drop it "
                         "for a batch, which runs its channels as tasks, in this process or "
                         "with --workers N")
    outcomes = _run("gap", args, args.real,
                    functools.partial(gap_plan, args.channels, input_options(args)),
                    functools.partial(gap_work, args))
    rows: list[dict[str, Any]] = []
    for o in outcomes:
        done = [ch for ch in o.channels if ch in o.results]
        if not done:
            continue
        doc = json.loads(json.dumps(o.results[done[0]][0]))  # a copy to merge into
        doc["channels"] = {ch: o.results[ch][0]["channels"][ch] for ch in done}
        doc["units"] = gap_units(done)
        stem = report_stem(o.recording)
        if args.report is not None:
            from imubench.gap.report import write_report

            doc["report"] = str(write_report(Path(args.report) / stem, doc,
                                             {ch: o.results[ch][1] for ch in done},
                                             doc["rate_hz"]))
        write_json(doc, str(out_dir / f"{stem}.gap.json"))
        rows.extend(gap_rows(o.recording, doc))
    return _finish("gap", outcomes, rows, out_dir, args)


__all__ = ["allan_plan", "allan_rows", "allan_work", "fit_plan", "fit_rows", "fit_work",
           "gap_plan", "gap_rows", "gap_work", "run_allan_batch", "run_fit_batch",
           "run_gap_batch", "write_table"]
