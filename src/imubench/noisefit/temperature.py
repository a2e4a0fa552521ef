"""Does a channel's rate follow the die temperature? A check before trusting a noise fit.

The noise terms of :mod:`.fit` are stationary noise; a rate that drifts with a varying
temperature (the ``temp_coeff`` of a model file) shows in the Allan variance as extra
random walk or flicker at long taus, and the fit then reports those inflated (measured: a
0.01 dps/degC sensitivity over a 4 degC, 900 s cycle gave a random walk 60 times the
true one). The check: block means of the rate and of the temperature over blocks of
:data:`BLOCK_S`, the least-squares slope of one on the other, and its t statistic with the
residuals' lag-1 autocorrelation r counted by the effective number of blocks
n (1 - r) / (1 + r) (the AR(1) variance-inflation rule, e.g. Bretherton et al. 1999,
J. Climate 12, 1990-2009, eq. 31).
"""

from __future__ import annotations

import math

import numpy as np

BLOCK_S = 30.0
"""Block length (s) of the means the slope is fitted to."""
MIN_BLOCKS = 20
MIN_TEMP_SPREAD_C = 0.2
"""Standard deviation of the temperature block means (degC) below which nothing is said."""
T_LIMIT = 5.0
"""|t| above which the rate is said to follow the temperature."""


def _block_means(a: np.ndarray, n: int, m: int) -> np.ndarray:
    """Means of n blocks of m samples over their finite values (NaN for a block without)."""
    blocks = np.asarray(a[: n * m], dtype=float).reshape(n, m)
    ok = np.isfinite(blocks)
    count = ok.sum(axis=1)
    total = np.where(ok, blocks, 0.0).sum(axis=1)
    return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def temperature_slope(y: np.ndarray, temp_c: np.ndarray, rate_hz: float
                      ) -> tuple[float, float, int] | None:
    """(slope per degC, t statistic, blocks) of the rate's block means on the temperature's,
    or None when the record is too short or the temperature too steady to tell."""
    m = max(int(BLOCK_S * rate_hz), 1)
    n = min(len(y), len(temp_c)) // m
    if n < MIN_BLOCKS:
        return None
    yb, tb = _block_means(y, n, m), _block_means(temp_c, n, m)
    ok = np.isfinite(yb) & np.isfinite(tb)
    yb, tb = yb[ok], tb[ok]
    if len(yb) < MIN_BLOCKS or float(np.std(tb)) < MIN_TEMP_SPREAD_C:
        return None
    x = tb - tb.mean()
    slope = float(x @ (yb - yb.mean()) / (x @ x))
    res = yb - yb.mean() - slope * x
    r = float(np.corrcoef(res[:-1], res[1:])[0, 1]) if np.std(res) > 0 else 0.0
    r = min(max(r, 0.0), 0.95) if math.isfinite(r) else 0.0
    n_eff = max(len(yb) * (1 - r) / (1 + r), 3.0)
    se = math.sqrt(float(res @ res) / max(n_eff - 2, 1.0) / float(x @ x)) * math.sqrt(
        len(yb) / n_eff)
    return slope, (slope / se if se > 0 else math.inf), len(yb)


def temperature_warning(channel: str, unit: str, y: np.ndarray, temp_c: np.ndarray,
                        rate_hz: float) -> str | None:
    """A warning, in words, when the rate follows the temperature (|t| > T_LIMIT)."""
    found = temperature_slope(y, temp_c, rate_hz)
    if found is None or abs(found[1]) <= T_LIMIT:
        return None
    slope, t, n = found
    what = "rate" if channel.startswith("g") else "acceleration"
    return (f"{channel}: the {what} follows the die temperature ({slope:.3g} {unit}/degC, "
            f"t {t:.1f} over {n} blocks of {BLOCK_S:g} s); the fitted long-tau terms "
            "(random walk, flicker) include that drift: fit a recording at constant "
            "temperature, or model the temperature effect (imubench gap)")
