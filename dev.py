#!/usr/bin/env python3
"""One-command set-up for imubench: creates ``.venv/`` at the repo root, installs the
project (editable, with the ``dev`` extra) when ``pyproject.toml`` changed, compiles the
numba kernels into their cache after an install, then runs.

    python3 dev.py run  [imubench run options]   # the daemon on the shipped quick start
    python3 dev.py test                          # ruff, mypy, then the whole test suite
                                                 # in SUITE_WORKERS processes (xdist)
    python3 dev.py test [pytest options]         # pytest only, with those options
    python3 dev.py setup                         # create/refresh the environment and
                                                 # compile the kernels (NUMBA_CACHE_DIR)

Needs only Python 3.11+ and access to the package index.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
BIN = VENV / ("Scripts" if os.name == "nt" else "bin")
STAMP = VENV / ".imubench-installed"


SUITE_WORKERS = 2
"""Processes (pytest-xdist) the whole suite runs in: most of its time is spent waiting on
real-time daemons, brokers and subprocesses (one process: 10:19 at 44 % of a core; two:
5:57, docs/benchmarks.md). ``python3 dev.py test ARGS`` runs pytest as given."""


def _digest() -> str:
    return hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()


def setup(warm: bool = False) -> None:
    """Create the venv and install when ``pyproject.toml`` changed; compile the numba
    kernels after an install (or always with ``warm``) so the first daemon start and the
    first test do not compile them (cache: ``NUMBA_CACHE_DIR`` when set)."""
    if sys.version_info < (3, 11):  # noqa: UP036  (dev.py runs on any system python)
        sys.exit(f"imubench needs Python 3.11 or newer; this is {sys.version.split()[0]}")
    if not (BIN / "python").exists():
        print(f"[dev.py] creating virtual environment {VENV}", flush=True)
        venv.EnvBuilder(with_pip=True, clear=True).create(VENV)
    if not (STAMP.exists() and STAMP.read_text() == _digest()):
        print("[dev.py] installing imubench and its dependencies into .venv", flush=True)
        pip = [str(BIN / "python"), "-m", "pip", "--disable-pip-version-check", "-q"]
        subprocess.run([*pip, "install", "-e", f"{ROOT}[dev]"], check=True)
        STAMP.write_text(_digest())
        warm = True
    if warm:
        subprocess.run([str(BIN / "python"), "-m", "imubench.warmup"], check=True, cwd=ROOT)


def lint() -> int:
    """``ruff check .`` then ``mypy`` (its files and settings are in pyproject.toml);
    0 when both pass, else the failing tool's status after a one-line hint."""
    for name, cmd in (("ruff", [str(BIN / "ruff"), "check", "."]),
                      ("mypy", [str(BIN / "mypy")])):
        print(f"[dev.py] {' '.join([name, *cmd[1:]])}", flush=True)
        status = subprocess.run(cmd, cwd=ROOT).returncode
        if status:
            print(f"[dev.py] {name} found problems (above): fix them before the tests run; "
                  "`python3 dev.py test -q` runs pytest alone", file=sys.stderr, flush=True)
            return status
    return 0


def ensure_chromium() -> None:
    """Install Debian's chromium for the browser test where that is possible (root, apt,
    not yet installed); quiet, and never a reason for the run to fail: the test skips,
    saying why, without it."""
    if (Path("/usr/bin/chromium").exists() or not hasattr(os, "geteuid")
            or os.geteuid() != 0 or not Path("/usr/bin/apt-get").exists()):
        return
    print("[dev.py] installing chromium for the browser test (apt-get)", flush=True)
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    for cmd in (["apt-get", "update", "-qq"], ["apt-get", "install", "-y", "-qq", "chromium"]):
        try:
            subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                           timeout=600, check=False)
        except (OSError, subprocess.SubprocessError):
            return


def main(argv: list[str]) -> int:
    cmd, rest = (argv[0], argv[1:]) if argv else ("", [])
    if cmd not in {"run", "test", "setup"}:
        print(__doc__)
        return 2
    setup(warm=cmd == "setup")
    os.chdir(ROOT)
    if cmd == "setup":
        return 0
    if cmd == "run":
        args = [str(BIN / "imubench"), "run", *rest]
    else:
        ensure_chromium()
        if not rest and (status := lint()):
            return status
        workers = [] if rest else ["-n", str(SUITE_WORKERS)]
        args = [str(BIN / "python"), "-m", "pytest", *workers, *rest]
    os.execv(args[0], args)
    return 0  # not reached


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
