"""Progress bars (tqdm) for commands that can run longer than a few seconds.

One helper for every command::

    from imubench.progress import progress

    with progress(total=n_samples, desc="sim", unit="sample") as bar:
        for batch in source:
            ...
            bar.update(len(batch))

    with progress(total=100, desc="oadev", unit="%") as bar:  # a callback giving a fraction
        compute(..., progress=bar.fraction)

Bars go to stderr, never to stdout (so ``--json -`` output stays clean), and are shown
when stderr is a terminal, after the first second; ``--progress on`` shows them at once
whatever stderr is, ``--progress off`` never (:func:`set_mode`, called by
:func:`imubench.cli.main`).
"""

from __future__ import annotations

import sys
from types import TracebackType
from typing import Literal

from tqdm import tqdm

Mode = Literal["auto", "on", "off"]
MODES: tuple[Mode, ...] = ("auto", "on", "off")

_mode: Mode = "auto"


def set_mode(mode: Mode) -> None:
    """``auto`` (bars when stderr is a terminal), ``on`` or ``off``; process-wide, as the
    terminal it describes."""
    global _mode
    if mode not in MODES:
        raise ValueError(f"progress mode {mode!r}; choose one of {', '.join(MODES)}")
    _mode = mode


def enabled() -> bool:
    """Whether a bar made now would be shown."""
    if _mode == "auto":
        return sys.stderr.isatty()
    return _mode == "on"


class Progress:
    """A tqdm bar on stderr (or nothing, when disabled) with a context manager."""

    def __init__(self, total: float | None, desc: str, unit: str = "it") -> None:
        self.total = total
        self._bar = tqdm(
            total=total, desc=desc, unit=unit, file=sys.stderr, disable=not enabled(),
            delay=0.0 if _mode == "on" else 1.0, mininterval=0.5, leave=False,
            dynamic_ncols=True,
        )

    def update(self, n: float = 1) -> None:
        """Advance by ``n`` units."""
        self._bar.update(n)

    def fraction(self, done: float) -> None:
        """Set the position to ``done`` times ``total`` (for callbacks that report the
        fraction of work done, 0..1, like ``imubench.stats.compute(progress=...)``)."""
        if self.total is None:
            return
        target = min(max(done, 0.0), 1.0) * self.total
        if target > self._bar.n:
            self._bar.update(target - self._bar.n)

    def close(self) -> None:
        """Draw the final position once (throttled updates may have skipped it) if the
        bar is showing (past its delay), then clear the bar."""
        if not self._bar.disable and self._bar.format_dict["elapsed"] >= self._bar.delay:
            self._bar.refresh()
        self._bar.close()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


def progress(total: float | None, desc: str, unit: str = "it") -> Progress:
    """A progress bar of ``total`` units (None: a counter without an end)."""
    return Progress(total, desc, unit)


__all__ = ["MODES", "Progress", "enabled", "progress", "set_mode"]
