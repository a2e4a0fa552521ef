"""``imubench report REC [--model MODEL.toml | --fit-temperature] --out DIR``: plots, fit, HTML.

Writes into DIR, per sensor (gyro, accel): ``sigma_tau_<sensor>.png/.svg`` (OADEV with 95 %
error bars, the model and each term's line clipped to the data, IEEE 952 readouts N at
1 s, B at the minimum, K at 3 s in datasheet units, a deg/h or ug right axis),
``psd_<sensor>.png/.svg`` (amplitude spectral density in mdps/sqrt(Hz) or ug/sqrt(Hz),
log-band averaged, with the model's terms) and ``<sensor>.html`` (one-page summary with the
datasheet comparison); and ``model.toml``, ``fit.json``, ``imu.yaml`` (Kalibr),
``index.html``. With ``--model`` the noise values are those of the model file (written by
``imubench fit -o``): nothing is refitted and, as such a file has no intervals, the pages
say so; a model's ``temp_coeff`` is taken out of the recording (where it has a temperature
column) before the comparison. ``--fit-temperature`` fits as ``imubench fit
--fit-temperature`` does, and the plots show the data less the response taken out. See
docs/reports.md.
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
    p.add_argument("recording", type=Path,
                   help="recording (.imbr, CSV, .h5, MCAP, ...: docs/recordings.md)")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    p.add_argument("--model", type=Path, default=None, metavar="MODEL.toml",
                   help="use this model file (imubench fit -o output) instead of fitting")
    p.add_argument("--terms", default=None, help="as for imubench fit (default auto)")
    p.add_argument("--method", choices=METHODS, default=None,
                   help="as for imubench fit (default wls)")
    p.add_argument("--fit-temperature", action="store_true",
                   help="as for imubench fit: take a channel's response to the recording's "
                        "temperature out before the noise terms are fitted; the plots then "
                        "show the data less that response")
    add_input_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from imubench.noisefit.report import write_report

    if args.model is not None and (args.terms is not None or args.method is not None
                                   or args.fit_temperature):
        print("imubench report: error: --terms, --method and --fit-temperature choose how "
              "to fit; --model "
              f"{args.model} reuses a fit and fits nothing (drop one of them)",
              file=sys.stderr)
        return 2
    try:
        files = write_report(args.recording, args.out, terms=args.terms or "auto",
                             method=args.method or "wls", options=input_options(args),
                             model_file=args.model, fit_temperature=args.fit_temperature)
    except BrokenPipeError:
        raise  # stdout's reader went away: cli.main exits 141, no message
    except OSError as exc:
        print(f"imubench report: error: {exc}", file=sys.stderr)
        return 2
    for f in files:
        print(f)
    return 0
