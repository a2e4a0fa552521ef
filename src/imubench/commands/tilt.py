"""``imubench tilt``: tilt angles from a recording or a live source, and tilt error budgets.

    imubench tilt SOURCE [--form single|dual|triple] [--axis x] [--ref z] [--average N]
                  [--duration-s S] [--calibration FILE] [--json PATH]
    imubench tilt --budget BUDGET.toml [--json PATH]

SOURCE is a recording (``.imbr``, ``.csv``, ``.csv.gz``) or a source URI
(``sim://...``, ``i2c://...``, ...; read for ``--duration-s`` seconds). The accelerometer
samples are averaged in blocks of ``--average`` samples (mean first, then the angle) and
turned into angles by the single-axis arcsin, dual-axis or three-axis atan2 forms
(:mod:`imubench.tilt.angles`). ``--calibration`` applies a calibration file first
(refused on a recording whose header says one was already applied). ``--budget``
prints an error budget (worst case and RSS, tilt degrees, the noise multiplier analysis;
``config/tilt-budget-note-table1.toml`` is the tilt note's Table 1). See
docs/calibration.md.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from imubench.batch import Batch
from imubench.recording.options import InputOptions, add_input_arguments, input_options
from imubench.tilt.angles import FORMS, block_average, tilt
from imubench.tilt.errors import TiltError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tilt", help="tilt angles from a recording or live source; tilt error budgets",
        description="Tilt angles (single-axis arcsin, dual/three-axis atan2, averaged over "
        "N samples) from a recording or a live source, or an error budget (--budget).",
    )
    p.add_argument("source", nargs="?", metavar="SOURCE",
                   help="recording (.imbr, .csv) or source URI (sim://..., i2c://...)")
    p.add_argument("--form", choices=FORMS, default="triple",
                   help="single (arcsin of --axis), dual (atan2 of --axis over --ref) or "
                   "triple (all three-axis angles, roll and pitch); default triple")
    p.add_argument("--axis", choices=("x", "y", "z"), default="x", help="tilt axis")
    p.add_argument("--ref", choices=("x", "y", "z"), default="z",
                   help="reference axis of the dual-axis form (vertical at 0 deg)")
    p.add_argument("--average", type=int, default=1, metavar="N",
                   help="samples averaged per angle (mean first, then the angle)")
    p.add_argument("--duration-s", type=float, default=None,
                   help="seconds to read from a live source (required for a URI)")
    p.add_argument("--calibration", type=Path, default=None, metavar="FILE",
                   help="apply this calibration file to the samples first")
    p.add_argument("--budget", type=Path, default=None, metavar="BUDGET.toml",
                   help="print this error budget instead of computing angles")
    p.add_argument("--json", type=Path, default=None, metavar="PATH",
                   help="write the angles (or the budget) as JSON here (- for stdout)")
    add_input_arguments(p)
    p.set_defaults(func=run)


def _read_source(text: str, duration_s: float | None, options: InputOptions
                 ) -> tuple[Batch, float, dict[str, Any]]:
    """(batch, odr_hz, metadata) of a recording (read with ``options``) or a live
    source."""
    if "://" not in text:
        from imubench.recording import load_recording

        rec = load_recording(text, options)
        return rec.batch(), rec.rate_hz, dict(rec.metadata)
    if duration_s is None or duration_s <= 0:
        raise TiltError("a live source needs --duration-s > 0")
    from imubench.commands.acquire import add_duration
    from imubench.sources.registry import open_source

    src = open_source(add_duration(text, duration_s))
    n = round(duration_s * src.info.odr_hz)
    parts: list[Batch] = []
    got = 0
    with src:
        for b in src:
            if len(b):
                parts.append(b)
                got += len(b)
            if got >= n:
                break
    if not parts:
        raise TiltError(f"{text}: no samples")
    return Batch.concat(parts).head(n), src.info.odr_hz, {"source_uri": text}


def angles(batch: Batch, odr_hz: float, form: str, axis: str, ref: str,
           average: int) -> dict[str, Any]:
    """Block-averaged accelerometer samples and their angles (JSON-ready)."""
    a = batch.values[:, 3:6]
    if np.all(np.isnan(a)):
        raise TiltError("the data hold no accelerometer samples")
    blocks = block_average(a, average)
    t = block_average(batch.t_s[:, None], average)[:, 0]
    out = tilt(blocks, form, axis, ref)
    return {
        "form": form, "axis": axis, "ref": ref, "average": average, "odr_hz": odr_hz,
        "t_s": t.tolist(), "accel_g": blocks.tolist(),
        "angles_deg": {k: v.tolist() for k, v in out.items()},
        "summary": {k: {"mean": float(np.nanmean(v)), "std": float(np.nanstd(v)),
                        "n": int(np.isfinite(v).sum())} for k, v in out.items()},
    }


def _write_json(data: dict[str, Any], path: Path | None) -> None:
    if path is None:
        return
    text = json.dumps(data, indent=1) + "\n"
    if str(path) == "-":
        sys.stdout.write(text)
    else:
        path.write_text(text)


def run(args: argparse.Namespace) -> int:
    if args.budget is not None:
        if args.source is not None:
            raise TiltError("give either SOURCE (angles) or --budget, not both")
        from imubench.tilt.budget import load_budget

        budget = load_budget(args.budget)
        if str(args.json) != "-":
            print(budget.render())
        _write_json(budget.summary(), args.json)
        return 0
    if args.source is None:
        raise TiltError("give SOURCE (a recording or a URI) or --budget FILE")
    batch, odr, meta = _read_source(args.source, args.duration_s, input_options(args))
    if np.all(np.isnan(batch.values[:, 3:6])):
        raise TiltError(f"{args.source}: no accelerometer samples (ax, ay, az); tilt "
                        "needs them (name their columns with --columns ax=...,ay=...,az=...)")
    calibration = None
    if args.calibration is not None:
        from imubench.calibration import Calibration

        already = meta.get("calibration")
        if isinstance(already, dict) and already.get("applied"):
            raise TiltError(f"{args.source}: its header says calibration"
                            f" {already.get('path')!r} was applied already; drop --calibration")
        calibration = Calibration.load(args.calibration)
        batch = calibration.apply(batch)
    try:
        data = angles(batch, odr, args.form, args.axis, args.ref, args.average)
    except TiltError as exc:  # e.g. fewer samples than --average: name the source
        raise TiltError(f"{args.source}: {exc}") from None
    data["source"] = args.source
    data["calibration"] = None if calibration is None else calibration.describe()
    if str(args.json) != "-":
        cal = "" if calibration is None else f", calibration {args.calibration}"
        print(f"{args.source}: {len(data['t_s'])} angles of {args.average}-sample means"
              f" ({args.form}{cal})")
        for k, s in data["summary"].items():
            print(f"  {k:10s} mean {s['mean']:+9.4f} deg  std {s['std']:.4f} deg  (n={s['n']})")
    _write_json(data, args.json)
    return 0
