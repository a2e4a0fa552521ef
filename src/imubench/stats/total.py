"""Raw (uncorrected) total variances: TOTVAR, MTOTVAR, TTOTVAR, HTOTVAR.

Sources: NIST SP 1065 sections 5.2.11-5.2.13 (eqs. (25)-(30)); D. A. Howe, "The total
deviation approach to long-term characterization of frequency stability", IEEE UFFC 47
(2000); Howe & Vernotte, "Generalization of the total variance approach to the modified
Allan variance", PTTI 1999. Conventions are those of Stable32 (verified against its output
for phase.dat): no bias correction here, it is applied by the caller.

* TOTVAR (eq. (25)): phase extended by inverted reflection at both ends,
  ``x*[-j] = 2 x[0] - x[j]``, ``x*[N-1+j] = 2 x[N-1] - x[N-1-j]``; then
  ``1 / (2 tau^2 (N-2)) sum_{i=1}^{N-2} (x*[i-m] - 2 x*[i] + x*[i+m])^2``.
* MTOTVAR (eq. (27)): for each of the N-3m+1 phase subsequences of 3m points, remove the
  linear trend estimated from the means of the first and last halves (separated by
  ceil(3m/2) points), extend by uninverted even reflection to 9m points, and average the
  6m squared second differences of m-point phase averages; divide by 2 tau^2.
* TTOTVAR (eq. (29)): tau^2 / 3 * MTOTVAR.
* HTOTVAR (eq. (30)): the same construction on frequency subsequences of 3m points, third
  differences of m-point frequency averages, normalised by 1/6; at m = 1 it is OHVAR
  (as Stable32 does).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from imubench.stats import _kernels as _k
from imubench.stats.allan import ohvar
from imubench.stats.prep import PhaseData

Kernel = tuple[float, int, int]
THREADS = max(1, min(8, os.cpu_count() or 1))  # threads for the MTOT / HTOT start sums
THREAD_MIN_WORK = 2_000_000  # z terms below which one thread is faster than starting more
_NO_GAPS = np.zeros(0, dtype=np.int64)


def extended_phase(pd: PhaseData) -> np.ndarray:
    """TOTVAR's reflected phase x* of length 3N - 4; x[0] sits at index N - 2."""
    x = pd.x
    n = x.size
    xe = np.empty(3 * n - 4)
    xe[: n - 2] = 2.0 * x[0] - x[n - 2 : 0 : -1]
    xe[n - 2 : 2 * n - 2] = x
    xe[2 * n - 2 :] = 2.0 * x[-1] - x[-2:0:-1]
    return xe


def totvar(pd: PhaseData, m: int, xe: np.ndarray | None = None) -> Kernel:
    """TOTVAR, SP 1065 eq. (25); terms i = 1..N-2 of the reflected series."""
    n = pd.n_phase
    if xe is None:
        xe = extended_phase(pd)
    count = n - 2
    gp = _NO_GAPS if pd.gap_prefix is None else pd.gap_prefix
    s, valid = _k.totvar_sum(xe, n, m, gp, pd.gap_end_offset)
    valid = int(valid)
    tau = m * pd.tau0_s
    var = float(s) / (2.0 * tau * tau * valid) if valid else float("nan")
    return var, valid, count - valid


def _subseq_meansq_sum(series: np.ndarray, m: int, starts: np.ndarray) -> float:
    """Sum over subsequence starts i of mean_j z_j^2 / m^2 (``_kernels.subseq_meansq_sum``).

    Each subsequence series[i:i+3m] is detrended by the half-means slope, reflected to 9m
    points (uninverted, even), and z_j = C[j] - 2 C[j+m] + C[j+2m] with C the m-point moving
    sums, j = 0..6m-1. The starts are independent: with at least :data:`THREAD_MIN_WORK`
    z terms in all they are cut into :data:`THREADS` contiguous runs summed on parallel
    threads (the kernel releases the GIL); the partial sums are added in a fixed order, so
    the result does not depend on scheduling.
    """
    chunks = THREADS if starts.size * 6 * m >= THREAD_MIN_WORK else 1
    if chunks <= 1 or starts.size < 2 * chunks:
        return float(_k.subseq_meansq_sum(series, m, starts))
    parts = np.array_split(starts, chunks)
    with ThreadPoolExecutor(max_workers=chunks) as pool:
        sums = list(pool.map(lambda st: _k.subseq_meansq_sum(series, m, st), parts))
    return float(sum(sums))


def mtotvar(pd: PhaseData, m: int) -> Kernel:
    """MTOTVAR, SP 1065 eq. (27) (no bias correction)."""
    n = pd.n_phase
    count = n - 3 * m + 1
    starts = np.arange(count, dtype=np.int64)
    if pd.gap_prefix is not None:
        starts = starts[pd.span_ok(starts, starts + 3 * m - 1)]
    if starts.size == 0:
        return float("nan"), 0, count
    msq = _subseq_meansq_sum(pd.x, m, starts)
    tau = m * pd.tau0_s
    return msq / (2.0 * tau * tau * starts.size), int(starts.size), count - starts.size


def ttotvar(pd: PhaseData, m: int) -> Kernel:
    """TTOTVAR = tau^2 / 3 * MTOTVAR, SP 1065 eq. (29) (with tau^2, see allantools note)."""
    v, ok, skipped = mtotvar(pd, m)
    tau = m * pd.tau0_s
    return tau * tau / 3.0 * v, ok, skipped


def htotvar(pd: PhaseData, m: int) -> Kernel:
    """HTOTVAR, SP 1065 eq. (30) (no bias correction); m = 1 gives OHVAR as Stable32."""
    if m == 1:
        return ohvar(pd, 1)
    y = np.diff(pd.x) / pd.tau0_s
    count = y.size - 3 * m + 1
    starts = np.arange(count, dtype=np.int64)
    if pd.gap_prefix is not None:
        starts = starts[pd.span_ok(starts, starts + 3 * m)]
    if starts.size == 0:
        return float("nan"), 0, count
    msq = _subseq_meansq_sum(y, m, starts)
    # msq = sum_i mean_j (z_j / m)^2 with z on frequency sums; Hadamard 1/6 normalisation
    return msq / (6.0 * starts.size), int(starts.size), count - starts.size
