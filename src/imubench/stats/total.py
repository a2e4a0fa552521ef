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

from collections.abc import Callable

import numpy as np

from imubench.stats.allan import ohvar
from imubench.stats.prep import PhaseData

Kernel = tuple[float, int, int]
CHUNK_ELEMS = 1 << 21


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
    o = n - 2
    count = n - 2
    d = xe[o + 1 - m : o + n - 1 - m] + xe[o + 1 + m : o + n - 1 + m]
    d -= 2.0 * xe[o + 1 : o + n - 1]
    if pd.gap_prefix is not None:
        i = np.arange(1, n - 1, dtype=np.int64)
        ok = pd.span_ok(np.maximum(0, i - m), np.minimum(n - 1, i + m))
        d = d[ok]
    valid = int(d.size)
    tau = m * pd.tau0_s
    var = float(np.dot(d, d)) / (2.0 * tau * tau * valid) if valid else float("nan")
    return var, valid, count - valid


def _reflect_index(m: int) -> np.ndarray:
    r = np.arange(3 * m, dtype=np.int64)
    return np.concatenate([r[::-1], r, r[::-1]])


def _subseq_meansq(
    series: np.ndarray, m: int, starts: np.ndarray, progress: Callable[[int], None] | None
) -> np.ndarray:
    """Per subsequence start i: mean over the 6m terms of (second difference of m-sums)^2.

    Each subsequence series[i:i+3m] is detrended by the half-means slope, reflected to 9m
    points (uninverted, even), and z_j = C[j] - 2 C[j+m] + C[j+2m] with C the m-point moving
    sums, j = 0..6m-1. Returns mean_j z_j^2 / m^2.
    """
    n3 = 3 * m
    h1 = n3 // 2
    h2 = n3 - h1  # ceil(3m/2): separation of the two half means, in samples
    p = np.empty(series.size + 1)
    p[0] = 0.0
    np.cumsum(series, out=p[1:])
    rel = _reflect_index(m)
    relf = rel.astype(np.float64)
    out = np.empty(starts.size)
    chunk = max(1, CHUNK_ELEMS // (9 * m))
    for c0 in range(0, starts.size, chunk):
        st = starts[c0 : c0 + chunk]
        mean1 = (p[st + h1] - p[st]) / h1
        mean2 = (p[st + n3] - p[st + h2]) / (n3 - h2)
        slope = (mean2 - mean1) / h2
        xs = series[st[:, None] + rel[None, :]]
        xs -= slope[:, None] * relf[None, :]
        cs = np.zeros((st.size, 9 * m + 1))
        np.cumsum(xs, axis=1, out=cs[:, 1:])
        z = cs[:, 3 * m : 9 * m] - cs[:, 0 : 6 * m]
        z -= 3.0 * cs[:, 2 * m : 8 * m]
        z += 3.0 * cs[:, m : 7 * m]
        out[c0 : c0 + chunk] = np.einsum("ij,ij->i", z, z) / (6.0 * m * m * m)
        if progress is not None:
            progress(st.size)
    return out


def mtotvar(pd: PhaseData, m: int, progress: Callable[[int], None] | None = None) -> Kernel:
    """MTOTVAR, SP 1065 eq. (27) (no bias correction)."""
    n = pd.n_phase
    count = n - 3 * m + 1
    starts = np.arange(count, dtype=np.int64)
    if pd.gap_prefix is not None:
        starts = starts[pd.span_ok(starts, starts + 3 * m - 1)]
    if starts.size == 0:
        return float("nan"), 0, count
    msq = _subseq_meansq(pd.x, m, starts, progress)
    tau = m * pd.tau0_s
    return float(msq.sum()) / (2.0 * tau * tau * starts.size), int(starts.size), count - starts.size


def ttotvar(pd: PhaseData, m: int, progress: Callable[[int], None] | None = None) -> Kernel:
    """TTOTVAR = tau^2 / 3 * MTOTVAR, SP 1065 eq. (29) (with tau^2, see allantools note)."""
    v, ok, skipped = mtotvar(pd, m, progress)
    tau = m * pd.tau0_s
    return tau * tau / 3.0 * v, ok, skipped


def htotvar(pd: PhaseData, m: int, progress: Callable[[int], None] | None = None) -> Kernel:
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
    msq = _subseq_meansq(y, m, starts, progress)
    # msq = mean_j (z_j / m)^2 with z on frequency sums; Hadamard 1/6 normalisation
    return float(msq.sum()) / (6.0 * starts.size), int(starts.size), count - starts.size
