"""Simulated time: virtual (as fast as the host allows) or paced to the wall clock.

Every simulated device and the simulated bus read the time from one :class:`SimClock`, so
that a driver which sleeps through ``clock.sleep`` and a chip which produces samples at
``clock.now()`` agree on what "now" is. In ``virtual`` mode time only moves when someone
calls :meth:`SimClock.advance` or :meth:`SimClock.sleep` (the bus timing model does, per
transaction); in ``wall`` mode it follows :func:`time.monotonic`.
"""

from __future__ import annotations

import threading
import time

CLOCK_MODES: tuple[str, ...] = ("virtual", "wall")


class SimClock:
    """Simulated seconds since start.

    Args:
        mode: ``"virtual"`` (jumps on :meth:`advance`/:meth:`sleep`) or ``"wall"``
            (``time.monotonic`` based; :meth:`advance` is a no-op).
        start_s: value of :meth:`now` at construction, s.
    """

    def __init__(self, mode: str = "virtual", start_s: float = 0.0) -> None:
        if mode not in CLOCK_MODES:
            raise ValueError(f"SimClock mode {mode!r} must be one of {', '.join(CLOCK_MODES)}")
        self.mode: str = mode
        self._start_s = float(start_s)
        self._virtual_s = float(start_s)
        self._wall0 = time.monotonic()
        self._lock = threading.Lock()

    def now(self) -> float:
        """Simulated seconds since start (plus ``start_s``)."""
        if self.mode == "wall":
            return self._start_s + (time.monotonic() - self._wall0)
        return self._virtual_s

    def advance(self, dt_s: float) -> None:
        """Move virtual time forward by ``dt_s`` seconds (no-op on a wall clock)."""
        if dt_s < 0:
            raise ValueError(f"SimClock.advance: dt_s={dt_s} must not be negative")
        if self.mode == "virtual":
            with self._lock:
                self._virtual_s += dt_s

    def sleep(self, dt_s: float) -> None:
        """Virtual: :meth:`advance`; wall: :func:`time.sleep`."""
        if dt_s <= 0:
            return
        if self.mode == "virtual":
            self.advance(dt_s)
        else:
            time.sleep(dt_s)

    def __repr__(self) -> str:
        return f"SimClock(mode={self.mode!r}, now={self.now():.6f})"
