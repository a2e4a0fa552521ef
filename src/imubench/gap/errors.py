"""The error of the sim-to-real diagnosis."""

from __future__ import annotations

from imubench.errors import ImubenchError


class GapError(ImubenchError):
    """Bad input to ``imubench gap`` (the message names the file, channel, flag or key)."""
