"""Reading a TOML file with one-line errors that name the file (the jig's station and
limits files, calibration files, tilt error budgets)."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any


def read_toml(path: str | Path, what: str,
              error: type[Exception]) -> tuple[dict[str, Any], str]:
    """(parsed table, text) of ``path``; a file that cannot be read or is not TOML
    raises ``error`` with ``<path>: cannot read the <what> (...)`` / ``not valid TOML``."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise error(f"{p}: cannot read the {what} ({exc.strerror})") from None
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{p}: not valid TOML: {exc}") from None


__all__ = ["read_toml"]
