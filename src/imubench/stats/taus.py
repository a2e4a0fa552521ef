"""Averaging-factor (tau) selection and Stable32's per-statistic stop ratios.

Stop ratios (largest averaging factor m for ``M`` frequency samples, i.e. ``N = M + 1``
phase points) as Stable32 applies them; they reproduce the AF ranges of the Stable32
reference runs (phase.dat, OCXO, Keysight counter, pink FM):

=========================  ========================
statistic                  largest m
=========================  ========================
adev, hdev                 M / 5
oadev, mdev, tdev, ohdev   M / 4
totdev, stdev, ostdev      M / 2
mtotdev, ttotdev, htotdev  M / 3
theo1, theobr, theoh       M - 2 (even m, m >= 10)
=========================  ========================
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from imubench.errors import StatsError

STOP_RATIO: dict[str, float] = {
    "adev": 5.0,
    "hdev": 5.0,
    "oadev": 4.0,
    "mdev": 4.0,
    "tdev": 4.0,
    "ohdev": 4.0,
    "totdev": 2.0,
    "stdev": 2.0,
    "ostdev": 2.0,
    "mtotdev": 3.0,
    "ttotdev": 3.0,
    "htotdev": 3.0,
}
THEO_STATS = ("theo1", "theobr", "theoh")
THEO1_MIN_M = 10  # SP 1065 section 5.2.14: 10 <= m <= N - 1, m even


TAU_KEYWORDS = ("octave", "decade", "all")


def parse_taus(text: str) -> str | int | list[float]:
    """A tau specification as text (``--taus``, ``allan.taus``): a keyword of
    :data:`TAU_KEYWORDS`, an integer (points per decade) or comma-separated tau values in
    seconds; the value :func:`averaging_factors` takes."""
    t = text.strip().lower()
    if t in TAU_KEYWORDS:
        return t
    try:
        if "," not in t and "." not in t and "e" not in t:
            return int(t)
        return [float(v) for v in t.split(",") if v.strip()]
    except ValueError:
        raise StatsError(
            f"taus {text!r} is not understood: use octave, decade, all, an integer (points "
            "per decade) or a comma-separated list of tau values in seconds"
        ) from None


def streaming_factors(
    stats: Sequence[str], taus: str | int | Sequence[float], rate_hz: float,
    max_tau_s: float | None,
) -> tuple[int, list[int]]:
    """``(m_max, factors)`` a streaming engine keeps: every averaging factor of ``taus``
    for each statistic up to ``m_max = floor(max_tau_s * rate_hz)`` (2**20 without
    ``max_tau_s``), sorted. The rule :class:`~imubench.stats.streaming.StreamingAllan`
    and the configuration check share.

    Raises:
        StatsError: ``max_tau_s`` shorter than one sample period, or no factor at all.
    """
    # largest m; a tau given as m / rate_hz must not lose m to rounding
    max_m = int(np.floor(max_tau_s * rate_hz * (1 + 1e-12))) if max_tau_s else 2**20
    if max_m < 1:
        raise StatsError(f"max_tau_s={max_tau_s} is shorter than one sample period")
    ms: set[int] = set()
    for stat in stats:
        ms.update(int(m) for m in averaging_factors(stat, 10**15, taus, 1.0 / rate_hz,
                                                    max_af_override=max_m))
    if not ms:
        raise StatsError(f"no averaging factor <= {max_m} from taus={taus!r}")
    return max_m, sorted(ms)


def max_af(stat: str, n_freq: int, max_af_override: float | None = None) -> int:
    """Largest averaging factor Stable32 uses for ``stat`` with ``n_freq`` frequency samples."""
    if max_af_override is not None:
        return int(max_af_override)
    if stat in THEO_STATS:
        mm = n_freq - 2
        return mm - (mm % 2)
    try:
        return int(np.floor(n_freq / STOP_RATIO[stat]))
    except KeyError:
        raise StatsError(f"unknown statistic {stat!r}: no stop ratio defined") from None


def _octave(mmax: int) -> np.ndarray:
    if mmax < 1:
        return np.zeros(0, dtype=np.int64)
    return 2 ** np.arange(int(np.floor(np.log2(mmax))) + 1, dtype=np.int64)


def _decade(mmax: int) -> np.ndarray:
    out = [f * 10**k for k in range(0, 19) for f in (1, 2, 4)]
    return np.array([v for v in out if v <= mmax], dtype=np.int64)


def _per_decade(k: int, mmax: int) -> np.ndarray:
    if k < 1:
        raise StatsError(f"taus={k}: points per decade must be >= 1")
    if mmax < 1:
        return np.zeros(0, dtype=np.int64)
    ms = np.round(10 ** (np.arange(0, np.log10(mmax) * k + 1) / k)).astype(np.int64)
    return np.unique(ms[ms <= mmax])


def averaging_factors(
    stat: str,
    n_freq: int,
    taus: str | int | Sequence[float] | np.ndarray,
    tau0_s: float,
    max_af_override: float | None = None,
) -> np.ndarray:
    """Averaging factors m for ``taus``.

    ``taus``: ``"octave"`` (1, 2, 4, ...), ``"decade"`` (1, 2, 4, 10, 20, 40, ... as Stable32),
    ``"all"`` (every m), an int k (k log-spaced points per decade), or explicit tau values in
    seconds (rounded to the nearest m; for the Theo1 family tau = 0.75 m tau0 so
    m = tau / (0.75 tau0), rounded to even). Factors beyond the stop ratio are dropped.
    """
    theo = stat in THEO_STATS
    mmax = max_af(stat, n_freq, max_af_override)
    if isinstance(taus, str):
        if taus == "octave":
            ms = _octave(mmax)
        elif taus == "decade":
            ms = _decade(mmax)
        elif taus == "all":
            ms = np.arange(1, mmax + 1, dtype=np.int64)
        else:
            raise StatsError(
                f"taus={taus!r} is not understood: use 'octave', 'decade', 'all', "
                "an int (points per decade) or a list of tau values in seconds"
            )
        if theo:
            ms = ms[(ms % 2 == 0) & (ms >= THEO1_MIN_M)]
            if taus != "all" and ms.size and ms[0] != THEO1_MIN_M and mmax >= THEO1_MIN_M:
                ms = np.concatenate([[THEO1_MIN_M], ms])
        return ms
    if isinstance(taus, int | np.integer) and not isinstance(taus, bool):
        ms = _per_decade(int(taus), mmax)
        if theo:
            ms = np.unique(ms + ms % 2)
            ms = ms[(ms >= THEO1_MIN_M) & (ms <= mmax)]
        return ms
    arr = np.asarray(taus, dtype=np.float64).ravel()
    if arr.size == 0 or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise StatsError(f"taus must be positive finite seconds, got {taus!r}")
    if theo:
        ms = np.round(arr / (0.75 * tau0_s) / 2.0).astype(np.int64) * 2
        ms = ms[(ms >= 2) & (ms <= mmax)]
    else:
        ms = np.round(arr / tau0_s).astype(np.int64)
        ms = ms[(ms >= 1) & (ms <= mmax)]
    return np.unique(ms)
