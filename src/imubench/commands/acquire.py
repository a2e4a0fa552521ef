"""``imubench acquire SOURCE --duration-s S --out REC [--stats-json PATH]``: one recording.

The source is any registered URI (``sim://``, ``i2c://``, ``sensortile://``, ...). Every
hole in the sample index is written as an explicit gap with its reason (FIFO overrun,
chip reset, ...). The stats JSON holds the source counters (``samples``, ``gaps``,
``lost_samples``, ``overruns``, ``bus_bytes``, ``io_errors``, ``retries``, ``bad_frames``,
``reconnects``) plus ``bus_utilization``, ``expected_samples``, ``duration_s`` (source
seconds elapsed) and, for chips streaming with timestamps, ``measured_odr_hz`` (the ODR
measured against the host clock: a crystal error shows here).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

from imubench.errors import SourceError
from imubench.recording import STORAGE_RAW, open_writer
from imubench.sources.base import Source
from imubench.sources.registry import open_source


def add_duration(uri: str, duration_s: float) -> str:
    """``uri`` with ``duration_s=`` set (kept if the URI has it already)."""
    if "duration_s=" in uri:
        return uri
    return uri + ("&" if "?" in uri else "?") + f"duration_s={duration_s:g}"


def source_metadata(src: Source) -> dict[str, Any]:
    info = dataclasses.asdict(src.info)
    meta: dict[str, Any] = {k: v for k, v in info.items() if k != "config"}
    meta["source_config"] = info["config"]
    if info.get("gyro_sensitivity_dps") and info.get("accel_sensitivity_g"):
        meta["storage"] = STORAGE_RAW
    return meta


def record(src: Source, out: Path) -> dict[str, Any]:
    """Read ``src`` to its end into the recording ``out``; return the stats."""
    with src:
        writer = open_writer(out, source_metadata(src))
        last = -1
        try:
            for batch in src:
                gaps = batch.meta.get("gaps", []) if batch.meta else []
                reasons = {int(at): str(reason) for at, _, reason in gaps}  # type: ignore[misc]
                if batch.raw is None and getattr(writer, "storage", "") == STORAGE_RAW:
                    raise SourceError("source delivered no raw counts for raw storage")
                writer.write(batch, reasons)
                last = int(batch.index[-1])
            # gaps after the last delivered sample (end of a finite stream)
            for at, lost, reason in getattr(src, "gap_log", []):
                if at - lost > last:
                    writer.write_gap(at, lost, reason)
        finally:
            writer.close()
    stats: dict[str, Any] = dict(src.counters)
    stats["bus_utilization"] = float(getattr(src, "bus_utilization", 0.0))
    n_total = getattr(src, "n_total", None)
    if n_total is not None:
        stats["expected_samples"] = n_total
    stats["duration_s"] = float(getattr(src, "elapsed_s", 0.0))
    measured = getattr(src, "measured_odr_hz", None)
    if measured is not None:
        stats["measured_odr_hz"] = float(measured)
    return stats


def record_uri(uri: str, out: Path, stats_json: Path | None) -> dict[str, Any]:
    """Open the source ``uri``, record it to ``out`` and write the counters to
    ``stats_json`` (if given); returns the counters (see :func:`record`)."""
    stats = record(open_source(uri), out)
    if stats_json is not None:
        stats_json.write_text(json.dumps(stats, indent=2, sort_keys=True) + "\n")
    return stats


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "acquire",
        help="record a source to a file",
        description="Acquire from SOURCE (a URI such as sim://lsm6dsl?odr_hz=104 or "
        "i2c:///dev/i2c-1?chip=lsm6dsl&addr=0x6a) for --duration-s seconds into --out "
        "(.imbr native or .csv). Gaps are recorded explicitly.",
    )
    p.add_argument("source", metavar="SOURCE")
    p.add_argument("--duration-s", type=float, required=True)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--stats-json", type=Path, default=None)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.duration_s <= 0:
        raise SourceError(f"--duration-s {args.duration_s} must be > 0")
    stats = record_uri(add_duration(args.source, args.duration_s), args.out, args.stats_json)
    print(
        f"{args.out}: {stats['samples']} samples, {stats['gaps']} gaps, "
        f"{stats['lost_samples']} lost, {stats['overruns']} overruns, "
        f"{stats['io_errors']} I/O errors"
    )
    return 0
