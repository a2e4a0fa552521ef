"""Per-tau EDF and chi-squared deviation limits for a whole result (array form)."""

from __future__ import annotations

import numpy as np

from imubench.errors import StatsError
from imubench.stats.ci import chi2_limits
from imubench.stats.edf import edf as edf_one


def confidence_arrays(
    stat: str,
    alpha: np.ndarray,
    m: np.ndarray,
    n_phase: int,
    var: np.ndarray,
    confidence: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(edf, ci_low, ci_high)`` per tau: EDF from :func:`imubench.stats.edf.edf`,
    limits from :func:`imubench.stats.ci.chi2_limits`. Where the EDF is undefined
    (alpha outside the method's range, too few points) the three are NaN."""
    edf = np.full(m.shape, np.nan)
    for i, (a, mm) in enumerate(zip(alpha, m, strict=True)):
        try:
            edf[i] = edf_one(stat, int(a), int(mm), n_phase)
        except StatsError:
            continue
    ok = np.isfinite(edf) & (edf > 0) & np.isfinite(var)
    lo = np.full(m.shape, np.nan)
    hi = np.full(m.shape, np.nan)
    if ok.any():
        lo[ok], hi[ok] = chi2_limits(var[ok], edf[ok], confidence)
    return edf, lo, hi
