"""Where a board's results are kept: ``REPORT_DIR/<serial>/<run id>/``.

A run id is the UTC start time ``YYYYmmddTHHMMSSZ`` (``-2``, ``-3``, ... appended when
that directory exists); the directory is created exclusively, so a re-test always adds a
run and never overwrites one. ``REPORT_DIR/<serial>/history.jsonl`` gets one line per
finished run (run id, verdict, time, station), appended.
"""

from __future__ import annotations

import datetime as dt
import json
import re
from pathlib import Path
from typing import Any

from imubench.jig.errors import JigError

SERIAL_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")
HISTORY_FILE = "history.jsonl"


def check_serial(serial: str) -> str:
    """A serial number usable as a directory name (letters, digits, ``. _ -``)."""
    if not SERIAL_RE.match(serial) or serial in (".", ".."):
        raise JigError(f"serial number {serial!r}: use 1 to 64 letters, digits, '.', '_' or"
                       " '-', starting with a letter or digit")
    return serial


def new_run_dir(report_dir: str | Path, serial: str, now: dt.datetime | None = None) -> Path:
    """Create and return a fresh run directory for ``serial``."""
    board = Path(report_dir) / check_serial(serial)
    board.mkdir(parents=True, exist_ok=True)
    stamp = (now or dt.datetime.now(dt.UTC)).strftime("%Y%m%dT%H%M%SZ")
    for k in range(1, 10_000):
        run = board / (stamp if k == 1 else f"{stamp}-{k}")
        try:
            run.mkdir()
        except FileExistsError:
            continue
        return run
    raise JigError(f"{board}: cannot create a new run directory for {stamp}")


def append_history(run_dir: Path, entry: dict[str, Any]) -> None:
    with (run_dir.parent / HISTORY_FILE).open("a", encoding="utf-8") as fh:
        fh.write(json.dumps(entry, separators=(",", ":")) + "\n")


def runs(report_dir: str | Path, serial: str) -> list[Path]:
    """The run directories of a board, oldest first."""
    board = Path(report_dir) / check_serial(serial)
    return sorted(p for p in board.iterdir() if p.is_dir()) if board.is_dir() else []


__all__ = ["HISTORY_FILE", "append_history", "check_serial", "new_run_dir", "runs"]
