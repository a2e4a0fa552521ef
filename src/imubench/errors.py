"""The imubench exception family.

Every error says what was wrong, where (file, line, key path, register, field) and what
to do about it; the CLI prints ``str(error)`` on one line and exits non-zero.
"""

from __future__ import annotations


class ImubenchError(Exception):
    """Base of every error raised by imubench on purpose."""


class ConfigError(ImubenchError):
    """A configuration file or override is invalid."""


class RecordingError(ImubenchError):
    """A recording (native or CSV) cannot be read or written."""


class SourceError(ImubenchError):
    """A data source URI is invalid or the source failed."""


class StatsError(ImubenchError):
    """Invalid input to a statistic (too few samples, bad tau, unknown option)."""


class ModelError(ImubenchError):
    """A noise model file is invalid."""
