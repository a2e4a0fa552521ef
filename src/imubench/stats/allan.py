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

Sums are taken in blocks (``BLOCK`` terms) with in-place float64 operations so peak memory
stays at about one block beyond the phase array.
"""

from __future__ import annotations

import numpy as np

from imubench.stats.prep import PhaseData

BLOCK = 1 << 15

Kernel = tuple[float, int, int]


def _blocked_sumsq(
    pd: PhaseData,
    count: int,
    lags: tuple[int, ...],
    coefs: tuple[float, ...],
    span: int,
    step: int = 1,
) -> tuple[float, int]:
    """sum over k < count of (sum_j coefs[j] * x[k*step + lags[j]])^2, skipping gapped spans.

    ``span`` is the phase-point extent of a term (its points are k*step .. k*step + span).
    Returns (sum of squares, number of valid terms).
    """
    x = pd.x
    total = 0.0
    valid = 0
    buf = np.empty(min(BLOCK, max(count, 1)))
    tmp = np.empty_like(buf)
    for k0 in range(0, count, BLOCK):
        k1 = min(count, k0 + BLOCK)
        start = k0 * step
        stop = (k1 - 1) * step + 1
        d = buf[: k1 - k0]
        np.multiply(x[start + lags[0] : stop + lags[0] : step], coefs[0], out=d)
        for lag, c in zip(lags[1:], coefs[1:], strict=True):
            seg = x[start + lag : stop + lag : step]
            if c == 1.0:
                d += seg
            elif c == -1.0:
                d -= seg
            else:
                np.multiply(seg, c, out=tmp[: k1 - k0])
                d += tmp[: k1 - k0]
        if pd.gap_prefix is not None:
            a = np.arange(k0, k1, dtype=np.int64) * step
            ok = pd.span_ok(a, a + span)
            dd = d[ok]
            valid += int(ok.sum())
            total += float(np.dot(dd, dd))
        else:
            valid += k1 - k0
            total += float(np.dot(d, d))
    return total, valid


def avar(pd: PhaseData, m: int) -> Kernel:
    """Non-overlapping Allan variance, SP 1065 eq. (7) on phase decimated by m."""
    n_dec = (pd.n_phase - 1) // m + 1
    count = n_dec - 2
    s, ok = _blocked_sumsq(pd, count, (0, m, 2 * m), (1.0, -2.0, 1.0), 2 * m, step=m)
    tau = m * pd.tau0_s
    return _norm(s, ok, 2.0 * tau * tau), ok, count - ok


def oavar(pd: PhaseData, m: int) -> Kernel:
    """Overlapping Allan variance, SP 1065 eq. (11)."""
    count = pd.n_phase - 2 * m
    s, ok = _blocked_sumsq(pd, count, (2 * m, m, m, 0), (1.0, -1.0, -1.0, 1.0), 2 * m)
    tau = m * pd.tau0_s
    return _norm(s, ok, 2.0 * tau * tau), ok, count - ok


def hvar(pd: PhaseData, m: int) -> Kernel:
    """Non-overlapping Hadamard variance (1/6 normalisation), SP 1065 eq. (18)."""
    n_dec = (pd.n_phase - 1) // m + 1
    count = n_dec - 3
    s, ok = _blocked_sumsq(pd, count, (0, m, 2 * m, 3 * m), (1.0, -3.0, 3.0, -1.0), 3 * m, step=m)
    tau = m * pd.tau0_s
    return _norm(s, ok, 6.0 * tau * tau), ok, count - ok


def ohvar(pd: PhaseData, m: int) -> Kernel:
    """Overlapping Hadamard variance (1/6 normalisation), SP 1065 eq. (19)."""
    count = pd.n_phase - 3 * m
    s, ok = _blocked_sumsq(pd, count, (0, m, 2 * m, 3 * m), (1.0, -3.0, 3.0, -1.0), 3 * m)
    tau = m * pd.tau0_s
    return _norm(s, ok, 6.0 * tau * tau), ok, count - ok


def phase_prefix(pd: PhaseData) -> np.ndarray:
    """S[k] = sum(x[:k]) (length N + 1), for m-sample phase averages in O(1)."""
    s = np.empty(pd.n_phase + 1)
    s[0] = 0.0
    np.cumsum(pd.x, out=s[1:])
    return s


def mvar(pd: PhaseData, m: int, prefix: np.ndarray | None = None) -> Kernel:
    """Modified Allan variance, SP 1065 eq. (15), via the phase prefix sum S.

    The inner sum over m second differences equals S[j+3m] - 3 S[j+2m] + 3 S[j+m] - S[j].
    """
    s_arr = phase_prefix(pd) if prefix is None else prefix
    count = pd.n_phase - 3 * m + 1
    sub = PhaseData(s_arr, pd.tau0_s, pd.gap_prefix, pd.gap_end_offset)
    s, ok = _blocked_sumsq(sub, count, (3 * m, 2 * m, m, 0), (1.0, -3.0, 3.0, -1.0), 3 * m - 1)
    tau = m * pd.tau0_s
    return _norm(s, ok, 2.0 * m * m * tau * tau), ok, count - ok


def tvar(pd: PhaseData, m: int, prefix: np.ndarray | None = None) -> Kernel:
    """Time variance TVAR = tau^2 / 3 * MVAR (SP 1065 eq. (17)), in seconds^2."""
    v, ok, skipped = mvar(pd, m, prefix)
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
