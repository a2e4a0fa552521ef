"""Logging set-up of the ``imubench`` command line and daemon: one stderr handler, ISO 8601
local time with milliseconds and UTC offset, ``-v`` for INFO and ``-vv`` for DEBUG.

Library modules only call ``logging.getLogger(__name__)``; the CLI installs the handler
(:func:`setup_logging`) and removes it when it returns (:func:`remove_logging`), so
calling :func:`imubench.cli.main` repeatedly in one process (tests) leaves nothing behind.
Under systemd, stderr goes to the journal, which keeps its own timestamps too.
"""

from __future__ import annotations

import datetime as dt
import logging
import sys
from typing import TextIO

PROJECT_LOGGERS = ("imubench", "lsm6ds", "lsm6ds_sim")
"""Loggers whose level follows ``-v``; every other library logs WARNING and above."""

FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


class IsoFormatter(logging.Formatter):
    """``2025-01-31T14:02:03.250+01:00 INFO imubench.daemon: message``."""

    def formatTime(self, record: logging.LogRecord, datefmt: str | None = None) -> str:
        stamp = dt.datetime.fromtimestamp(record.created).astimezone()
        return stamp.isoformat(timespec="milliseconds")


class StderrHandler(logging.StreamHandler[TextIO]):
    """Writes to the ``sys.stderr`` of the moment (a test's capture, a redirected stream),
    not to the one that was current when the handler was made."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    @property
    def stream(self) -> TextIO:
        return sys.stderr

    @stream.setter
    def stream(self, value: TextIO) -> None:
        pass


def level_for(verbosity: int) -> int:
    """WARNING, INFO (``-v``), DEBUG (``-vv`` or more)."""
    return (logging.WARNING, logging.INFO, logging.DEBUG)[min(max(verbosity, 0), 2)]


def setup_logging(verbosity: int) -> logging.Handler:
    """Attach the stderr handler to the root logger; set the project loggers' level."""
    handler = StderrHandler()
    handler.setFormatter(IsoFormatter(FORMAT))
    logging.getLogger().addHandler(handler)
    for name in PROJECT_LOGGERS:
        logging.getLogger(name).setLevel(level_for(verbosity))
    return handler


def remove_logging(handler: logging.Handler) -> None:
    """Undo :func:`setup_logging`."""
    logging.getLogger().removeHandler(handler)
    for name in PROJECT_LOGGERS:
        logging.getLogger(name).setLevel(logging.NOTSET)
