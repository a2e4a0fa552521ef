"""Taking back a write that failed half-way, so a recording never ends in a partial record.

A full disk (ENOSPC, EDQUOT) or an I/O error can hit in the middle of a record: the
bytes before it are on disk, the rest in the writer's buffer. The writers remember the
file's size after each whole batch; on an error they call :func:`cut_back`, which drops
the buffer and cuts the file to that size (shrinking a file needs no free space), so
the file holds whole batches only and the caller counts the failed batch, and nothing
else, as not recorded. (Also :func:`need_parent`: the writers' one rule for where a new
file may go; and :func:`replace_text`, a small file written whole or not at all.)
"""

from __future__ import annotations

import contextlib
import logging
import os
from pathlib import Path
from typing import IO, Any

from imubench.errors import RecordingError

log = logging.getLogger(__name__)


def need_parent(path: Path) -> None:
    """RecordingError unless the directory ``path`` goes into exists: writers never create
    directories; a caller that means to (the daemon's ``log.path``) creates it first."""
    parent = path.parent
    if not parent.is_dir():
        raise RecordingError(f"{path}: the directory {parent} does not exist; create it "
                             "first (or give another output path)")


def cut_back(path: Path, fh: IO[Any], size: int) -> None:
    """Close ``fh`` without writing its buffer further, and cut ``path`` to ``size`` bytes.

    A close that flushes into a disk whose space the cut freed could append the partial
    record again, so the file is closed first (its flush may fail: ignored) and cut after.
    """
    with contextlib.suppress(OSError):
        fh.close()
    try:
        fd = os.open(path, os.O_WRONLY)
    except OSError as exc:
        log.error("%s: cannot reopen to cut the partial record off: %s", path, exc)
        return
    try:
        os.ftruncate(fd, size)
        os.fsync(fd)
    except OSError as exc:
        log.error("%s: cannot cut the partial record off at byte %d: %s", path, size, exc)
    finally:
        os.close(fd)


def replace_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` whole or not at all: into ``path.tmp``, flushed to disk,
    then renamed over ``path`` (POSIX rename is atomic). On an error (a full disk) the
    temporary file is removed and the OSError raised: a reader never finds a cut file
    (a jig's ``result.json`` was left cut at byte 8192, invalid JSON)."""
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
