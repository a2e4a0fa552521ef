"""CLI subcommands; each module has ``register(subparsers)`` and ``run(args)``.

Errors of the project's families propagate to :func:`imubench.cli.main`, which prints
them as ``imubench COMMAND: error: ...`` and exits with 2.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from imubench.errors import ImubenchError


def write_json(doc: Any, dest: str) -> None:
    """Write ``doc`` as indented JSON to the file ``dest``, or to stdout when ``dest`` is
    ``-`` (the ``--json PATH|-`` option of every subcommand)."""
    text = json.dumps(doc, indent=1)
    if dest == "-":
        print(text)
        return
    try:
        Path(dest).write_text(text + "\n", encoding="utf-8")
    except OSError as exc:
        raise ImubenchError(f"--json {dest}: cannot write ({exc.strerror})") from exc
