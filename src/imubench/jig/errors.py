"""The jig package's exception family."""

from __future__ import annotations

from imubench.errors import ImubenchError


class JigError(ImubenchError):
    """A station, limits or fixture problem, or a jig run that cannot go on (the message
    says which file, key, fixture command or capture, and what to do)."""


__all__ = ["JigError"]
