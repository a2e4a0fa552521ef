"""Theo1, TheoBR and TheoH kernels (raw, no bias correction).

Theo1 (D. A. Howe and T. K. Peppler, "Very long-term frequency stability: estimation using
a special-purpose statistic", IEEE FCS 2003; NIST SP 1065 eq. (31)), for even m,
tau = 0.75 m tau0 (Stable32 reports this tau; the variance itself uses m tau0):

    Theo1(m) = 1 / (0.75 (N-m) (m tau0)^2) sum_{i=0}^{N-m-1} sum_{d=0}^{m/2-1}
               1/(m/2-d) [(x_i - x_{i-d+m/2}) + (x_{i+m} - x_{i+d+m/2})]^2

With a = m/2 - d and the lag-a first difference D_a(i) = x_i - x_{i+a}, the bracket is
D_a(i) - D_a(i + m - a). Expanding the square, the sum over i is two windowed sums of
D_a^2 minus twice the lag-(m-a) autocorrelation of D_a, which is exact over the full
valid range. A few averaging factors are summed directly (O(N m / 2) each, squares of
exact differences); many closely spaced ones (TheoBR's support, ``taus="all"``) go through
FFT autocorrelations of D_a, summed over blocks of consecutive a in the frequency domain so
that one inverse FFT serves a whole block (:func:`_theo1_fft_blocks`): O(N log N) per a for
every m at once. :func:`fft_count` splits a sorted set between the two by a cost model.

TheoBR (SP 1065 eq. (32), Howe & Tasset 2004): Theo1 scaled by
kf = 1/(n+1) sum_{i=0}^{n} OAVAR(m=9+3i) / Theo1(m=12+4i), n = floor(0.1 N / 3 - 3).
TheoH (SP 1065 eq. (33)): OAVAR for tau <= 0.1 T (T = (N-1) tau0), TheoBR beyond.
"""

from __future__ import annotations

import os
from collections.abc import Callable

import numpy as np
import scipy.fft

from imubench.errors import StatsError
from imubench.stats import _kernels as _k
from imubench.stats.prep import PhaseData

_NO_ROWS = np.zeros(0, dtype=np.bool_)

FFT_BLOCK = 16  # consecutive a summed in the frequency domain before one inverse FFT
FFT_COST = 2.0  # one real FFT of length P costs about FFT_COST * P log2 P multiply-adds
FFT_WORKERS = max(1, min(2, os.cpu_count() or 1))  # threads of scipy.fft (2-core target)


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
    out = np.empty(srt.size)
    out[order] = theo1_sums_nogap(pd.x, srt, fft_count(srt, pd.n_phase), progress)
    rows_all = pd.n_phase - ms
    return out, rows_all, np.zeros_like(rows_all)


def theo1_sums_nogap(
    x: np.ndarray,
    srt: np.ndarray,
    n_fft: int,
    progress: Callable[[float], None] | None = None,
) -> np.ndarray:
    """S(m) for sorted even ``srt`` on gap-free phase: the first ``n_fft`` averaging factors by
    blocked FFT autocorrelations (:func:`_theo1_fft_blocks`), the others directly."""
    sums = np.zeros(srt.size)
    if n_fft > 0:
        sums[:n_fft] = _theo1_fft_blocks(x, srt[:n_fft], progress)
    if n_fft < srt.size:
        sums[n_fft:] = _k.theo1_direct(x, srt[n_fft:], 1, _NO_ROWS)
    return sums


def _fft_len(n: int, m_hi: int) -> int:
    """FFT length with no circular wrap for lags up to m_hi - 1 of a series of n - 1 points."""
    return int(scipy.fft.next_fast_len(n + m_hi, real=True))


def fft_count(srt: np.ndarray, n: int) -> int:
    """How many of the sorted averaging factors to give to the blocked FFT path.

    Cost model (in units of one multiply-add over the data): the FFT path costs one real
    FFT of length P per a <= m_hi / 2, about :data:`FFT_COST` P log2 P, plus the irfft per
    block; the direct path costs (m / 2)(N - m) per m. The split minimising the sum is
    chosen (the many closely spaced TheoBR support factors go to the FFT, a few octave
    factors far above them stay direct)."""
    direct = (srt / 2.0) * (n - srt)
    tail = np.concatenate([np.cumsum(direct[::-1])[::-1], [0.0]])
    best, best_j = tail[0], 0
    for j in range(1, srt.size + 1):
        p = _fft_len(n, int(srt[j - 1]))
        cost = (srt[j - 1] / 2.0) * FFT_COST * p * np.log2(p) + tail[j]
        if cost < best:
            best, best_j = cost, j
    return best_j


def _theo1_fft_blocks(
    x: np.ndarray, srt: np.ndarray, progress: Callable[[float], None] | None
) -> np.ndarray:
    """S(m) for sorted even ``srt`` from per-a FFTs, summed over a in the frequency domain.

    For a fixed a the m-th bracket sum is W_a(m) - 2 R_a(m - a) with W_a two windowed sums
    of D_a^2 (totals minus short head/tail sums) and R_a(L) = sum_i D_a(i) D_a(i + L) the full-range
    autocorrelation of D_a. R_a(m - a) is the value at lag m of R_a delayed by a, whose
    spectrum is |F_a|^2 exp(-2 pi i k a / P) (F_a the zero-padded DFT of D_a, P >= N + m_hi
    so nothing wraps). Within a block of :data:`FFT_BLOCK` consecutive a the shifted
    spectra weighted by 1/a are summed and inverted once, giving sum_a R_a(m - a) / a for
    every m at once; that is valid for the m that need every a of the block (m >= 2 a_last);
    the few m inside the block's range (2 a_first <= m < 2 a_last) take their a >= a_first
    terms from the direct kernel instead. The forward FFTs of a block are one batched call
    (:data:`FFT_WORKERS` threads). Squares of D_a enter through FFTs of D_a, not of x:
    the rounding is relative to sum D_a^2, as in the per-lag sums.
    """
    n = x.size
    m_hi = int(srt[-1])
    a_max = m_hi // 2
    p = _fft_len(n, m_hi)
    sums = np.zeros(srt.size)
    buf = np.empty((FFT_BLOCK, p))
    spec = np.empty(p // 2 + 1, dtype=np.complex128)
    ph = (-2.0 * np.pi / p) * np.arange(p // 2 + 1)
    wr, wi = np.cos(ph), np.sin(ph)
    er, ei = wr.copy(), wi.copy()  # exp(-2 pi i k a / P) at a = 1, advanced per a
    for a0 in range(1, a_max + 1, FFT_BLOCK):
        a_last = min(a0 + FFT_BLOCK - 1, a_max)
        k_part = int(np.searchsorted(srt, 2 * a0))
        k_full = int(np.searchsorted(srt, 2 * a_last))
        if k_full > k_part:  # m in [2 a0, 2 a_last): a = a0 .. m/2 directly
            sums[k_part:k_full] += _k.theo1_direct(x, srt[k_part:k_full], a0, _NO_ROWS)
        nb = a_last - a0 + 1
        sel = srt[k_full:]
        rows = buf[:nb]
        sums[k_full:] += _k.diff_rows_windows(x, a0, rows, sel).sum(axis=0)
        f = scipy.fft.rfft(rows, axis=1, workers=FFT_WORKERS)
        _k.shifted_power_sum(f, a0, wr, wi, er, ei, spec)
        sums[k_full:] -= 2.0 * scipy.fft.irfft(spec, p, workers=FFT_WORKERS)[sel]
        if progress is not None:
            progress(a_last / a_max)
    return sums


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
