"""Equivalent degrees of freedom (EDF) of the Allan-family variance estimators.

The EDF turns an estimated variance into chi-squared confidence limits (see ``ci.py``).
Everything here follows what Stable32 does, so that the limits match its "Min Sigma" /
"Max Sigma" columns:

* AVAR, OAVAR, MVAR, TVAR, HVAR, OHVAR: Greenhall's combined algorithm,
  C. A. Greenhall and W. J. Riley, "Uncertainty of stability variances based on finite
  differences", Proc. 35th PTTI Meeting, 2003 (sections 3.1-3.6, tables 1-3).
* TOTVAR: NIST SP 1065 (W. J. Riley, *Handbook of Frequency Stability Analysis*, 2008),
  section 5.2.11 table: ``edf = b (T/tau) - c``; noise types outside WFM..RWFM fall back to
  the simple formulas of SP 1065 section 5.3 (Stein 1985) plus :data:`SIMPLE_EDF_OFFSET`,
  as Stable32's limits show.
* MTOTVAR, TTOTVAR: ``edf = b (T/tau) - c`` (SP 1065 section 5.2.12 form), with Stable32's
  switch to the MVAR EDF at short tau; see :data:`MTOT_EDF_COEFFICIENTS` for where the
  coefficients come from.
* HTOTVAR: ``edf = (T/tau) / (b0 + b1 tau/T)`` (D. A. Howe et al., "A total estimator of
  the Hadamard function used for GPS operations", 32nd PTTI, 2000; SP 1065 section 5.2.14)
  for m >= 16; below that, and for PM noise, the simple formulas plus
  :data:`SIMPLE_EDF_OFFSET` (from Stable32's HTOT limits, see there).
* Theo1, TheoBR, TheoH: SP 1065 section 5.2.15 (D. A. Howe and T. K. Peppler, "Very
  long-term frequency stability: estimation using a special-purpose statistic", 2003).
* STDVAR: N/m - 1 (averaged frequency samples minus the mean); OSTDVAR: the overlapping
  sample variance of the m-averages, counted with the white-FM OAVAR rule (see below).

``n_phase`` is always the number of phase points N (number of frequency samples + 1), and
T/tau = N / m here (Stable32 uses the number of data points over the averaging factor).
"""

from __future__ import annotations

import math
from functools import lru_cache

from imubench.errors import StatsError

__all__ = [
    "GREENHALL_JMAX",
    "MTOT_EDF_COEFFICIENTS",
    "SIMPLE_EDF_OFFSET",
    "edf",
    "edf_greenhall",
    "edf_simple",
]

#: Greenhall's J_max: above it the basic sum is replaced by the asymptotic tables.
GREENHALL_JMAX = 100

# Greenhall & Riley 2003, table 1 (modified variances, F = 1): (a0, a1) by alpha, d.
_TABLE1: dict[int, dict[int, tuple[float, float]]] = {
    2: {1: (2 / 3, 1 / 3), 2: (7 / 9, 1 / 2), 3: (22 / 25, 2 / 3)},
    1: {1: (0.840, 0.345), 2: (0.997, 0.616), 3: (1.141, 0.843)},
    0: {1: (1.079, 0.368), 2: (1.033, 0.607), 3: (1.184, 0.848)},
    -1: {2: (1.048, 0.534), 3: (1.180, 0.816)},
    -2: {2: (1.302, 0.535), 3: (1.175, 0.777)},
    -3: {3: (1.194, 0.703)},
    -4: {3: (1.489, 0.702)},
}
# Table 2 (unmodified variances, F = m): (a0, a1) by alpha, d.
_TABLE2: dict[int, dict[int, tuple[float, float]]] = {
    2: {1: (3 / 2, 1 / 2), 2: (35 / 18, 1.0), 3: (231 / 100, 3 / 2)},
    1: {1: (78.6, 25.2), 2: (790.0, 410.0), 3: (9950.0, 6520.0)},
    0: {1: (2 / 3, 1 / 6), 2: (2 / 3, 1 / 3), 3: (7 / 9, 1 / 2)},
    -1: {2: (0.852, 0.375), 3: (0.997, 0.617)},
    -2: {2: (1.079, 0.368), 3: (1.033, 0.607)},
    -3: {3: (1.053, 0.553)},
    -4: {3: (1.302, 0.535)},
}
# Table 3 (flicker PM, unmodified): (b0, b1) by d, for the log term b0 + b1 ln(m).
_TABLE3: dict[int, tuple[float, float]] = {1: (6.0, 4.0), 2: (15.23, 12.0), 3: (47.8, 40.0)}

#: (d, F is m [else 1], S is m [else 1]) of each Greenhall-family variance.
_GREENHALL_PARAMS: dict[str, tuple[int, bool, bool]] = {
    "avar": (2, True, False),
    "oavar": (2, True, True),
    "mvar": (2, False, True),
    "tvar": (2, False, True),
    "hvar": (3, True, False),
    "ohvar": (3, True, True),
}

#: TOTVAR, SP 1065 section 5.2.11 table (Howe 1999): alpha -> (b, c), edf = b N/m - c.
#: TOTVAR: alpha -> (b, c) in edf = b N/m - c (Howe & Greenhall, "Total variance: a
#: progress report on a new frequency stability characterization", 29th PTTI, 1997), with
#: the unrounded values of W. J. Riley's EDF library (``TotvarEDF`` in edf4.c, the
#: functions Stable32 calls); SP 1065 section 5.2.11 prints them rounded (1.50, 0), (1.17,
#: 0.22), (0.93, 0.36).
TOTVAR_EDF_COEFFICIENTS: dict[int, tuple[float, float]] = {
    0: (1.500, 0.0),
    -1: (1.16832, 0.222),
    -2: (0.92715, 0.358),
}

#: MTOTVAR and TTOTVAR: alpha -> (b, c) in edf = b N/m - c.
#: SP 1065 section 5.2.12 lists the ORIGINAL values (1.90, 2.10) WPM, (1.20, 1.40) FPM,
#: (1.10, 1.20) WFM, (0.85, 0.50) FFM, (0.75, 0.31) RWFM, which do not reproduce Stable32's
#: limits. Stable32 uses D. A. Howe's revised values (e-mail of 2000-05-20, as recorded in
#: W. J. Riley's EDF library, ``ModTotvarEDF`` in edf4.c, "New values per D. Howe"), below.
#: Session 2 had fitted (1.334, 1.90) WFM and (1.731, 2.99) FPM to the phasedat MTOT/TTOT
#: files before this source was found: the same numbers to the printed precision.
MTOT_EDF_COEFFICIENTS: dict[int, tuple[float, float]] = {
    2: (2.16, 2.28),
    1: (1.73, 2.99),
    0: (1.33, 1.89),
    -1: (0.92, 0.76),
    -2: (0.79, 0.37),
}
#: Stable32 uses the MVAR EDF for MTOT/TTOT below this averaging factor.
MTOT_MIN_M = 10

#: HTOTVAR, Howe et al. 2000 / SP 1065 section 5.2.14: alpha -> (b0, b1),
#: edf = (N/m) / (b0 + b1 m/N); flicker-walk and random-run FM (alpha -3, -4) from the
#: final draft of that paper as recorded in Riley's EDF library (``HadTotvarEDF``, edf4.c).
HTOTVAR_EDF_COEFFICIENTS: dict[int, tuple[float, float]] = {
    0: (0.559, 1.004),
    -1: (0.868, 1.140),
    -2: (0.938, 1.696),
    -3: (0.974, 2.554),
    -4: (1.276, 3.149),
}
#: Stable32 uses the simple formulas for HTOT below this averaging factor.
HTOT_MIN_M = 16
#: Added to the simple-formula EDF wherever Stable32 falls back to it (HTOT at m < 16 and
#: at PM noise; TOTVAR at PM noise). Empirical, not published: Stable32's HTOT limits
#: (phasedat htotdev octave runs, N = 1001) imply edf = simple + 2 in all 15 such rows
#: (white PM m = 1..256, white FM m = 1..8, flicker PM m = 128, 256): with the offset
#: every one matches to <= 1.8e-4 (exact chi-squared; without it 2.2e-4..6.8e-4, and
#: 2.6e-3 / 1.4e-2 at flicker PM). No N or m shift of the simple formulas fits the three
#: noise types at once. The TOTVAR flicker-PM rows of the Keysight TIC run agree (with
#: Stable32's chi-squared: 4.0e-5 -> 1.6e-5 at AF 2048, 1.2e-4 -> 1.7e-5 at AF 4096).
#: Unchecked for FFM/RWFM at m < 16 (no reference row).
SIMPLE_EDF_OFFSET = 2.0


# --------------------------------------------------------------------------------------
# Greenhall's algorithm
# --------------------------------------------------------------------------------------


def _sw(t: float, alpha: int) -> float:
    """Generalised autocovariance of the pure power-law process w(t), G&R 2003 eq. (7)."""
    t = abs(t)
    if alpha == 2:
        return -t
    if alpha == 1:
        return t * t * math.log(t) if t != 0.0 else 0.0
    if alpha == 0:
        return t**3
    if alpha == -1:
        return -(t**4) * math.log(t) if t != 0.0 else 0.0
    if alpha == -2:
        return -(t**5)
    if alpha == -3:
        return t**6 * math.log(t) if t != 0.0 else 0.0
    if alpha == -4:
        return t**7
    raise StatsError(f"Greenhall EDF: noise exponent alpha={alpha} outside -4..2")


def _sx(t: float, F: float, alpha: int) -> float:
    """Autocovariance of the (filtered) phase, G&R 2003 eq. (8); F = inf uses sw(alpha+2)."""
    if math.isinf(F):
        return _sw(t, alpha + 2)
    return F * F * (2.0 * _sw(t, alpha) - _sw(t - 1.0 / F, alpha) - _sw(t + 1.0 / F, alpha))


def _sz(t: float, F: float, alpha: int, d: int) -> float:
    """Autocovariance of the d-th phase difference, G&R 2003 eq. (9).

    sz(t) = sum_{k=-d..d} (-1)^k C(2d, d+k) sx(t + k).
    """
    total = 0.0
    for k in range(-d, d + 1):
        total += (-1) ** k * math.comb(2 * d, d + k) * _sx(t + k, F, alpha)
    return total


def _basic_sum(J: int, M: float, S: float, F: float, alpha: int, d: int) -> float:
    """BasicSum of G&R 2003 eq. (10).

    sz(0)^2 + (1 - J/M) sz(J/S)^2 + 2 sum_{j=1}^{J-1} (1 - j/M) sz(j/S)^2.
    """
    total = _sz(0.0, F, alpha, d) ** 2 + (1.0 - J / M) * _sz(J / S, F, alpha, d) ** 2
    for j in range(1, J):
        total += 2.0 * (1.0 - j / M) * _sz(j / S, F, alpha, d) ** 2
    return total


@lru_cache(maxsize=4096)
def edf_greenhall(
    alpha: int, d: int, m: int, n_phase: int, modified: bool, overlapping: bool
) -> float:
    """EDF of a finite-difference variance estimator, Greenhall & Riley 2003 ("combined" EDF).

    Parameters follow the paper: ``d`` is the phase-difference order (2 Allan, 3 Hadamard),
    the filter factor is ``F = 1`` for modified variances and ``F = m`` otherwise, the stride
    factor is ``S = m`` for overlapping estimators and ``S = 1`` for non-overlapping ones.
    Initial steps (section 3.4): ``L = m/F + m d``, ``M = 1 + floor(S (N - L) / m)``,
    ``J = min(M, (d + 1) S)``, ``r = M / S``. The four cases of section 3.6 follow (modified;
    unmodified alpha <= 0; unmodified flicker PM; unmodified white PM), each using the basic
    sum when ``J <= J_max = 100`` and the asymptotic tables 1-3 otherwise.
    Valid for ``alpha + 2 d > 1`` (alpha from 2 down to -2 for d = 2, to -4 for d = 3).
    """
    if alpha + 2 * d <= 1 or alpha > 2:
        raise StatsError(
            f"Greenhall EDF needs alpha + 2d > 1 and alpha <= 2; got alpha={alpha}, d={d}: "
            "fix the noise type or use a higher-order (Hadamard) statistic"
        )
    if m < 1:
        raise StatsError(f"Greenhall EDF: averaging factor m={m} must be >= 1")
    F: float = 1.0 if modified else float(m)
    S: float = float(m) if overlapping else 1.0
    L = m / F + m * d
    if n_phase < L:
        raise StatsError(
            f"Greenhall EDF: {n_phase} phase points are fewer than the filter length "
            f"L={L:g} at m={m}, d={d}: use a smaller averaging factor"
        )
    M = 1 + math.floor(S * (n_phase - L) / m)
    J = int(min(M, (d + 1) * S))
    r = M / S
    jmax = GREENHALL_JMAX

    if F == 1.0:  # case 1: modified variances (and unmodified at m = 1), all alpha
        if jmax >= J:
            inv = _basic_sum(J, M, S, 1.0, alpha, d) / (M * _sz(0.0, 1.0, alpha, d) ** 2)
        elif r >= d + 1:
            a0, a1 = _TABLE1[alpha][d]
            inv = (a0 - a1 / r) / r
        else:
            mp = jmax / r
            inv = _basic_sum(jmax, jmax, mp, 1.0, alpha, d) / (jmax * _sz(0.0, 1.0, alpha, d) ** 2)
    elif alpha <= 0:  # case 2: unmodified, white FM and below
        if jmax >= J:
            mp = float(m) if m * (d + 1) <= jmax else math.inf
            inv = _basic_sum(J, M, S, mp, alpha, d) / (M * _sz(0.0, mp, alpha, d) ** 2)
        elif r >= d + 1:
            a0, a1 = _TABLE2[alpha][d]
            inv = (a0 - a1 / r) / r
        else:
            mp = jmax / r
            inv = _basic_sum(jmax, jmax, mp, math.inf, alpha, d) / (
                jmax * _sz(0.0, math.inf, alpha, d) ** 2
            )
    elif alpha == 1:  # case 3: unmodified, flicker PM
        b0, b1 = _TABLE3[d]
        if jmax >= J:
            inv = _basic_sum(J, M, S, float(m), 1, d) / (M * _sz(0.0, float(m), 1, d) ** 2)
        elif r >= d + 1:
            a0, a1 = _TABLE2[1][d]
            inv = (a0 - a1 / r) / (r * (b0 + b1 * math.log(m)) ** 2)
        else:
            mp = jmax / r
            inv = _basic_sum(jmax, jmax, mp, mp, 1, d) / (jmax * (b0 + b1 * math.log(m)) ** 2)
    else:  # case 4: unmodified, white PM
        K = math.ceil(r)
        if d >= K:
            acc = 0.0
            for k in range(1, K):
                acc += (1.0 - k / r) * math.comb(2 * d, d - k) ** 2
            inv = (1.0 + 2.0 * acc / math.comb(2 * d, d) ** 2) / M
        else:
            a0 = math.comb(4 * d, 2 * d) / math.comb(2 * d, d) ** 2
            a1 = d / 2.0
            inv = (a0 - a1 / r) / M
    return 1.0 / inv


# --------------------------------------------------------------------------------------
# Simple formulas (SP 1065 section 5.3, after Stein 1985) and the totals
# --------------------------------------------------------------------------------------


def edf_simple(alpha: int, m: int, n_phase: int) -> float:
    """Simple EDF approximations of SP 1065 section 5.3 (S. Stein, 1985), N phase points.

    * WPM  (alpha  2): (N+1)(N-2m) / (2(N-m))
    * FPM  (alpha  1): exp( sqrt( ln((N-1)/(2m)) ln((2m+1)(N-1)/4) ) )
    * WFM  (alpha  0): (3(N-1)/(2m) - 2(N-2)/N) * 4m^2/(4m^2+5)
    * FFM  (alpha -1): 2(N-2)/(2.3N-4.9) for m = 1, 5N^2/(4m(N+3m)) for m >= 2
    * RWFM (alpha -2): (N-2)/(m(N-3)^2) * ((N-1)^2 - 3m(N-1) + 4m^2)
    """
    N = float(n_phase)
    mf = float(m)
    if alpha == 2:
        return (N + 1) * (N - 2 * mf) / (2 * (N - mf))
    if alpha == 1:
        a = (N - 1) / (2 * mf)
        b = (2 * mf + 1) * (N - 1) / 4
        if a <= 1.0:
            raise StatsError(f"simple EDF (flicker PM): m={m} too large for N={n_phase}")
        return math.exp(math.sqrt(math.log(a) * math.log(b)))
    if alpha == 0:
        return (3 * (N - 1) / (2 * mf) - 2 * (N - 2) / N) * (4 * mf * mf / (4 * mf * mf + 5))
    if alpha == -1:
        if m == 1:
            return 2 * (N - 2) / (2.3 * N - 4.9)
        return 5 * N * N / (4 * mf * (N + 3 * mf))
    if alpha == -2:
        return (N - 2) / (mf * (N - 3) ** 2) * ((N - 1) ** 2 - 3 * mf * (N - 1) + 4 * mf * mf)
    raise StatsError(f"simple EDF: noise exponent alpha={alpha} outside -2..2")


def _edf_theo1(alpha: int, m: int, n_phase: int) -> float:
    """Theo1 EDF, SP 1065 section 5.2.15 (Howe & Peppler 2003), tau = 0.75 m tau0.

    With N phase points and t = 0.75 m:
    * WPM:  0.86 (N+1)(N - 4t/3) / (N - t) * t / (t + 1.14)
    * FPM:  (4.798 N^2 - 6.374 N t + 12.387 t) / (sqrt(t + 36.6) (N - t)) * t / (t + 0.3)
    * WFM:  ((4.1 N + 0.8)/t - (3.1 N + 6.5)/N) * t^1.5 / (t^1.5 + 5.2)
    * FFM:  (2 N^2 - 1.3 N t - 3.5 t) / (N t) * t^3 / (t^3 + 2.3)
    * RWFM: (4.4 N - 2)/(2.9 t) * ((4.4N - 1)^2 - 8.6 t (4.4N - 1) + 11.4 t^2) / (4.4N - 3)^2
    """
    N = float(n_phase)
    t = 0.75 * m
    if alpha == 2:
        return 0.86 * (N + 1) * (N - 4 * t / 3) / (N - t) * (t / (t + 1.14))
    if alpha == 1:
        return (
            (4.798 * N * N - 6.374 * N * t + 12.387 * t)
            / (math.sqrt(t + 36.6) * (N - t))
            * (t / (t + 0.3))
        )
    if alpha == 0:
        return ((4.1 * N + 0.8) / t - (3.1 * N + 6.5) / N) * (t**1.5 / (t**1.5 + 5.2))
    if alpha == -1:
        return (2 * N * N - 1.3 * N * t - 3.5 * t) / (N * t) * (t**3 / (t**3 + 2.3))
    if alpha == -2:
        u = 4.4 * N
        return (
            (u - 2) / (2.9 * t) * ((u - 1) ** 2 - 8.6 * t * (u - 1) + 11.4 * t * t) / (u - 3) ** 2
        )
    raise StatsError(f"Theo1 EDF: noise exponent alpha={alpha} outside -2..2")


VAR_NAME: dict[str, str] = {
    "adev": "avar",
    "oadev": "oavar",
    "mdev": "mvar",
    "tdev": "tvar",
    "hdev": "hvar",
    "ohdev": "ohvar",
    "totdev": "totvar",
    "mtotdev": "mtotvar",
    "ttotdev": "ttotvar",
    "htotdev": "htotvar",
    "theo1": "theo1var",
    "theobr": "theobrvar",
    "theoh": "theohvar",
    "stdev": "stdvar",
    "ostdev": "ostdvar",
}


def canonical_stat(stat: str) -> str:
    """Variance name for a deviation or variance name ("oadev" -> "oavar")."""
    key = stat.lower()
    return VAR_NAME.get(key, key)


def edf(stat: str, alpha: int, m: int, n_phase: int) -> float:
    """Equivalent degrees of freedom of ``stat`` at averaging factor ``m``.

    ``stat`` is a variance or deviation name (``"oavar"`` or ``"oadev"``), ``alpha`` the
    noise exponent (S_y ~ f^alpha) used for the estimate, ``n_phase`` the number of phase
    points N. Raises :class:`StatsError` for an unknown statistic, an unsupported alpha,
    or too few points. The methods per statistic are listed in the module docstring.
    """
    name = canonical_stat(stat)
    alpha = int(alpha)
    m = int(m)
    n_phase = int(n_phase)
    if m < 1 or n_phase < 2:
        raise StatsError(
            f"edf({stat!r}): need m >= 1 and N >= 2 phase points, got m={m}, N={n_phase}"
        )
    ratio = n_phase / m  # T / tau
    if name in _GREENHALL_PARAMS:
        d, f_is_m, s_is_m = _GREENHALL_PARAMS[name]
        return edf_greenhall(alpha, d, m, n_phase, not f_is_m, s_is_m)
    if name == "totvar":
        if alpha in TOTVAR_EDF_COEFFICIENTS:
            b, c = TOTVAR_EDF_COEFFICIENTS[alpha]
            return b * ratio - c
        return edf_simple(alpha, m, n_phase) + SIMPLE_EDF_OFFSET
    if name in ("mtotvar", "ttotvar"):
        if alpha not in MTOT_EDF_COEFFICIENTS:
            raise StatsError(f"edf({stat!r}): alpha={alpha} outside -2..2 for MTOT/TTOT")
        if m < MTOT_MIN_M:
            return edf_greenhall(alpha, 2, m, n_phase, True, True)
        b, c = MTOT_EDF_COEFFICIENTS[alpha]
        return b * ratio - c
    if name == "htotvar":
        if m >= HTOT_MIN_M and alpha in HTOTVAR_EDF_COEFFICIENTS:
            b0, b1 = HTOTVAR_EDF_COEFFICIENTS[alpha]
            return ratio / (b0 + b1 / ratio)
        if alpha < -2:
            # the simple formulas stop at RWFM: below HTOT_MIN_M use the OHVAR EDF (same
            # d = 3 kernel), as Stable32 does for the overlapping Hadamard variance.
            return edf_greenhall(alpha, 3, m, n_phase, False, True)
        return edf_simple(alpha, m, n_phase) + SIMPLE_EDF_OFFSET
    if name in ("theo1var", "theobrvar", "theohvar"):
        return _edf_theo1(alpha, m, n_phase)
    if name == "stdvar":
        # m-averaged frequency samples: K = floor((N-1)/m), variance about their mean.
        return float((n_phase - 1) // m - 1)
    if name == "ostdvar":
        # overlapping averages are correlated: count them as the white-FM OAVAR does.
        return edf_greenhall(0, 2, m, n_phase, False, True)
    raise StatsError(
        f"edf: unknown statistic {stat!r}; expected one of avar, oavar, mvar, tvar, hvar, "
        "ohvar, totvar, mtotvar, ttotvar, htotvar, theo1var, theobrvar, theohvar, stdvar, "
        "ostdvar (or their deviation names)"
    )
