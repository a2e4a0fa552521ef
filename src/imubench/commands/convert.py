"""``imubench convert IN OUT``: between recording formats by suffix (.imbr, .csv,
.csv.gz, .h5), or one channel to a Stable32 data file (OUT.dat --channel gx)."""

from __future__ import annotations

import argparse
from pathlib import Path

from imubench.progress import progress
from imubench.recording import STABLE32_SUFFIX, convert
from imubench.recording.options import add_input_arguments, input_options
from imubench.recording.stable32 import UNITS


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "convert", help="convert a recording (.imbr, .csv, .h5) or export one channel to "
        "Stable32 (.dat)",
        description="Convert a recording; the format of each file follows its suffix "
        "(.imbr native, .csv or .csv.gz CSV, .h5 HDF5; any input the reader takes). "
        "Metadata, gaps and raw counts are kept where the target format can hold them. "
        "OUT.dat with --channel writes that channel as a Stable32 / allantools data file "
        "(docs/recordings.md).",
    )
    p.add_argument("input", metavar="IN",
                   help="recording to read (.imbr, .csv, .h5, .mcap, a ROS 2 bag, CSV from "
                   "elsewhere, Stable32 text; .gz ok)")
    p.add_argument("output", metavar="OUT",
                   help="file to write (.imbr, .csv, .csv.gz, .h5, or .dat with --channel); "
                   "never overwritten")
    p.add_argument("--channel", choices=tuple(UNITS), default=None,
                   help="the channel a Stable32 .dat file holds (values in dps, g or degC)")
    p.add_argument("--calibration", type=Path, default=None, metavar="FILE",
                   help="apply this calibration file to the values (docs/calibration.md); "
                   "raw counts stay as recorded, the header says which file")
    add_input_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    with progress(100, "convert", unit="%") as bar:
        done = convert(args.input, args.output, input_options(args), channel=args.channel,
                       calibration=args.calibration,
                       on_progress=lambda done, total: bar.fraction(done / max(total, 1)))
    rec = done.recording
    note = f"; input was damaged: {rec.damage}" if rec.damage else ""
    if args.calibration is not None:
        note += f"; calibration {args.calibration} applied (raw counts unchanged)"
    what = (f"Stable32 data file of {args.channel} in {UNITS[args.channel]}, "
            f"{len(rec)} values, tau0 {1.0 / rec.rate_hz:.6g} s"
            if args.output.lower().endswith(STABLE32_SUFFIX)
            else f"{len(rec)} samples, {done.gaps} gaps"
            + (f" ({done.lost_samples} samples lost)" if done.lost_samples else ""))
    print(f"{args.input} -> {args.output}: {what}{note}")
    return 0
