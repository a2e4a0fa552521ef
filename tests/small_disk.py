"""A small tmpfs for tests of a disk that fills."""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest


@contextlib.contextmanager
def small_tmpfs(tmp_path: Path, size: str = "64k") -> Iterator[Path]:
    """A tmpfs of ``size`` mounted in ``tmp_path`` (a disk that fills); the test is
    skipped where mounting is not allowed (needs root and mount)."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None or subprocess.run(
            ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(disk)],
            capture_output=True).returncode:
        pytest.skip("cannot mount a small tmpfs here (needs root and mount)")
    try:
        yield disk
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True)
