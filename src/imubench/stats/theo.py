"""Theo1, TheoBR and TheoH kernels (raw, no bias correction).

Theo1 (D. A. Howe and T. K. Peppler, "Very long-term frequency stability: estimation using
a special-purpose statistic", IEEE FCS 2003; NIST SP 1065 eq. (31)), for even m,
tau = 0.75 m tau0 (Stable32 reports this tau; the variance itself uses m tau0):

    Theo1(m) = 1 / (0.75 (N-m) (m tau0)^2) sum_{i=0}^{N-m-1} sum_{d=0}^{m/2-1}
               1/(m/2-d) [(x_i - x_{i-d+m/2}) + (x_{i+m} - x_{i+d+m/2})]^2

With a = m/2 - d and the lag-a first difference D_a(i) = x_i - x_{i+a}, the bracket is
D_a(i) - D_a(i + m - a). Expanding the square, the sum over i is two windowed sums of
D_a^2 (prefix sums) minus twice the lag-(m-a) autocorrelation of D_a, which is exact over
the full valid range. So each a is visited once for all m: either one dot product per m or,
when many m need that a (TheoBR), one FFT autocorrelation for all lags at once.
Cost: O(N * max(m)/2) instead of O(N m^2 / 2) for brute force.

TheoBR (SP 1065 eq. (32), Howe & Tasset 2004): Theo1 scaled by
kf = 1/(n+1) sum_{i=0}^{n} OAVAR(m=9+3i) / Theo1(m=12+4i), n = floor(0.1 N / 3 - 3).
TheoH (SP 1065 eq. (33)): OAVAR for tau <= 0.1 T (T = (N-1) tau0), TheoBR beyond.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.fft

from imubench.errors import StatsError
from imubench.stats import _kernels as _k
from imubench.stats.prep import PhaseData

_NO_ROWS = np.zeros(0, dtype=np.bool_)

FFT_MIN_LAGS = 48  # use an FFT autocorrelation when at least this many m share an a


def theo1_sums(
    pd: PhaseData, ms: np.ndarray, progress: Callable[[float], None] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each even m: (S(m), rows used, rows skipped) with S the double sum above."""
    ms = np.asarray(ms, dtype=np.int64)
    if ms.size == 0:
        z = np.zeros(0)
        return z, z.astype(np.int64), z.astype(np.int64)
    if np.any(ms % 2) or np.any(ms < 2) or np.any(ms > pd.n_phase - 1):
        raise StatsError(f"Theo1 needs even 2 <= m <= N-1 = {pd.n_phase - 1}, got {ms}")
    if pd.gap_prefix is not None:
        return _theo1_sums_gaps(pd, ms)
    order = np.argsort(ms)
    srt = ms[order]
    sums = np.zeros(srt.size)
    a_split = _fft_a_limit(srt, pd.n_phase)
    if a_split > 1:
        _theo1_fft_part(pd.x, srt, a_split, sums, progress)
    sums += _k.theo1_direct(pd.x, srt, a_split, _NO_ROWS)
    out = np.empty_like(sums)
    out[order] = sums
    rows_all = pd.n_phase - ms
    return out, rows_all, np.zeros_like(rows_all)


def _fft_a_limit(srt: np.ndarray, n: int) -> int:
    """Smallest a from which the direct sums are cheaper than one FFT autocorrelation.

    For a given a every m >= 2a needs one O(N) pass directly, against one FFT pair of
    about N log2 N work for all of them: FFT below the first a where fewer than
    :data:`FFT_MIN_LAGS` averaging factors still need it."""
    a = 1
    while a <= int(srt[-1]) // 2:
        if srt.size - int(np.searchsorted(srt, 2 * a)) < FFT_MIN_LAGS:
            return a
        a += 1
    return a


def _theo1_fft_part(
    x: np.ndarray,
    srt: np.ndarray,
    a_split: int,
    sums: np.ndarray,
    progress: Callable[[float], None] | None,
) -> None:
    """Add the a < a_split terms: per a, windowed sums of D_a^2 from a prefix sum and the
    lag-(m-a) autocorrelation of D_a from one FFT, for every m >= 2a at once."""
    n = x.size
    cs = np.empty(n + 1)
    d = np.empty(n)
    for a in range(1, a_split):
        k0 = int(np.searchsorted(srt, 2 * a))
        sel = srt[k0:]
        da = d[: n - a]
        np.subtract(x[: n - a], x[a:], out=da)
        cs[0] = 0.0
        np.cumsum(da * da, out=cs[1 : n - a + 1])
        rows = n - sel
        lags = sel - a
        total = cs[n - a]
        sq = cs[rows] + (total - cs[lags])
        nfft = scipy.fft.next_fast_len(int(n - a + lags.max() + 1), real=True)
        f = scipy.fft.rfft(da, nfft)
        ac = scipy.fft.irfft(f.real * f.real + f.imag * f.imag, nfft)
        sums[k0:] += (sq - 2.0 * ac[lags]) / a
        if progress is not None and a % 64 == 0:
            progress(a / a_split)


def _theo1_sums_gaps(pd: PhaseData, ms: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Direct evaluation skipping rows i whose span i..i+m touches a gap."""
    n = pd.n_phase
    sums = np.zeros(ms.size)
    used = np.zeros(ms.size, dtype=np.int64)
    skipped = np.zeros(ms.size, dtype=np.int64)
    for k, m in enumerate(ms):
        m = int(m)
        rows = n - m
        i = np.arange(rows, dtype=np.int64)
        ok = np.asarray(pd.span_ok(i, i + m))
        used[k] = int(ok.sum())
        skipped[k] = rows - used[k]
        sums[k] = _k.theo1_direct(pd.x, np.array([m], dtype=np.int64), 1, ok)[0]
    return sums, used, skipped


def theo1var(
    pd: PhaseData, ms: np.ndarray, progress: Callable[[float], None] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Raw Theo1 variance per even m; returns (var, terms, skipped terms) with Stable32's
    term count (rows) * m / 2."""
    ms = np.asarray(ms, dtype=np.int64)
    sums, rows, skipped = theo1_sums(pd, ms, progress)
    tau = ms * pd.tau0_s
    with np.errstate(invalid="ignore", divide="ignore"):
        var = sums / (0.75 * rows * tau * tau)
    return var, rows * (ms // 2), skipped * (ms // 2)


def theobr_n(n_phase: int) -> int:
    """n = floor(0.1 N / 3 - 3) of SP 1065's TheoBR; needs n >= 0 (N >= 90)."""
    return int(np.floor(0.1 * n_phase / 3.0 - 3.0))


def theobr_kf(
    pd: PhaseData,
    oavar_fn: Callable[[PhaseData, int], tuple[float, int, int]],
    theo1_at: dict[int, float],
) -> float:
    """Bias-removal ratio kf = mean_i OAVAR(9+3i) / Theo1(12+4i), i = 0..n."""
    nb = theobr_n(pd.n_phase)
    if nb < 0:
        raise StatsError(f"TheoBR needs at least 90 phase points (N={pd.n_phase})")
    ratios = [oavar_fn(pd, 9 + 3 * i)[0] / theo1_at[12 + 4 * i] for i in range(nb + 1)]
    return float(np.mean(ratios))


def theobr_support_m(n_phase: int) -> np.ndarray:
    """The Theo1 averaging factors 12 + 4 i, i = 0..n, that kf needs."""
    nb = theobr_n(n_phase)
    return 12 + 4 * np.arange(max(nb + 1, 0), dtype=np.int64)
