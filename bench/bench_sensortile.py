"""Throughput and loss accounting of the simulated SensorTile kit (docs/benchmarks.md,
section "SensorTile"). Run: ``.venv/bin/python bench/bench_sensortile.py [--quick]
[--frames N]``.

Each row opens a ``sensortile-sim://`` URI with :func:`imubench.sources.registry.open_source`
(the simulated DataLogExtended / DataLog firmware on a pty, read through real pyserial,
virtual clock: the firmware runs as fast as the host reads) and iterates its batches until
the sample index covers ``--frames`` firmware frames (default 20000) or the source ends
(``duration_s``). Reading stops after the first batch that reaches the target, so a
shortened run may cover up to one batch (256 frames) more than asked.

Columns:

- frames: firmware frames in the index range read, ``last index + 1`` (the index counts
  frame periods since the first frame, so a frame lost on the line is a hole in it).
- decoded: samples in the batches; lost_samples, bad_frames, reconnects: the source's
  counters (``Source.counters``). Check (PASS/FAIL): decoded + lost_samples == frames,
  i.e. the source's loss counter accounts for every hole in the index (docs/sensortile.md,
  "Batches").
- frames/s: frames / wall seconds of the reading loop (open and close excluded). CPU
  seconds (``time.process_time``, the firmware thread included: it runs in this process)
  are printed next to it because the machine is shared.
- x kit: frames/s over the real kit's frame rate, 1 / frame period (binary DataLogExtended
  10 ms -> 100 frames/s; ASCII DataLog 20 ms -> 50 frames/s).
- B/frame: bytes received on the port per frame that arrived (good + bad frames as counted
  by the link; byte stuffing, checksum and terminator included, command replies too).
- x link: frames/s over the physical limit of the link, ``1e6 / (B/frame)`` frames/s,
  taking ~1 MB/s as the payload a USB CDC full-speed bulk endpoint carries (USB 2.0
  spec. §5.8.4: at most 19 64-byte bulk transactions per 1 ms frame = 1.216 MB/s
  before protocol overhead and host scheduling).
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import time
from dataclasses import dataclass

from imubench.sources.registry import open_source
from imubench.sources.sensortile import SensorTileSource

LINK_PAYLOAD_BPS = 1e6
"""USB CDC full-speed payload, bytes/s (approximate; see the module docstring)."""

URIS: tuple[str, ...] = (
    "sensortile-sim://?seed=1&duration_s=200",
    "sensortile-sim://?seed=1&duration_s=200&corrupt_rate=1e-3",
    "sensortile-sim://?seed=1&duration_s=200&corrupt_rate=1e-3&unplug_every_s=60"
    "&replug_after_s=0.5",
    "sensortile-sim://?mode=ascii&seed=1&duration_s=400",
)


@dataclass
class Row:
    """One measured URI."""

    uri: str
    frames: int
    decoded: int
    lost: int
    bad_frames: int
    reconnects: int
    wall_s: float
    cpu_s: float
    kit_rate_hz: float
    bytes_per_frame: float

    @property
    def ok(self) -> bool:
        """Loss account: every frame of the index range is decoded or counted lost."""
        return self.decoded + self.lost == self.frames

    @property
    def rate(self) -> float:
        """Frames per wall second."""
        return self.frames / self.wall_s

    @property
    def link_limit(self) -> float:
        """Frames/s the link could carry at :data:`LINK_PAYLOAD_BPS`."""
        return LINK_PAYLOAD_BPS / self.bytes_per_frame


def measure(uri: str, target: int) -> Row:
    """Read ``uri`` until its index covers ``target`` frames or it ends; return the row."""
    src = open_source(uri)
    assert isinstance(src, SensorTileSource)
    decoded, last = 0, -1
    with src:
        w0, c0 = time.perf_counter(), time.process_time()
        for batch in src:
            decoded += len(batch)
            last = int(batch.index[-1])
            if last + 1 >= target:
                break
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        counters = dict(src.counters)
        link = dict(src.link.counters)
    arrived = link["frames"] + link["bad_frames"]
    return Row(
        uri=uri,
        frames=last + 1,
        decoded=decoded,
        lost=counters["lost_samples"],
        bad_frames=counters["bad_frames"],
        reconnects=counters["reconnects"],
        wall_s=wall,
        cpu_s=cpu,
        kit_rate_hz=src.info.odr_hz,
        bytes_per_frame=link["bytes"] / max(arrived, 1),
    )


def table(rows: list[Row]) -> str:
    """The rows as a markdown table."""
    head = (
        "| URI parameters | frames | decoded | lost_samples | bad_frames | reconnects | "
        "wall s | CPU s | frames/s | x kit | B/frame | x link | decoded+lost=frames |"
    )
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        lines.append(
            f"| `{r.uri.split('?', 1)[1]}` | {r.frames} | {r.decoded} | {r.lost} | "
            f"{r.bad_frames} | {r.reconnects} | {r.wall_s:.1f} | {r.cpu_s:.1f} | "
            f"{r.rate:.0f} | {r.rate / r.kit_rate_hz:.1f} ({r.kit_rate_hz:g}/s) | "
            f"{r.bytes_per_frame:.1f} | {r.rate / r.link_limit:.3f} ({r.link_limit:,.0f}/s) | "
            f"{'PASS' if r.ok else 'FAIL'} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=20000, help="frames per URI (default 20000)")
    ap.add_argument("--quick", action="store_true", help="2000 frames per URI")
    args = ap.parse_args(argv)
    target = 2000 if args.quick else args.frames
    load = " ".join(f"{v:.2f}" for v in os.getloadavg())
    print(
        f"# bench_sensortile {datetime.date.today()} {platform.node()} {platform.machine()} "
        f"{os.cpu_count()} cores, load {load} (shared machine: throughput is indicative)"
    )
    print(f"# {target} frames per URI (or until the source ends), virtual clock\n")
    rows = [measure(uri, target) for uri in URIS]
    print(table(rows))
    print(
        f"\nx kit: frames/s over the real kit's rate (1 / frame period). x link: frames/s "
        f"over the USB CDC full-speed limit, {LINK_PAYLOAD_BPS:.0e} B/s / (B/frame)."
    )
    for r in rows:
        print(
            f"check {'PASS' if r.ok else 'FAIL'}: decoded {r.decoded} + lost {r.lost} = "
            f"{r.decoded + r.lost} vs frames {r.frames}  ({r.uri})"
        )
    return 0 if all(r.ok for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
