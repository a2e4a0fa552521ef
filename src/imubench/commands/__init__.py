"""CLI subcommands; each module has ``register(subparsers)`` and ``run(args)``.

Errors of the project's families propagate to :func:`imubench.cli.main`, which prints
them as ``imubench COMMAND: error: ...`` and exits with 2 (every exit status is decided
there). Conventions: every option has a help text; a ``PATH|-`` option writes to stdout
for ``-`` (:func:`write_json`), and the human summary then goes to stderr
(:func:`summary_stream`); progress bars come from :func:`imubench.progress.progress`.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any, TextIO

from imubench.errors import ImubenchError


def check_writable(dest: str | Path | None, option: str) -> None:
    """ImubenchError, before a long computation, when the output file ``dest`` of
    ``option`` cannot be written there: its folder is missing or is not a folder, or
    ``dest`` is a folder. ``None`` and ``-`` (stdout) pass."""
    if dest is None or str(dest) == "-":
        return
    path = Path(dest)
    folder = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise ImubenchError(f"{option} {dest}: is a folder; give a file name")
    if not folder.is_dir():
        raise ImubenchError(f"{option} {dest}: the folder {folder} does not exist")


def write_json(doc: Any, dest: str, option: str = "--json") -> None:
    """Write ``doc`` as indented JSON to the file ``dest``, or to stdout when ``dest`` is
    ``-`` (the ``--json PATH|-`` option of every subcommand; ``option`` names it in an
    error)."""
    text = json.dumps(doc, indent=1)
    if dest == "-":
        print(text)
        return
    try:
        Path(dest).write_text(text + "\n", encoding="utf-8")
    except OSError as exc:
        raise ImubenchError(f"{option} {dest}: cannot write ({exc.strerror})") from exc


def summary_stream(*json_dests: str | Path | None) -> TextIO:
    """Where a command's human-readable summary goes: stdout, unless one of its JSON
    outputs is ``-`` (stdout then carries only that JSON)."""
    return sys.stderr if any(str(d) == "-" for d in json_dests if d is not None) else sys.stdout
