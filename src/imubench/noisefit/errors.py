"""The noise fit's error type (part of the imubench exception family)."""

from __future__ import annotations

from imubench.errors import ImubenchError


class FitError(ImubenchError):
    """Bad input to the noise fit (too short, constant, unknown term, bad option)."""


__all__ = ["FitError"]
