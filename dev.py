#!/usr/bin/env python3
"""One-command set-up for imubench: creates ``.venv/`` at the repo root, installs the
project (editable, with the ``dev`` extra) when ``pyproject.toml`` changed, then runs.

    python3 dev.py run  [imubench run options]   # the daemon on config/quickstart.toml
    python3 dev.py test [pytest options]         # the whole test suite
    python3 dev.py setup                         # only create/refresh the environment

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


def _digest() -> str:
    return hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()


def setup() -> None:
    if sys.version_info < (3, 11):  # noqa: UP036  (dev.py runs on any system python)
        sys.exit(f"imubench needs Python 3.11 or newer; this is {sys.version.split()[0]}")
    if not (BIN / "python").exists():
        print(f"[dev.py] creating virtual environment {VENV}", flush=True)
        venv.EnvBuilder(with_pip=True, clear=True).create(VENV)
    if STAMP.exists() and STAMP.read_text() == _digest():
        return
    print("[dev.py] installing imubench and its dependencies into .venv", flush=True)
    pip = [str(BIN / "python"), "-m", "pip", "--disable-pip-version-check", "-q"]
    subprocess.run([*pip, "install", "-e", f"{ROOT}[dev]"], check=True)
    STAMP.write_text(_digest())


def main(argv: list[str]) -> int:
    cmd, rest = (argv[0], argv[1:]) if argv else ("", [])
    if cmd not in {"run", "test", "setup"}:
        print(__doc__)
        return 2
    setup()
    os.chdir(ROOT)
    if cmd == "setup":
        return 0
    if cmd == "run":
        if not any(a.startswith("--config") for a in rest):
            rest = ["--config", "config/quickstart.toml", *rest]
        args = [str(BIN / "imubench"), "run", *rest]
    else:
        args = [str(BIN / "python"), "-m", "pytest", *rest]
    os.execv(args[0], args)
    return 0  # not reached


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
