"""The imubench exception family.

Every error says what was wrong, where (file, line, key path, register, field) and what
to do about it; the CLI prints ``str(error)`` on one line and exits non-zero.
"""

from __future__ import annotations

from lsm6ds.errors import LSM6DSError
from lsm6ds_sim.errors import ModelError, ProfileError, SimError


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


# The simulator's family (lsm6ds_sim knows nothing of imubench): re-exported here because
# imubench reads and writes noise model files through it.
USER_ERRORS: tuple[type[Exception], ...] = (ImubenchError, SimError, LSM6DSError)
"""Every error family whose message the CLI prints on one line (exit code 2)."""

__all__ = [
    "USER_ERRORS",
    "ConfigError",
    "ImubenchError",
    "LSM6DSError",
    "ModelError",
    "ProfileError",
    "RecordingError",
    "SimError",
    "SourceError",
    "StatsError",
]
