"""``imubench allan``: one Allan-family statistic of a recording or a text table.

INPUT is a recording (``.imbr`` native, ``.csv``; pick the channel with ``--column``), a
CSV from elsewhere (``--columns``, ``--units``, ``--time-unit``: docs/recordings.md) or a
Stable32 / allantools text file (one value per line, or time tag and value; ``#``
comments; ``.gz`` ok; without a rate its tau is in samples). Prints a table, or JSON with
``--json PATH`` (``-`` for stdout). Exit status 0 on success, 2 on an imubench error (the
message says what and where).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

import numpy as np

from imubench.batch import UNITS
from imubench.batchrun import add_batch_options, is_batch
from imubench.commands import write_json
from imubench.errors import RecordingError, StatsError
from imubench.progress import progress
from imubench.recording.options import InputOptions, add_input_arguments, input_options
from imubench.stats import STATISTICS, compute
from imubench.stats.result import dev_unit
from imubench.stats.taus import parse_taus


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "allan",
        help="Allan-family statistic (adev, oadev, mdev, ..., theoh) of a recording",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", type=Path,
                   help="recording (.imbr/.csv), CSV from elsewhere or Stable32 text (.gz ok)")
    p.add_argument("--stat", required=True, choices=STATISTICS, help="statistic (deviation)")
    p.add_argument(
        "--data-type",
        choices=("phase", "freq"),
        default="freq",
        help="phase (s) or frequency/rate samples (default freq: a rate in dps or g)",
    )
    p.add_argument(
        "--rate",
        type=float,
        default=None,
        help="sample rate in Hz (default: the recording's; 1 Hz, tau in samples, for a "
        "text file that states none)",
    )
    p.add_argument(
        "--taus",
        default="octave",
        help="octave | decade | all | N (points per decade) | comma list of tau_s",
    )
    p.add_argument(
        "--column",
        default=None,
        help="recording channel, e.g. gx (required for multi-channel recordings)",
    )
    p.add_argument("--ci", type=float, default=0.683, help="confidence level (default 0.683)")
    p.add_argument(
        "--alpha",
        type=int,
        default=None,
        choices=(-2, -1, 0, 1, 2),
        help="fix the noise type alpha instead of identifying it per tau",
    )
    p.add_argument(
        "--no-bias-correction",
        action="store_true",
        help="do not apply Stable32's bias corrections (TOT, HTOT, Theo1)",
    )
    p.add_argument(
        "--remove-drift", action="store_true", help="remove linear frequency drift first (reported)"
    )
    p.add_argument("--json", default=None, metavar="PATH|-", help="write JSON here")
    add_input_arguments(p, rate=False)
    add_batch_options(p)
    p.set_defaults(func=run)


def load_channel(path: Path, column: str | None, options: InputOptions
                 ) -> tuple[np.ndarray, float, str, str]:
    """(data, rate_hz, channel, unit) of one channel of a recording or a text table (the
    one reader, :func:`imubench.recording.load_recording`; a file that states no rate and
    has no time column is read at 1 Hz, tau in samples, as Stable32 and allantools do).
    ``unit`` is the channel's (dps, g), or "input unit" when nothing in the file or the
    options states it (a plain series: a clock's fractional frequency is no rate in
    dps)."""
    from imubench.recording import load_recording

    rec = load_recording(path, dataclasses.replace(options, default_rate_hz=1.0))
    chans = list(rec.channels)
    if column is None:
        if len(chans) != 1:
            raise RecordingError(f"{path}: pick a channel with --column (one of {chans})")
        column = chans[0]
    if column not in chans:
        raise RecordingError(f"{path}: no channel {column!r}; channels are {chans}")
    assumed = rec.metadata.get("units_assumed") or []
    unit = INPUT_UNIT if column in assumed else UNITS.get(column, INPUT_UNIT)
    return (np.asarray(rec.channel(column), dtype=np.float64), float(rec.rate_hz), column,
            unit)


INPUT_UNIT = "input unit"


def with_units(doc: dict[str, Any], channel: str, unit: str, data_type: str
               ) -> dict[str, Any]:
    """An ``allan`` JSON document with its ``channel``, the unit of the data analysed
    (``data_unit``) and the ``units`` of its numbers (``unit``: the series', see
    :func:`load_channel`)."""
    u = dev_unit(unit, str(doc.get("stat", "")))
    units = {"rate_hz": "Hz", "tau_s": "s", "m": "samples", "n": "terms", "dev": u,
             "ci_low": u, "ci_high": u, "var": f"{u}^2", "drift": f"{unit}/s",
             "edf": "1", "alpha": "1 (S(f) ~ f^alpha)",
             "gaps": "terms (skipped: they span a missing sample)", "bias_factor": "1",
             "confidence": "1 (probability of the interval)"}
    return {**doc, "channel": channel,
            "data_unit": unit if data_type == "freq" else f"{unit}*s", "units": units}


def format_table(res: Any, unit: str) -> str:
    """The result as a table, ``dev`` and its interval in :func:`dev_unit` of ``unit``."""
    dev = dev_unit(unit, res.stat)
    lines = [
        f"# {res.stat}  data_type={res.data_type}  rate={res.rate_hz:g} Hz  "
        f"confidence={res.confidence:g}  bias_corrected={res.bias_corrected}  "
        f"dev in {dev}"
        + (f"  drift={res.drift:.6g} {unit}/s" if res.drift is not None else ""),
        f"{'AF':>8} {'tau_s':>12} {'n':>10} {'alpha':>5} {'ci_low':>12} {'dev':>12} "
        f"{'ci_high':>12} {'edf':>9} {'gaps':>6}",
    ]
    for k in range(len(res)):
        lines.append(
            f"{res.m[k]:>8d} {res.tau_s[k]:>12.5e} {res.n[k]:>10d} {res.alpha[k]:>5d} "
            f"{res.ci_low[k]:>12.5e} {res.dev[k]:>12.5e} {res.ci_high[k]:>12.5e} "
            f"{res.edf[k]:>9.4g} {res.gaps[k]:>6d}"
        )
    lines.extend(f"# note: {n}" for n in res.notes)
    return "\n".join(lines)


def holes_note(data: np.ndarray) -> str | None:
    """``N of M samples missing (...)`` when the series has holes (NaN), else None: the
    table's ``gaps`` column alone did not say how much of the record was there."""
    missing = int(np.count_nonzero(~np.isfinite(data)))
    if not missing:
        return None
    return (f"{missing} of {len(data)} samples missing ({100.0 * missing / len(data):.3g} %): "
            "the terms that span them are skipped (the gaps column)")


def analyse(args: argparse.Namespace, data: np.ndarray, rec_rate: float | None,
            on_progress: Any = None) -> Any:
    """The statistic the options ask for, of one series (``rec_rate``: the recording's
    rate, None for text input)."""
    rate = args.rate if args.rate is not None else (rec_rate or 1.0)
    return compute(
        args.stat,
        data,
        rate,
        args.data_type,
        parse_taus(args.taus),
        confidence=args.ci,
        alpha=args.alpha,
        bias_correction=not args.no_bias_correction,
        remove_drift=args.remove_drift,
        progress=on_progress,
    )


def run(args: argparse.Namespace) -> int:
    if is_batch(args.input, args):
        from imubench.batchrun.jobs import run_allan_batch

        return run_allan_batch(args)
    data, rec_rate, channel, unit = load_channel(args.input, args.column,
                                                 input_options(args))
    with progress(100, args.stat, unit="%") as bar:
        try:
            res = analyse(args, data, rec_rate, bar.fraction)
        except StatsError as exc:  # e.g. too few samples left: name the file
            raise StatsError(f"{args.input} {channel}: {exc}") from None
    if args.json is not None:
        write_json(with_units(res.to_dict(), channel, unit, args.data_type), args.json)
    # the table goes to stderr when stdout carries the JSON (docs/cli.md)
    out = sys.stderr if args.json == "-" else sys.stdout
    print(format_table(res, unit), file=out)
    note = holes_note(data)
    if note is not None:
        print(f"# note: {args.input} {channel}: {note}", file=out)
    return 0
