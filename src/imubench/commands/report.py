"""``imubench report REC --out DIR``: sigma-tau and PSD plots, the fit, one HTML page.

Writes into DIR: ``sigma_tau_gyro.png/.svg`` and ``sigma_tau_accel.png/.svg`` (OADEV with
95 % error bars, MDEV, the fitted model and each term's line, local slopes labelled),
``psd_gyro/accel.png/.svg`` (Welch), ``model.toml`` (loads in the simulator), ``fit.json``,
``imu.yaml`` (Kalibr) and ``index.html`` (one-page summary). See docs/noise-fit.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from imubench.noisefit.fit import METHODS
from imubench.recording.options import add_input_arguments, input_options


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "report", help="noise report of a recording: plots, fit, HTML summary",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recording", type=Path, help="recording (.imbr or .csv)")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    p.add_argument("--terms", default="auto", help="as for imubench fit")
    p.add_argument("--method", choices=METHODS, default="wls", help="as for imubench fit")
    add_input_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from imubench.noisefit.report import write_report

    try:
        files = write_report(args.recording, args.out, terms=args.terms, method=args.method,
                             options=input_options(args))
    except OSError as exc:
        print(f"imubench report: error: {exc}", file=sys.stderr)
        return 2
    for f in files:
        print(f)
    return 0
