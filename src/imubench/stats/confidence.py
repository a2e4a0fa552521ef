"""Per-tau EDF and chi-squared deviation limits for a whole result (array form).

The streaming engine's bounded mode keeps, for an overlapping statistic at a large
averaging factor m, only the terms at positions that are multiples of a stride s (a
divisor of m). Its EDF is Greenhall's combined EDF (C. A. Greenhall and W. J. Riley,
"Uncertainty of stability variances based on finite differences", Proc. 35th PTTI, 2003,
section 3.4) with the stride factor ``S = m / s`` instead of ``S = m`` (fully
overlapping). :func:`imubench.stats.edf.edf_greenhall` only takes ``S in {1, m}``, so the
decimated estimator is mapped onto an equivalent call: with ``m' = m / s`` and

* modified variances (MVAR, TVAR; F = 1, L = (d + 1) m):
  ``N' = (d + 1) m' + floor((N - (d + 1) m) / s)``;
* unmodified variances (OAVAR, OHVAR, and OSTDVAR's white-FM OAVAR rule; F = m,
  L = 1 + d m): ``N' = 1 + d m' + floor((N - 1 - d m) / s)``;

``edf_greenhall(alpha, d, m', N', modified, overlapping=True)`` has the same number of
terms ``M = 1 + floor((N - L) / s)``, the same ``S``, ``J`` and ``r = M / S``, hence the
same EDF wherever the result does not depend on F: every modified case, and the unmodified
cases alpha <= 0 and white PM as long as ``m' (d + 1) > J_max = 100`` (otherwise the
finite-F branch would be taken with F = m' instead of m: there the non-overlapping
estimator's EDF, ``S = 1``, a lower bound, is used). For unmodified flicker PM
(alpha = 1) F = m' instead of m is an approximation.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from imubench.errors import StatsError
from imubench.stats.ci import chi2_limits
from imubench.stats.edf import GREENHALL_JMAX, canonical_stat, edf_greenhall
from imubench.stats.edf import edf as edf_one

#: (d, modified) of the overlapping statistics whose EDF follows Greenhall's algorithm.
_STRIDED = {
    "oavar": (2, False),
    "ohvar": (3, False),
    "mvar": (2, True),
    "tvar": (2, True),
    "ostdvar": (2, False),
}


def strided_edf(stat: str, alpha: int, m: int, n_phase: int, stride: int) -> float:
    """EDF of the overlapping ``stat`` at m from only the terms at multiples of ``stride``.

    ``stride = 1`` is the ordinary (fully overlapping) EDF of :func:`edf.edf`. OSTDVAR is
    counted with the white-FM OAVAR rule, as :func:`edf.edf` does for the full estimator.
    """
    if stride == 1:
        return edf_one(stat, alpha, m, n_phase)
    name = canonical_stat(stat)
    if name not in _STRIDED or m % stride:
        raise StatsError(f"strided EDF: {stat!r} at m={m} with stride {stride} is not defined")
    d, modified = _STRIDED[name]
    if name == "ostdvar":
        alpha = 0
    mp = m // stride
    if modified:
        n_eq = (d + 1) * mp + (n_phase - (d + 1) * m) // stride
    elif mp * (d + 1) > GREENHALL_JMAX:
        n_eq = 1 + d * mp + (n_phase - 1 - d * m) // stride
    else:
        # F = m' would take Greenhall's finite-F branch where F = m does not: use the
        # non-overlapping estimator's EDF (S = 1), a lower bound (wider, honest limits)
        return edf_greenhall(int(alpha), d, m, n_phase, False, False)
    return edf_greenhall(int(alpha), d, mp, int(n_eq), modified, True)


Runs = tuple[np.ndarray, np.ndarray]
"""A record's gap-free runs: (their lengths in phase points, how many runs have each)."""


def runs_edf(stat: str, alpha: int, m: int, runs: Runs, stride: int = 1) -> float:
    """EDF of ``stat`` at ``m`` over a record made of independent gap-free runs
    (:data:`Runs`): the sum of the runs' EDFs (:func:`strided_edf` of each run alone; a
    run too short for a term adds none).

    The estimate is the mean over every term that touches no gap, i.e. the runs' own
    estimates weighted by their term counts; Satterthwaite's EDF of such a weighted mean,
    ``(sum w)^2 / sum(w^2 / edf_i)``, is the sum of the EDFs when the weights are
    proportional to them, as term counts and EDFs both grow with the run's length
    (Satterthwaite 1946, Biometrics Bulletin 2(6)). One run (no gap) is
    :func:`strided_edf` itself. Without this, a record with one hole in its middle kept
    the EDF of the whole length at taus where the hole removes half the terms (1 h of an
    ADIS16405 gyro at tau = 655 s: terms 228 929 -> 97 857, EDF 4.7 unchanged; now 3.0).
    Raises :class:`StatsError` like :func:`strided_edf` when there is one run."""
    lengths, counts = runs
    if counts.sum() == 1:
        return strided_edf(stat, alpha, m, int(lengths[0]), stride)
    total = 0.0
    for length, count in zip(lengths.tolist(), counts.tolist(), strict=True):
        try:
            e = strided_edf(stat, alpha, m, length, stride)
        except StatsError:  # too short for a term at this m
            continue
        if np.isfinite(e) and e > 0:
            total += count * e
    return total if total > 0 else float("nan")


def confidence_arrays(
    stat: str,
    alpha: np.ndarray,
    m: np.ndarray,
    runs: int | Sequence[Runs],
    var: np.ndarray,
    confidence: float,
    stride: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(edf, ci_low, ci_high)`` per tau: EDF from :func:`runs_edf` (:func:`strided_edf`
    where ``stride`` > 1), limits from :func:`imubench.stats.ci.chi2_limits`. ``alpha``
    and ``var`` have one entry per m (shape ``(k,)``) or one row per channel (``(channels,
    k)``); ``runs`` is the number of phase points of a gap-free record, or per channel row
    its gap-free runs (:data:`Runs`); the EDF is computed once per distinct (alpha, m,
    runs). Where the EDF is undefined (alpha outside the method's range, too few points)
    or the variance is NaN, the three are NaN."""
    alpha = np.asarray(alpha)
    var = np.asarray(var, dtype=float)
    strides = np.ones(m.shape, np.int64) if stride is None else np.asarray(stride)
    rows = alpha.shape[0] if alpha.ndim > 1 else 1
    per_row = ([(np.array([runs], np.int64), np.ones(1, np.int64))] * rows
               if isinstance(runs, (int, np.integer)) else list(runs))
    edf = np.full(alpha.shape, np.nan)
    cache: dict[tuple[int, int, bytes], float] = {}
    for idx in np.ndindex(alpha.shape):
        i = idx[-1]
        row = per_row[idx[0] if alpha.ndim > 1 else 0]
        key = (int(alpha[idx]), i, row[0].tobytes() + row[1].tobytes())
        e = cache.get(key)
        if e is None:
            try:
                e = runs_edf(stat, key[0], int(m[i]), row, int(strides[i]))
            except StatsError:
                e = float("nan")
            cache[key] = e
        edf[idx] = e
    edf[~np.isfinite(var)] = np.nan  # no variance (every term hit a gap): as compute()
    ok = np.isfinite(edf) & (edf > 0) & np.isfinite(var)
    lo = np.full(alpha.shape, np.nan)
    hi = np.full(alpha.shape, np.nan)
    if ok.any():
        lo[ok], hi[ok] = chi2_limits(var[ok], edf[ok], confidence)
    return edf, lo, hi
