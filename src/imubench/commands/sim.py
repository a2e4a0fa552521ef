"""``imubench sim``: a recording produced through the full register path (simulated
chip, simulated bus, the real driver, FIFO reads), in virtual time.

    imubench sim --chip lsm6dsl --odr-hz 104 --duration-s 3600 --model MODEL.toml \\
        [--temperature PROFILE] [--seed N] [--bus-khz 400] [--fs-dps 250] [--fs-g 2] --out REC
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any
from urllib.parse import quote

from lsm6ds.registers import CHIPS

from imubench.commands import check_writable, summary_stream
from imubench.commands.acquire import AcquisitionError, record_uri
from imubench.errors import SourceError


def build_uri(args: argparse.Namespace) -> str:
    params = [
        f"odr_hz={args.odr_hz:g}",
        f"fs_dps={args.fs_dps:g}",
        f"fs_g={args.fs_g:g}",
        f"seed={args.seed}",
        f"duration_s={quote(f'{args.duration_s:g}', safe='')}",
        "clock=virtual",
    ]
    if args.model:
        params.append(f"model={quote(str(args.model))}")
    if args.temperature:
        params.append(f"temperature={quote(str(args.temperature))}")
    if args.bus_khz:
        params.append(f"bus_khz={args.bus_khz:g}")
    return f"sim://{args.chip}?" + "&".join(params)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sim",
        help="simulate a chip and record it through the real driver",
        description="Write a recording produced by a simulated LSM6DS chip read through "
        "the real I2C driver and its FIFO, in virtual time.",
    )
    p.add_argument("--chip", choices=CHIPS, default="lsm6dsl", help="simulated chip")
    p.add_argument("--odr-hz", type=float, default=104.0,
                   help="output data rate in Hz (one the chip has; default 104)")
    p.add_argument("--duration-s", type=float, required=True,
                   help="seconds of data to simulate (virtual time)")
    p.add_argument("--model", default=None, metavar="MODEL.toml|datasheet:CHIP",
                   help="noise model file, or datasheet:CHIP for the shipped "
                   "datasheet-typical one (default: no noise)")
    p.add_argument("--temperature", default=None,
                   help="temperature profile (docs/simulator.md; default 25 degC)")
    p.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    p.add_argument("--fs-dps", type=float, default=250.0,
                   help="gyro full scale in dps (default 250)")
    p.add_argument("--fs-g", type=float, default=2.0,
                   help="accelerometer full scale in g (default 2)")
    p.add_argument("--bus-khz", type=float, default=0.0,
                   help="I2C bus clock of the bus timing model in kHz (default 0 = off)")
    p.add_argument("--out", type=Path, required=True, metavar="REC",
                   help="recording to write (.imbr native, .csv, .csv.gz)")
    p.add_argument("--stats-json", type=Path, default=None, metavar="PATH|-",
                   help="write the acquisition counters as JSON here (- for stdout)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.duration_s <= 0:
        raise SourceError(f"--duration-s {args.duration_s} must be > 0")
    check_writable(args.stats_json, "--stats-json")  # before the acquisition, not after
    try:
        stats = record_uri(build_uri(args), args.out, args.stats_json, args.duration_s)
    except AcquisitionError as failed:  # what the closed recording holds, then the error
        print(_summary(args, failed.stats) + " up to the failure below",
              file=summary_stream(args.stats_json))
        raise failed.error from None
    print(_summary(args, stats), file=summary_stream(args.stats_json))
    return 0


def _summary(args: argparse.Namespace, stats: dict[str, Any]) -> str:
    return (f"{args.out}: {stats['samples']} samples from a simulated {args.chip} "
            f"({stats['gaps']} gaps, {stats['lost_samples']} lost)")
