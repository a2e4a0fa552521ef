"""Raw (uncorrected) variances of the Allan family from phase data, vectorised.

Every kernel takes :class:`~imubench.stats.prep.PhaseData` and an averaging factor m and
returns ``(var, n_terms, n_skipped)``: the variance, the number of terms summed (Stable32's
"#" column) and the number of terms skipped because they touched a gap. Formulas are
NIST SP 1065 (W. J. Riley, Handbook of Frequency Stability Analysis, 2008), tau = m tau0:

* AVAR  eq. (7):  1 / (2 tau^2 (N'-2)) sum (x[i+2] - 2 x[i+1] + x[i])^2 over x decimated by m
* OAVAR eq. (11): 1 / (2 tau^2 (N-2m)) sum_{i} (x[i+2m] - 2 x[i+m] + x[i])^2
* MVAR  eq. (15): 1 / (2 m^2 tau^2 (N-3m+1)) sum_j (sum_{i=j}^{j+m-1} x[i+2m]-2x[i+m]+x[i])^2
* HVAR  eq. (18) and OHVAR eq. (19): third differences, normalised by 1/6 as SP 1065 and
  Stable32 (the ST application note's filter chain uses 0.5: we do not follow it).
* STDVAR / OSTDVAR: sample variance (N-1 denominator) of the m-sample frequency averages,
  non-overlapping / overlapping (SP 1065 eq. (1) applied to averages).

Each tau is one compiled pass over the phase (``_kernels``): no temporaries, so peak memory
stays at the phase array plus O(1).
"""

from __future__ import annotations

import numpy as np

from imubench.stats import _kernels as _k
from imubench.stats.prep import PhaseData

_NO_GAPS = np.zeros(0, dtype=np.int64)

Kernel = tuple[float, int, int]


def _sumsq(pd: PhaseData, m: int, step: int, count: int, order: int) -> tuple[float, int]:
    """Sum of squared order-2/3 differences at lag m over ``count`` terms (compiled loop)."""
    if count <= 0:
        return 0.0, 0
    gp = _NO_GAPS if pd.gap_prefix is None else pd.gap_prefix
    s, ok = _k.sumsq_diff(pd.x, m, step, count, order, gp, pd.gap_end_offset)
    return float(s), int(ok)


def avar(pd: PhaseData, m: int) -> Kernel:
    """Non-overlapping Allan variance, SP 1065 eq. (7) on phase decimated by m."""
    n_dec = (pd.n_phase - 1) // m + 1
    count = n_dec - 2
    s, ok = _sumsq(pd, m, m, count, 2)
    tau = m * pd.tau0_s
    return _norm(s, ok, 2.0 * tau * tau), ok, count - ok


def oavar(pd: PhaseData, m: int) -> Kernel:
    """Overlapping Allan variance, SP 1065 eq. (11)."""
    count = pd.n_phase - 2 * m
    s, ok = _sumsq(pd, m, 1, count, 2)
    tau = m * pd.tau0_s
    return _norm(s, ok, 2.0 * tau * tau), ok, count - ok


def hvar(pd: PhaseData, m: int) -> Kernel:
    """Non-overlapping Hadamard variance (1/6 normalisation), SP 1065 eq. (18)."""
    n_dec = (pd.n_phase - 1) // m + 1
    count = n_dec - 3
    s, ok = _sumsq(pd, m, m, count, 3)
    tau = m * pd.tau0_s
    return _norm(s, ok, 6.0 * tau * tau), ok, count - ok


def ohvar(pd: PhaseData, m: int) -> Kernel:
    """Overlapping Hadamard variance (1/6 normalisation), SP 1065 eq. (19)."""
    count = pd.n_phase - 3 * m
    s, ok = _sumsq(pd, m, 1, count, 3)
    tau = m * pd.tau0_s
    return _norm(s, ok, 6.0 * tau * tau), ok, count - ok


def mvar(pd: PhaseData, m: int) -> Kernel:
    """Modified Allan variance, SP 1065 eq. (15): the inner sum of m second differences
    slides by one term per output term (``_kernels.mvar_sum``), one pass per tau."""
    count = pd.n_phase - 3 * m + 1
    if count <= 0:
        return float("nan"), 0, 0
    gp = _NO_GAPS if pd.gap_prefix is None else pd.gap_prefix
    s, ok = _k.mvar_sum(pd.x, m, gp, pd.gap_end_offset)
    tau = m * pd.tau0_s
    return _norm(float(s), int(ok), 2.0 * m * m * tau * tau), int(ok), count - int(ok)


def tvar(pd: PhaseData, m: int) -> Kernel:
    """Time variance TVAR = tau^2 / 3 * MVAR (SP 1065 eq. (17)), in seconds^2."""
    v, ok, skipped = mvar(pd, m)
    tau = m * pd.tau0_s
    return tau * tau / 3.0 * v, ok, skipped


def _averages(pd: PhaseData, m: int, step: int) -> np.ndarray:
    x = pd.x
    count = (pd.n_phase - 1 - m) // step + 1
    a = np.arange(count, dtype=np.int64) * step
    ybar = (x[a + m] - x[a]) / (m * pd.tau0_s)
    if pd.gap_prefix is not None:
        ybar = ybar[pd.span_ok(a, a + m)]
    return ybar


def stdvar(pd: PhaseData, m: int) -> Kernel:
    """Sample variance (N-1) of non-overlapping m-sample frequency averages."""
    count = (pd.n_phase - 1) // m
    yb = _averages(pd, m, m)
    return _sample_var(yb), yb.size, count - yb.size


def ostdvar(pd: PhaseData, m: int) -> Kernel:
    """Sample variance (N-1) of overlapping m-sample frequency averages."""
    count = pd.n_phase - m
    yb = _averages(pd, m, 1)
    return _sample_var(yb), yb.size, count - yb.size


def _sample_var(yb: np.ndarray) -> float:
    if yb.size < 2:
        return float("nan")
    return float(np.var(yb, ddof=1))


def _norm(s: float, n: int, denom: float) -> float:
    return s / (denom * n) if n > 0 else float("nan")
