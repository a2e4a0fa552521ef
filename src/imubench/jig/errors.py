"""The jig package's exception family."""

from __future__ import annotations

from imubench.errors import ImubenchError


class JigError(ImubenchError):
    """A station, limits or fixture problem, or a jig run that cannot go on (the message
    says which file, key, fixture command or capture, and what to do)."""


class StationError(JigError):
    """A station or limits setting that keeps a test from judging the board (limits for
    another chip, a limit the suite needs missing, a rate beyond the DUT's full scale):
    the test is INCONCLUSIVE, never a FAIL charged to the board."""


__all__ = ["JigError", "StationError"]
