"""``imubench convert IN OUT``: native (.imbr) <-> CSV (.csv, .csv.gz), by suffix."""

from __future__ import annotations

import argparse

from imubench.recording import convert
from imubench.recording.options import add_input_arguments, input_options


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "convert", help="convert a recording between native .imbr and .csv",
        description="Convert a recording; the format of each file follows its suffix "
        "(.imbr native, .csv or .csv.gz CSV). Metadata, gaps and raw counts are kept "
        "where the target format can hold them.",
    )
    p.add_argument("input", metavar="IN",
                   help="recording to read (.imbr, .csv, CSV from elsewhere, text; .gz ok)")
    p.add_argument("output", metavar="OUT",
                   help="recording to write (.imbr, .csv, .csv.gz); never overwritten")
    add_input_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    rec = convert(args.input, args.output, input_options(args))
    note = f"; input was damaged: {rec.damage}" if rec.damage else ""
    print(f"{args.input} -> {args.output}: {len(rec)} samples, {len(rec.gaps)} gaps{note}")
    return 0
