"""The calibration package's exception family."""

from __future__ import annotations

from imubench.errors import ImubenchError


class CalibrationError(ImubenchError):
    """A calibration cannot be fitted, read, written or applied (the message says which
    file, key, sensor or axis, and what to do)."""


__all__ = ["CalibrationError"]
