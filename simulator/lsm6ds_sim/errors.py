"""Exception family of the :mod:`lsm6ds_sim` simulator (it knows nothing of imubench).

Every error says what was wrong and where (file, table, key, line).
"""

from __future__ import annotations


class SimError(Exception):
    """Base of every error the simulator raises on purpose."""


class ModelError(SimError, ValueError):
    """A noise model (file or object) or a physics parameter is invalid."""


class ProfileError(SimError, ValueError):
    """A temperature profile specification or replay file is invalid."""
