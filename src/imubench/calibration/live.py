"""A calibration applied to a live stream (``imubench run`` and ``acquire``): every batch
corrected (:meth:`Calibration.apply`) and its die temperature watched against the sweep
each sensor's temperature terms were fitted over (``temp_range_c``).

A board that warms past its calibration sweep during a long run gets values the
temperature polynomial extrapolates (docs/calibration.md); the watcher says so when the
die temperature leaves the sweep by more than :data:`TEMP_MARGIN_C` and again when it
comes back, and counts the samples so corrected (``samples_extrapolated``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from imubench.batch import Batch
from imubench.calibration.file import SENSORS, Calibration


class LiveCalibration:
    """``transform`` of a :class:`~imubench.pipeline.Pipeline`: corrects each batch and
    calls ``warn`` (from the acquisition thread) when a sensor's die temperature leaves
    or re-enters its calibration sweep."""

    def __init__(self, calibration: Calibration, where: str,
                 warn: Callable[[str], None]) -> None:
        self.calibration = calibration
        self.where = where
        self._warn = warn
        self.samples_extrapolated = 0
        """Samples corrected with a temperature outside a sensor's sweep (+- margin)."""
        self._outside = {name: False for name in SENSORS}
        self.extrapolated_range_c: dict[str, tuple[float, float]] = {}
        """Per sensor, the lowest and highest die temperature outside its sweep so far."""

    def __call__(self, batch: Batch) -> Batch:
        out = self.calibration.apply(batch)
        if not len(batch):
            return out
        beyond = np.zeros(len(batch), dtype=bool)
        for name in SENSORS:
            sc = getattr(self.calibration, name)
            if sc is None:
                continue
            mask = sc.outside_sweep(batch.temp_c)
            beyond |= mask
            if mask.any():
                t = batch.temp_c[mask]
                lo, hi = self.extrapolated_range_c.get(name, (np.inf, -np.inf))
                self.extrapolated_range_c[name] = (min(lo, float(t.min())),
                                                   max(hi, float(t.max())))
            if mask.any() and not self._outside[name]:
                # the first temperature outside: the range is said when it comes back
                # (the first batch's alone read 89.9 to 91.1 degC on a ramp to 110)
                t0 = float(batch.temp_c[int(np.argmax(mask))])
                self._warn(self.calibration.extrapolation_warning(name, t0, t0, self.where)
                           + " (from here on)")
                self._outside[name] = True
            elif self._outside[name] and not mask[-1]:
                assert sc.temp_range_c is not None
                lo, hi = self.extrapolated_range_c[name]
                self._warn(f"{self.where}: die temperature {batch.temp_c[-1]:.1f} degC, back "
                           f"within the [{name}] calibration's {sc.temp_range_c[0]:.1f} to "
                           f"{sc.temp_range_c[1]:.1f} degC; outside it, it reached "
                           f"{lo:.1f} to {hi:.1f} degC")
                self._outside[name] = False
        self.samples_extrapolated += int(beyond.sum())
        return out
