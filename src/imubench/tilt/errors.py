"""The tilt package's exception family."""

from __future__ import annotations

from imubench.errors import ImubenchError


class TiltError(ImubenchError):
    """Bad tilt input or error-budget file (the message names the file, key or option)."""


__all__ = ["TiltError"]
