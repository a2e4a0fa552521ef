"""Power-law noise identification per averaging factor, as Stable32 does it.

The noise exponent alpha (S_y(f) ~ f^alpha: 2 white PM, 1 flicker PM, 0 white FM,
-1 flicker FM, -2 random-walk FM, -3 flicker-walk FM, -4 random-run FM) picks the EDF and
the bias correction of every statistic. Two estimators are used:

* Lag-1 autocorrelation (W. J. Riley and C. A. Greenhall, "Power law noise identification
  using the lag 1 autocorrelation", Proc. 18th EFTF, 2004; NIST SP 1065 section 5.6):
  the series at the averaging time of interest (phase decimated by m, or frequency
  averaged in groups of m) is differenced d = 0, 1, ... times; at each step
  r1 = (N-1)/N sum (z_i - zbar)(z_{i+1} - zbar) / sum (z_i - zbar)^2 and
  delta = r1 / (1 + r1).
  The loop stops when d >= dmin and (delta < 0.25 or d >= dmax); then
  p = -2 (delta + d), rounded to an integer, and alpha = p + 2 for phase data or p for
  frequency data. dmax = 2 for the Allan family, 3 for the Hadamard family. It needs
  about 30 points at the averaging time (Riley & Greenhall: N >= 30).
* Barnes B1 ratio (J. A. Barnes, "Tables of bias functions B1 and B2 for variances based
  on finite samples of processes with power law spectral densities", NBS TN 375, 1969;
  D. A. Howe et al., "A total estimator of the Hadamard function used for GPS
  operations", 32nd PTTI, 2000, tables 3-4): B1 = (standard variance of the K averaged
  frequencies) / (Allan variance at the same tau). Its expectation for phase exponent mu
  (S_x ~ f^(mu-1)... written tau^mu for AVAR) is B1(K, mu) = K (1 - K^mu) /
  (2 (K - 1)(1 - 2^mu)); the measured ratio is assigned to the mu whose expectation it is
  closest to on a log scale (boundaries at geometric means). mu = -2 covers both white and
  flicker PM; R(n) = MVAR/AVAR separates them (NIST TN 1337, table 2: R = 1/m for white
  PM, 3.37 / (1.04 + 3 ln(pi m)) for flicker PM with f_h = 1/(2 tau0)).

Stable32 uses the lag-1 method when it has at least 30 points at the averaging time and
B1 (with R(n)) otherwise; :func:`identify_alpha` does the same. Stable32 identifies only
up to half of the statistic's largest averaging factor (:func:`identifies_at`); beyond it
each tau keeps the alpha of the tau before it (see :func:`identify_alpha`).

The input ``x`` is always the phase array (seconds, or for an IMU the integrated rate);
``data_type`` says what the user supplied, because Stable32 identifies on the frequency
averages when it was given frequency data and on the decimated phase otherwise. NaN samples
are gaps: pairs touching a NaN are left out of every sum.
"""

from __future__ import annotations

import math

import numpy as np

from imubench.errors import StatsError
from imubench.stats import _kernels as _k
from imubench.stats.edf import VAR_NAME, canonical_stat
from imubench.stats.taus import max_af

__all__ = [
    "LAG1_MIN_POINTS",
    "alpha_range",
    "analysis_terms",
    "b1_alpha",
    "b1_expected",
    "dmax_for",
    "identifies_at",
    "identify_alpha",
    "lag1_acf",
    "lag1_alpha",
    "rn_expected",
]

#: Minimum number of points at the averaging time for the lag-1 ACF method.
LAG1_MIN_POINTS = 30

_HADAMARD_VARS = {"hvar", "ohvar", "htotvar"}
_DEV_NAME = {v: k for k, v in VAR_NAME.items()}  # variance name -> deviation name

#: Noise exponents each statistic's EDF (and bias) supports, as (lowest, highest).
_ALPHA_RANGE = {
    "avar": (-2, 2),
    "oavar": (-2, 2),
    "mvar": (-2, 2),
    "tvar": (-2, 2),
    "hvar": (-4, 2),
    "ohvar": (-4, 2),
    "totvar": (-2, 2),
    "mtotvar": (-2, 2),
    "ttotvar": (-2, 2),
    "htotvar": (-4, 2),
    "theo1var": (-2, 2),
    "theobrvar": (-2, 2),
    "theohvar": (-2, 2),
    "stdvar": (-2, 2),
    "ostdvar": (-2, 2),
}
_MODIFIED_STATS = {"mvar", "tvar", "mtotvar", "ttotvar"}


def dmax_for(stat: str) -> int:
    """Lag-1 dmax of :func:`identify_alpha`: 3 for the Hadamard family, 2 otherwise."""
    return 3 if canonical_stat(stat) in _HADAMARD_VARS else 2


def alpha_range(stat: str) -> tuple[int, int]:
    """(lowest, highest) noise exponent that ``stat``'s EDF and bias support."""
    name = canonical_stat(stat)
    if name not in _ALPHA_RANGE:
        raise StatsError(
            f"noise identification: unknown statistic {stat!r}; expected one of "
            f"{', '.join(sorted(_ALPHA_RANGE))}"
        )
    return _ALPHA_RANGE[name]


def _check(x: np.ndarray, m: int, data_type: str) -> np.ndarray:
    if data_type not in ("phase", "freq"):
        raise StatsError(f"noise identification: data_type={data_type!r} must be 'phase' or 'freq'")
    if int(m) != m or m < 1:
        raise StatsError(f"noise identification: averaging factor m={m} must be an integer >= 1")
    arr = np.ascontiguousarray(x, dtype=float)  # one compiled layout for the kernels
    if arr.ndim != 1:
        raise StatsError(f"noise identification: phase array must be 1-D, got shape {arr.shape}")
    return arr


def lag1_acf(z: np.ndarray) -> float:
    """Lag-1 autocorrelation r1 of ``z`` (Riley & Greenhall 2004, eq. 2), NaN-aware.

    r1 = sum_{i} (z_i - zbar)(z_{i+1} - zbar) / sum_i (z_i - zbar)^2, the sums running over
    finite values (pairs with a NaN are skipped).
    """
    z = np.ascontiguousarray(z, dtype=float)
    r1, n = _k.lag1_r1(z)
    return _r1_checked(float(r1), int(n))


def _r1_checked(r1: float, n: int) -> float:
    """r1 (n-1)/n from a kernel's (r1 without the factor, finite points), or a clear error."""
    if n < 3:
        raise StatsError(f"lag-1 ACF needs at least 3 finite points, got {n}")
    if not np.isfinite(r1):
        raise StatsError("lag-1 ACF: the series is constant (zero variance); no noise to identify")
    return r1 * (n - 1) / n


def lag1_alpha(x: np.ndarray, m: int, data_type: str, dmin: int = 0, dmax: int = 2) -> int:
    """Noise exponent alpha at averaging factor m by the lag-1 autocorrelation method.

    Recipe (Riley & Greenhall 2004, SP 1065 section 5.6): z = series at tau (phase decimated
    by m, or frequency averaged by m when ``data_type == "freq"``); d = 0; loop: r1 =
    lag1_acf(z), delta = r1/(1+r1); if d >= dmin and (delta < 0.25 or d >= dmax):
    p = -round(2 delta) - 2 d, return p + 2 (phase) or p (freq); else z = diff(z), d += 1.
    Raises :class:`StatsError` when fewer than :data:`LAG1_MIN_POINTS` points remain.
    """
    arr = _check(x, m, data_type)
    if not 0 <= dmax <= 3:
        raise StatsError(f"lag-1 noise identification: dmax={dmax} must be 0..3")
    freq = data_type == "freq"
    d = 0
    while True:
        # one fused pass per order d (``_kernels.lag1_r1_diff``): the same values as
        # lag1_acf(np.diff(z, d)) with z the series at tau, without the temporaries
        r1_raw, n = _k.lag1_r1_diff(arr, int(m), freq, d)
        if d == 0 and n < LAG1_MIN_POINTS:
            raise StatsError(
                f"lag-1 noise identification at m={m}: only {int(n)} points at this averaging "
                f"time (needs >= {LAG1_MIN_POINTS}); use b1_alpha or a smaller averaging factor"
            )
        r1 = _r1_checked(float(r1_raw), int(n))
        delta = r1 / (1.0 + r1)
        if d >= dmin and (delta < 0.25 or d >= dmax):
            p = -round(2.0 * delta) - 2 * d
            return int(p + 2 if data_type == "phase" else p)
        d += 1


def b1_expected(n: int, mu: int) -> float:
    """Expected B1 ratio for n frequency averages and AVAR exponent mu (Barnes 1969).

    B1(n, mu) = n (1 - n^mu) / (2 (n - 1)(1 - 2^mu)); mu = 0 is the limit
    n ln(n) / (2 (n - 1) ln 2).
    """
    if n < 2:
        raise StatsError(f"B1 ratio needs at least 2 frequency averages, got {n}")
    if mu == 0:
        return n * math.log(n) / (2.0 * (n - 1) * math.log(2.0))
    return n * (1.0 - float(n) ** mu) / (2.0 * (n - 1) * (1.0 - 2.0**mu))


def rn_expected(m: int, alpha: int) -> float:
    """Expected R(n) = MVAR/AVAR for white PM (1/m) or flicker PM (NIST TN 1337 table 2).

    Flicker PM: R = 3.37 / (1.04 + 3 ln(pi m)), i.e. measurement bandwidth f_h = 1/(2 tau0).
    """
    if alpha == 2:
        return 1.0 / m
    if alpha == 1:
        return 3.37 / (1.04 + 3.0 * math.log(math.pi * m))
    raise StatsError(f"R(n) expectation defined for alpha 1 or 2 only, got {alpha}")


def _freq_averages(x: np.ndarray, m: int) -> np.ndarray:
    """Non-overlapping m-averages of the frequency, from the phase: (x[(k+1)m]-x[km])/m."""
    return np.diff(x[::m]) / m


def _avar_from_averages(yk: np.ndarray) -> float:
    dy = np.diff(yk)
    dy = dy[np.isfinite(dy)]
    if dy.size < 1:
        raise StatsError("B1 ratio: no finite pair of frequency averages for the Allan variance")
    return float(0.5 * np.mean(dy * dy))


def _mvar(x: np.ndarray, m: int) -> float:
    """Modified Allan variance at m from phase x (SP 1065 eq. 14), NaN terms skipped."""
    n = x.size
    if n < 3 * m + 1:
        raise StatsError(f"MVAR at m={m} needs >= {3 * m + 1} phase points, got {n}")
    bad = ~np.isfinite(x)
    if bad.any():
        gp = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(bad, out=gp[1:])
        s, ok = _k.mvar_sum(np.where(bad, 0.0, x), m, gp, 1)
    else:
        s, ok = _k.mvar_sum(np.ascontiguousarray(x, dtype=float), m, np.zeros(0, np.int64), 1)
    if ok == 0:
        raise StatsError(f"MVAR at m={m}: every term touches a gap")
    return float(s / ok / (2.0 * m**2 * m**2))


def analysis_terms(stat: str, m: int, n_phase: int) -> int:
    """Number of terms ("#" column of Stable32) of ``stat`` at m for N phase points."""
    name = canonical_stat(stat)
    n = n_phase
    table = {
        "avar": (n - 1) // m - 1,
        "hvar": (n - 1) // m - 2,
        "oavar": n - 2 * m,
        "ohvar": n - 3 * m,
        "htotvar": n - 3 * m,
        "mvar": n - 3 * m + 1,
        "tvar": n - 3 * m + 1,
        "mtotvar": n - 3 * m + 1,
        "ttotvar": n - 3 * m + 1,
        "totvar": n - 2,
    }
    return int(table.get(name, (n - 1) // m))


def b1_alpha(x: np.ndarray, m: int, data_type: str, n_terms: int | None = None) -> int:
    """Noise exponent alpha at m from the Barnes B1 ratio, with R(n) for the PM types.

    B1 = sample variance (ddof 1) of the K = floor((N-1)/m) frequency averages divided by
    their (non-overlapping) Allan variance. The measured B1 is compared with
    :func:`b1_expected` for mu = 2, 1, 0, -1, -2 with boundaries at the geometric means of
    neighbours; mu maps to alpha = -mu - 1 (mu >= -1). mu = -2 (white or flicker PM) is
    split by R(n) = MVAR/AVAR against the geometric mean of :func:`rn_expected` for
    alpha 2 and 1; where MVAR cannot be formed (N < 3m + 1) white PM is returned.
    ``n_terms`` is the N put into :func:`b1_expected`; by default the number K of
    frequency averages. Stable32 puts the statistic's number of analysis terms there
    (its "#" column; :func:`identify_alpha` passes :func:`analysis_terms`): with it the
    OCXO all-tau OADEV alphas agree at 84 of 106 B1 AFs instead of 47, elsewhere no change;
    the other 22 are AFs where Stable32 does not identify at all (:func:`identifies_at`).
    ``data_type`` is accepted for symmetry with :func:`lag1_alpha`; B1 works on the phase.
    """
    arr = _check(x, m, data_type)
    m = int(m)
    yk = _freq_averages(arr, m)
    yk_ok = yk[np.isfinite(yk)]
    k = int(yk_ok.size)
    if k < 2:
        raise StatsError(
            f"B1 noise identification at m={m}: only {k} frequency averages (needs >= 2); "
            "use a smaller averaging factor"
        )
    avar = _avar_from_averages(yk)
    if avar <= 0.0:
        raise StatsError(f"B1 noise identification at m={m}: zero Allan variance")
    b1 = float(np.var(yk_ok, ddof=1)) / avar
    mus = (2, 1, 0, -1, -2)
    n_exp = k if n_terms is None else max(int(n_terms), 2)
    expected = [b1_expected(n_exp, mu) for mu in mus]
    mu_found = -2
    for i, mu in enumerate(mus[:-1]):
        boundary = math.sqrt(expected[i] * expected[i + 1])
        if b1 > boundary:
            mu_found = mu
            break
    if mu_found > -2:
        return -mu_found - 1
    try:
        rn = _mvar(arr, m) / avar
    except StatsError:
        return 2
    boundary = math.sqrt(rn_expected(m, 2) * rn_expected(m, 1))
    return 1 if rn > boundary else 2


def identifies_at(stat: str, m: int, n_phase: int) -> bool:
    """Whether Stable32 runs its noise identification at averaging factor m.

    True when 2 m <= the largest m of ``stat`` (:func:`imubench.stats.taus.max_af`, the
    Stable32 stop ratio r: m_max = floor((N - 1) / r)), i.e. when at least 2 r frequency
    averages exist at this tau (10 for ADEV/HDEV, 8 for OADEV/MDEV/TDEV/OHDEV, 6 for
    MTOT/TTOT/HTOT, 4 for TOTDEV). Beyond that Stable32 keeps the previous tau's alpha.

    Not in Stable32's help or SP 1065: the rule is inferred from the reference runs in
    allantools' test data (Stable32 1.53/1.60). The boundary lies between M/m = 10.41 and
    9.65 for ADEV/HDEV and 8.14 and 7.00 for the OADEV family (OCXO all-tau runs), 7.8 and
    5.0 for MTOT/TTOT/HTOT (phase.dat); TOTDEV on the Keysight TIC data identifies at
    M/m = 6.8 where OADEV, with its longer stop ratio, already holds. With it our alpha
    equals the Alpha column in all 4,389 rows of the auto-ID runs except the Keysight ADEV
    run (248 of 260; its 12 misses are white PM/flicker PM/white FM calls inside the identified
    range), against 22 misses in the OCXO OADEV all-tau run alone before.
    """
    name = canonical_stat(stat)
    dev = _DEV_NAME.get(name, name)
    n_freq = int(n_phase) - 1
    try:
        m_max = max_af(dev, n_freq)
    except StatsError:
        return True
    return 2 * int(m) <= m_max


def identify_alpha(
    x: np.ndarray, m: int, data_type: str, stat: str, previous: int | None = None
) -> int:
    """Noise exponent alpha that ``stat`` should use at averaging factor m (Stable32's rule).

    Lag-1 ACF (:func:`lag1_alpha`, dmax = 3 for the Hadamard family, 2 otherwise) when at
    least :data:`LAG1_MIN_POINTS` points exist at this averaging time, else the B1 ratio
    with R(n) (:func:`b1_alpha`). ``previous`` is the alpha of the previous (shorter) tau
    of the same run: where :func:`identifies_at` is false it is returned as it is, as
    Stable32 does beyond half the largest averaging factor; without it (``None``, the
    first tau of a run) alpha is identified anyway. The result is clipped to
    :func:`alpha_range` of ``stat``.
    """
    lo, hi = alpha_range(stat)
    arr = _check(x, m, data_type)
    if previous is not None and not identifies_at(stat, int(m), arr.size):
        return int(min(max(int(previous), lo), hi))
    dmax = dmax_for(stat)
    if _k.points_at_tau(arr, int(m), data_type == "freq", LAG1_MIN_POINTS) >= LAG1_MIN_POINTS:
        alpha = lag1_alpha(arr, int(m), data_type, dmin=0, dmax=dmax)
    else:
        alpha = b1_alpha(arr, int(m), data_type, n_terms=analysis_terms(stat, int(m), arr.size))
    return int(min(max(alpha, lo), hi))
