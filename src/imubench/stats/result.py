"""The one result type shared by every batch statistic (and the streaming engine)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class StatResult:
    """Result of one Allan-family statistic over a list of averaging times.

    Every array has one entry per averaging factor. ``var`` is the variance in the input's
    units squared (rate_dps -> dps^2); ``dev = sqrt(var)``. For the Theo1 family ``tau_s``
    is ``0.75 * m * tau0`` (the Stable32 convention) while ``m`` is the averaging factor.
    ``n`` is Stable32's "#" column (number of terms; Theo1 counts (N - m) * m / 2 terms).
    ``ci_low``/``ci_high`` are deviation limits at ``confidence`` (NaN when unavailable).
    ``bias_factor`` is the factor the raw variance was divided by (1.0 where none applied).
    ``gaps`` counts the terms skipped because they touched a NaN sample.
    """

    stat: str
    data_type: str
    rate_hz: float
    tau_s: np.ndarray
    m: np.ndarray
    n: np.ndarray
    var: np.ndarray
    dev: np.ndarray
    ci_low: np.ndarray
    ci_high: np.ndarray
    alpha: np.ndarray
    edf: np.ndarray
    confidence: float
    bias_corrected: bool
    bias_factor: np.ndarray
    drift: float | None
    gaps: np.ndarray
    notes: tuple[str, ...] = field(default=())

    def __len__(self) -> int:
        return int(self.tau_s.size)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: arrays become lists, NaN becomes None."""

        def lst(a: np.ndarray) -> list[Any]:
            if a.dtype.kind in "iu":
                return [int(v) for v in a]
            return [None if not np.isfinite(v) else float(v) for v in a]

        return {
            "stat": self.stat,
            "data_type": self.data_type,
            "rate_hz": float(self.rate_hz),
            "tau_s": lst(self.tau_s),
            "m": lst(self.m),
            "n": lst(self.n),
            "var": lst(self.var),
            "dev": lst(self.dev),
            "ci_low": lst(self.ci_low),
            "ci_high": lst(self.ci_high),
            "alpha": lst(self.alpha),
            "edf": lst(self.edf),
            "confidence": float(self.confidence),
            "bias_corrected": bool(self.bias_corrected),
            "bias_factor": lst(self.bias_factor),
            "drift": None if self.drift is None else float(self.drift),
            "gaps": lst(self.gaps),
            "notes": list(self.notes),
        }


TIME_DEVIATIONS = frozenset({"tdev", "ttotdev"})
"""Statistics in phase units: TDEV = tau MDEV / sqrt(3) (SP 1065 eq. 17), TTOT alike."""


def dev_unit(unit: str, stat: str = "oadev") -> str:
    """The unit of ``stat``'s deviations of a series in ``unit``: that unit for every
    statistic of rates (frequency data are rates in it; phase data are their integral,
    whose differences over tau give the same unit), that unit times seconds for a time
    deviation (TDEV, TTOT: deg for dps)."""
    if stat not in TIME_DEVIATIONS:
        return unit
    return "deg" if unit == "dps" else f"{unit}*s"
