"""``imubench gap``: where a simulated sensor departs from a real one, which unmodelled
effect causes it, and how far the gap closes once it is modelled, checked on held-out data.

    imubench gap REAL --model MODEL.toml [--channels gx,...] [--holdout-fraction 0.5]
        [--holdout REC2 ...] [--effects flicker,...] [--realisations 10] [--seed N]
        [--report DIR] [--limits] [--jobs N] --json OUT

REAL is a recording (.imbr or .csv, with a ``temp`` column when the sensor has one).
See docs/gap.md. Exit status 0 on success, 2 on an imubench error.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from lsm6ds_sim.model import load_model

from imubench.batchrun import add_batch_options, is_batch
from imubench.commands import check_writable, write_json
from imubench.gap import EFFECTS, GapOptions, diagnose_recording
from imubench.gap.errors import GapError
from imubench.gap.explain import explain_channel
from imubench.gap.recording import default_jobs, pick_channels
from imubench.progress import progress
from imubench.recording import coverage_text, empty_cells_text, load_recording
from imubench.recording.options import add_input_arguments, input_options


def headline(channel: str, c: dict[str, Any]) -> str:
    """'gx: verdict V, gap A -> B on the fit part; held out C -> D (systematic part beyond
    the scatter E -> F)': the held-out part's gap beside the fit part's, since an effect
    seen there only
    (a bias step in the held-out half) leaves the fit part's gap where it was, and its
    systematic part (``gap_excess_*``), which a better model can close: the gap itself
    keeps the scatter of the taus no effect touches (an outside reviewer read a raw gap
    closed by 36-59 % where the part beyond the scatter closed by all of it; another
    read "beyond its scatter 0.000 -> 0.000" as a scatter of zero)."""
    text = (f"{channel}: verdict {c['verdict']}, gap {c['gap_before']:.3f} -> "
            f"{c['gap_after']:.3f} on the fit part")
    h = c.get("holdout") or {}
    if h.get("gap_before") is not None:
        text += f"; held out {h['gap_before']:.3f} -> {h['gap_after']:.3f}"
        eb, ea = h.get("gap_excess_before"), h.get("gap_excess_after")
        if eb is not None and ea is not None:
            text += f" (systematic part beyond the scatter {eb:.3f} -> {ea:.3f})"
    return text


def _fraction(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 <= v < 1.0:
        raise argparse.ArgumentTypeError(f"{text!r} must be in [0, 1)")
    return v


def _jobs(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--jobs {text!r}: not a whole number") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"--jobs {n}: use 1 or more")
    return n


def _list(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "gap",
        help="sim-to-real gap: where the model departs from a recording, and why",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("real", type=Path, metavar="REAL",
                   help="recording (.imbr, CSV, .h5, MCAP, ...: docs/recordings.md)")
    p.add_argument("--model", type=Path, required=True, metavar="MODEL.toml|datasheet:CHIP",
                   help="noise model file, or datasheet:CHIP for a shipped one")
    p.add_argument("--channels", type=_list, default=None,
                   help="comma list, e.g. gx,gy (default: every channel of REAL)")
    p.add_argument("--holdout-fraction", type=_fraction, default=0.5,
                   help="last fraction of REAL held out from fitting (default 0.5; 0 = none)")
    p.add_argument("--holdout", type=Path, action="append", default=[], metavar="REC",
                   help="replicate recording of the same sensor to check on (repeatable)")
    p.add_argument("--effects", type=_list, default=None,
                   help=f"candidate effects (default all: {','.join(EFFECTS)})")
    p.add_argument("--realisations", type=int, default=10,
                   help="simulated realisations per model variant (default 10)")
    p.add_argument("--seed", type=int, default=0, help="seed of the realisations")
    p.add_argument("--limits", action="store_true",
                   help="inject each candidate into this recording at decreasing sizes and "
                        "report the smallest identified 90%% of the time (slow: minutes "
                        "per channel)")
    p.add_argument("--report", type=Path, default=None, metavar="DIR",
                   help="write PNG/SVG plots and index.html here")
    p.add_argument("--json", default=None, metavar="OUT|-",
                   help="write the JSON here (required for one recording)")
    p.add_argument("--jobs", type=_jobs, default=None, metavar="N",
                   help="channels of one recording diagnosed at once, one process each "
                        "(default: the CPUs this process may use for 2^18 samples per "
                        "channel or more, or with --limits; else 1); the result is the "
                        "same for any N")
    add_input_arguments(p)
    add_batch_options(p)
    p.set_defaults(func=run)


def gap_options(args: argparse.Namespace) -> GapOptions:
    effects = tuple(args.effects) if args.effects else EFFECTS
    return GapOptions(realisations=args.realisations, seed=args.seed,
                      holdout_fraction=args.holdout_fraction, effects=effects)


def gap_units(channels: list[str]) -> dict[str, object]:
    """The units of a ``gap`` JSON document's numbers: the gaps are dimensionless (RMS
    over the taus of ln(ADEV_real / ADEV_sim)); each channel's effect parameters are in
    the noise model's units of that channel (docs/noise-model.md)."""
    from imubench.batch import UNITS
    from imubench.noisefit.units import param_units

    def effect_units(ch: str) -> dict[str, str]:  # the gap's own effects' parameters
        return {"step_size": UNITS[ch], "step_time_s": "s", "telegraph_step": UNITS[ch],
                "telegraph_dwell_s": "s"}

    ln = "1 (RMS over taus of ln(ADEV_real/ADEV_sim))"
    return {"rate_hz": "Hz", "samples": "samples", "holdout_fraction": "1",
            **{k: ln for k in ("gap_before", "gap_after", "gap_null", "gap_null_after",
                               "gap_excess_before", "gap_excess_after", "gap_excess_floor",
                               "gap_excess_floor_after", "holdout_gap_after",
                               "holdout_gap_excess_after")},
            "lost_samples": "samples",
            "params": {ch: {**param_units(ch), **effect_units(ch)}
                       for ch in channels if ch != "temp"}}


def run(args: argparse.Namespace) -> int:
    if is_batch(args.real, args):
        from imubench.batchrun.jobs import run_gap_batch

        return run_gap_batch(args)
    if args.json is None:
        raise GapError("--json OUT is required for one recording (a directory or glob "
                       "writes into --out-dir)")
    check_writable(args.json, "--json")  # before the diagnosis, not after it
    options = gap_options(args)
    model = load_model(args.model)
    reading = input_options(args)
    rec = load_recording(args.real, reading)
    reps = [load_recording(p, reading) for p in args.holdout]

    n_channels = len(pick_channels(rec, args.channels))
    jobs = args.jobs if args.jobs is not None else default_jobs(rec, args.limits)
    with progress(n_channels, "gap", unit="channel") as bar:
        out, diags = diagnose_recording(rec, model, args.channels, options, reps,
                                        effects_requested=args.effects is not None,
                                        progress=lambda ch: bar.update(1),
                                        limits=args.limits, jobs=jobs)
    out["units"] = gap_units(list(out["channels"]))
    if args.report is not None:
        from imubench.gap.report import write_report  # matplotlib only when asked

        out["report"] = str(write_report(args.report, out, diags, rec.rate_hz))
    write_json(out, args.json)
    summary = sys.stderr if args.json == "-" else sys.stdout  # stdout: the JSON's, if "-"
    if rec.lost_samples:  # the realisations carry the same holes
        print(f"# {args.real}: {coverage_text(len(rec), rec.lost_samples, rec.holes)}",
              file=summary)
    for ch in out["channels"]:
        if (cells := empty_cells_text(rec, ch)) is not None:
            print(f"# {args.real}: {cells}", file=summary)
    for effect, why in out["effects_untested"].items():
        print(f"# {effect} not tested: {why}", file=summary)
    for ch, c in out["channels"].items():
        print(headline(ch, c), file=summary)
        for line in explain_channel(c, out["realisations"], out["units"]["params"][ch]):
            print(f"  {line}", file=summary)
    return 0
