"""``imubench gap``: where a simulated sensor departs from a real one, which unmodelled
effect causes it, and how far the gap closes once it is modelled, checked on held-out data.

    imubench gap REAL --model MODEL.toml [--channels gx,...] [--holdout-fraction 0.5]
        [--holdout REC2 ...] [--effects flicker,...] [--realisations 10] [--seed N]
        [--report DIR] --json OUT

REAL is a recording (.imbr or .csv, with a ``temp`` column when the sensor has one).
See docs/gap.md. Exit status 0 on success, 2 on an imubench error.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from lsm6ds_sim.model import load_model

from imubench.commands import write_json
from imubench.gap import EFFECTS, GapOptions, diagnose_recording
from imubench.gap.explain import explain_channel
from imubench.recording import load_recording


def _fraction(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 <= v < 1.0:
        raise argparse.ArgumentTypeError(f"{text!r} must be in [0, 1)")
    return v


def _list(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "gap",
        help="sim-to-real gap: where the model departs from a recording, and why",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("real", type=Path, metavar="REAL", help="recording (.imbr/.csv)")
    p.add_argument("--model", type=Path, required=True, help="noise model TOML")
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
    p.add_argument("--report", type=Path, default=None, metavar="DIR",
                   help="write PNG/SVG plots and index.html here")
    p.add_argument("--json", required=True, metavar="OUT|-", help="write the JSON here")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    effects = tuple(args.effects) if args.effects else EFFECTS
    options = GapOptions(realisations=args.realisations, seed=args.seed,
                         holdout_fraction=args.holdout_fraction, effects=effects)
    model = load_model(args.model)
    rec = load_recording(args.real)
    reps = [load_recording(p) for p in args.holdout]

    def progress(ch: str) -> None:
        if sys.stderr.isatty():
            print(f"imubench gap: {ch} ...", file=sys.stderr)

    out, diags = diagnose_recording(rec, model, args.channels, options, reps,
                                    effects_requested=args.effects is not None,
                                    progress=progress)
    if args.report is not None:
        from imubench.gap.report import write_report  # matplotlib only when asked

        out["report"] = str(write_report(args.report, out, diags, rec.rate_hz))
    write_json(out, args.json)
    for ch, c in out["channels"].items():
        print(f"{ch}: verdict {c['verdict']}, gap {c['gap_before']:.3f} -> "
              f"{c['gap_after']:.3f}", file=sys.stderr)
        for line in explain_channel(c, out["realisations"]):
            print(f"  {line}", file=sys.stderr)
    return 0
