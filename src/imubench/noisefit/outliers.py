"""Impulsive outliers in a channel? A check before trusting its white-noise level.

The noise terms of :mod:`.fit` are Gaussian; glitches (single-sample spikes) add their
variance to every short-tau Allan point, and the fit reports them as white noise
(measured: the Xsens MTi-G record in the reference data, ~5 % impulsive samples, fits a
white level 2.8 times the one of its glitch-free samples). The check uses the first
differences d_k = y_k - y_(k-1), which remove every slow term (flicker, random walk,
drift, temperature): their robust standard deviation s = 1.4826 MAD (the normal
consistency factor of the median absolute deviation, Rousseeuw & Croux 1993, JASA 88,
1273-1283) and the share of differences beyond :data:`Z_LIMIT` s from their median. A
Gaussian series puts 2e-9 of its differences there; the warning needs both
:data:`MIN_SHARE` and :data:`MIN_COUNT`.
"""

from __future__ import annotations

import numpy as np

Z_LIMIT = 6.0
"""Robust z beyond which a first difference is impulsive."""
MIN_SHARE = 1e-4
"""Share of impulsive differences above which a warning is given."""
MIN_COUNT = 10
"""... and at least this many of them."""


def impulsive_share(y: np.ndarray) -> tuple[float, int, float] | None:
    """(share of impulsive first differences, their count, std / robust std of the
    differences), or None when fewer than 100 differences are finite or the robust
    spread is 0 (a constant or almost constant record)."""
    d = np.diff(np.asarray(y, dtype=float))
    d = d[np.isfinite(d)]
    if d.size < 100:
        return None
    med = float(np.median(d))
    s = 1.4826 * float(np.median(np.abs(d - med)))
    if not s > 0:
        return None
    count = int(np.count_nonzero(np.abs(d - med) > Z_LIMIT * s))
    return count / d.size, count, float(np.std(d)) / s


def outlier_warning(channel: str, y: np.ndarray) -> str | None:
    """A warning, in words, when the channel holds impulsive outliers (module docstring)."""
    found = impulsive_share(y)
    if found is None:
        return None
    share, count, ratio = found
    if share <= MIN_SHARE or count < MIN_COUNT:
        return None
    return (f"{channel}: impulsive outliers or heavy-tailed noise: {count} first "
            f"differences ({100 * share:.2g} %) lie beyond {Z_LIMIT:g} robust standard "
            f"deviations (Gaussian noise puts ~2e-7 % there), a lower bound on the share "
            f"of bad samples (dense or clustered glitches widen the robust spread too: the "
            f"Xsens MTi-G record's 5.4 % read as 0.1 %); the differences' standard "
            f"deviation is {ratio:.3g}x their robust one, so the white level fitted here "
            f"can be up to {ratio:.3g}x that of the clean samples (the Gaussian noise terms "
            "absorb them); imubench gap tests sparse impulses as the 'outliers' effect")
