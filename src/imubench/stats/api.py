"""Public batch statistics: one signature for every Allan-family statistic.

``imubench.stats.<name>(data, rate=1.0, data_type="phase", taus="octave", *,
confidence=0.683, alpha=None, bias_correction=True, remove_drift=False, max_af=None,
afs=None, progress=None) -> StatResult``

Per averaging factor m: the raw variance from the kernels (``allan``, ``total``,
``theo``), the noise type alpha (``noise_id.identify_alpha`` unless fixed by the caller;
beyond half the statistic's largest averaging factor it keeps the previous tau's alpha, as
Stable32 does), the bias factor Stable32 divides by (``bias.bias_factor``), the EDF
(``edf.edf``) and the chi-squared deviation limits (``ci.chi2_limits``). If one of those
modules is missing or fails for a tau, the affected columns are NaN (alpha -99) and a note
says why; the deviations themselves never depend on them, except where a bias correction
needs alpha.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from imubench.errors import StatsError
from imubench.stats import allan as _allan
from imubench.stats import bias, ci, noise_id
from imubench.stats import theo as _theo
from imubench.stats import total as _total
from imubench.stats.confidence import Runs, runs_edf
from imubench.stats.edf import VAR_NAME as _VAR_NAME
from imubench.stats.prep import PhaseData, to_phase
from imubench.stats.result import StatResult
from imubench.stats.taus import THEO_STATS, averaging_factors
from imubench.stats.taus import max_af as _max_af

Progress = Callable[[float], None]
ALPHA_UNKNOWN = -99

VAR_NAME = _VAR_NAME  # deviation name -> variance name (one table, in edf.py)
DEV_NAME = {v: k for k, v in VAR_NAME.items()}

_SIMPLE: dict[str, Callable[[PhaseData, int], tuple[float, int, int]]] = {
    "adev": _allan.avar,
    "oadev": _allan.oavar,
    "hdev": _allan.hvar,
    "ohdev": _allan.ohvar,
    "stdev": _allan.stdvar,
    "ostdev": _allan.ostdvar,
}


def _noise_phase(pd: PhaseData) -> np.ndarray:
    """Phase with NaN where a gap makes it unknown (for noise identification)."""
    if pd.gap_prefix is None:
        return pd.x
    g = pd.gap_prefix
    x = pd.x.copy()
    if pd.gap_end_offset == 1:
        x[(g[1:] - g[:-1]) > 0] = np.nan
    else:  # frequency gap y[k] leaves x[k+1] unknown relative to x[k]
        x[1:][(g[1:] - g[:-1]) > 0] = np.nan
    return x


def _raw(
    stat: str, pd: PhaseData, ms: np.ndarray, progress: Progress | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    var = np.empty(ms.size)
    n = np.empty(ms.size, dtype=np.int64)
    skipped = np.empty(ms.size, dtype=np.int64)
    if stat == "theo1":
        v, nn, sk = _theo.theo1var(pd, ms, progress)
        return v, nn.astype(np.int64), sk.astype(np.int64)
    xe = _total.extended_phase(pd) if stat == "totdev" else None
    work = np.cumsum(
        ms.astype(np.float64) ** 2
        if stat in ("mtotdev", "ttotdev", "htotdev")
        else np.ones(ms.size)
    )
    for k, m in enumerate(ms):
        m = int(m)
        if stat in _SIMPLE:
            r = _SIMPLE[stat](pd, m)
        elif stat == "mdev":
            r = _allan.mvar(pd, m)
        elif stat == "tdev":
            r = _allan.tvar(pd, m)
        elif stat == "totdev":
            r = _total.totvar(pd, m, xe)
        elif stat == "mtotdev":
            r = _total.mtotvar(pd, m)
        elif stat == "ttotdev":
            r = _total.ttotvar(pd, m)
        elif stat == "htotdev":
            r = _total.htotvar(pd, m)
        else:  # pragma: no cover - guarded by the caller
            raise StatsError(f"unknown statistic {stat!r}")
        var[k], n[k], skipped[k] = r
        if progress is not None:
            progress(float(work[k] / work[-1]))
    return var, n, skipped


def _alpha_per_tau(alpha: int | Sequence[int] | np.ndarray | None, size: int) -> np.ndarray | None:
    if alpha is None:
        return None
    arr = np.atleast_1d(np.asarray(alpha))
    if arr.size == 1:
        arr = np.full(size, int(arr[0]))
    if arr.size != size or np.any(arr != np.round(arr)):
        raise StatsError(
            f"alpha must be one integer or one integer per tau ({size}), got {alpha!r}"
        )
    return arr.astype(np.int64)


class _Confidence:
    """Per-tau noise identification, bias factor and confidence limits of one result;
    collects a note wherever one of them cannot be computed (it is then NaN)."""

    def __init__(self) -> None:
        self.notes: list[str] = []

    def alpha(
        self, x: np.ndarray, m: int, data_type: str, var_stat: str, previous: int | None
    ) -> int:
        """Stable32's rule: identify on the series the user supplied (phase or freq);
        ``previous`` (alpha of the previous tau, None for the first or an unknown one) is
        kept beyond half the largest averaging factor (``noise_id.identifies_at``)."""
        try:
            return int(noise_id.identify_alpha(x, m, data_type, var_stat, previous))
        except StatsError as exc:  # noise ID may legitimately fail at the longest taus
            self.notes.append(f"noise id failed at m={m}: {exc}")
            return ALPHA_UNKNOWN

    def bias(self, var_stat: str, alpha: int, m: int, n_phase: int) -> float:
        if alpha == ALPHA_UNKNOWN:
            return float("nan")
        return float(bias.bias_factor(var_stat, alpha, m, n_phase))

    def limits(
        self, var_stat: str, alpha: int, m: int, runs: Runs, var: float,
        confidence: float
    ) -> tuple[float, float, float]:
        if alpha == ALPHA_UNKNOWN or not np.isfinite(var):
            return float("nan"), float("nan"), float("nan")
        try:
            e = float(runs_edf(var_stat, alpha, m, runs))
            lo, hi = ci.chi2_limits(var, e, confidence)
        except StatsError as exc:
            self.notes.append(f"EDF/CI failed for {var_stat} alpha={alpha} m={m}: {exc}")
            return float("nan"), float("nan"), float("nan")
        return e, float(lo), float(hi)


# Statistics Stable32 bias-corrects (TOTVAR for alpha -1/-2, HTOT, Theo1); MTOT and TTOT
# are listed too so that B's bias_factor decides (it returns 1.0 where Stable32 applies none).
BIAS_STATS = {"totdev", "mtotdev", "ttotdev", "htotdev", "theo1"}


def compute(
    stat: str,
    data: Any,
    rate: float = 1.0,
    data_type: str = "phase",
    taus: str | int | Sequence[float] | np.ndarray = "octave",
    *,
    confidence: float = 0.683,
    alpha: int | Sequence[int] | np.ndarray | None = None,
    bias_correction: bool = True,
    remove_drift: bool = False,
    max_af: float | None = None,
    afs: Sequence[int] | np.ndarray | None = None,
    progress: Progress | None = None,
) -> StatResult:
    """Compute deviation ``stat`` (a key of VAR_NAME, or its variance name)."""
    stat = DEV_NAME.get(stat, stat)
    if stat not in VAR_NAME:
        raise StatsError(f"unknown statistic {stat!r}; choose one of {sorted(VAR_NAME)}")
    if not 0.0 < confidence < 1.0:
        raise StatsError(f"confidence must be in (0, 1), got {confidence!r}")
    pd, drift = to_phase(data, rate, data_type, remove_drift)
    if stat == "theoh":
        return _theoh(pd, drift, data_type, rate, taus, confidence, alpha, max_af, afs, progress)
    return _compute_pd(
        stat, pd, drift=drift, data_type=data_type, rate=rate, taus=taus,
        confidence=confidence, alpha=alpha, bias_correction=bias_correction, max_af=max_af,
        afs=afs, progress=progress,
    )


def _compute_pd(
    stat: str,
    pd: PhaseData,
    *,
    drift: float | None,
    data_type: str,
    rate: float,
    taus: str | int | Sequence[float] | np.ndarray,
    confidence: float,
    alpha: int | Sequence[int] | np.ndarray | None,
    bias_correction: bool,
    max_af: float | None,
    afs: Sequence[int] | np.ndarray | None,
    progress: Progress | None,
) -> StatResult:
    """:func:`compute` on prepared phase data; noise ID uses the user's ``data_type``."""
    n_freq = pd.n_phase - 1
    tau0 = pd.tau0_s
    if afs is not None:
        ms = np.unique(np.asarray(afs, dtype=np.int64))
        if ms.size == 0 or ms[0] < 1 or ms[-1] > _max_af(stat, n_freq, max_af or n_freq):
            raise StatsError(f"afs out of range 1..{n_freq} for {stat}: {afs!r}")
    else:
        ms = averaging_factors(stat, n_freq, taus, tau0, max_af)
    if ms.size == 0:
        raise StatsError(
            f"{stat}: no averaging factor fits {n_freq} samples with taus={taus!r}; "
            "record more data or pass shorter taus"
        )
    conf = _Confidence()
    notes = list(conf.notes)
    theo_stat = stat in THEO_STATS
    if stat == "theobr":
        var_raw, n, skipped, kf = _theobr_raw(pd, ms, progress)
        notes.append(f"TheoBR kf = {kf:.6g} (n = {_theo.theobr_n(pd.n_phase)})")
    else:
        var_raw, n, skipped = _raw(stat, pd, ms, progress)
    fixed = _alpha_per_tau(alpha, ms.size)
    xn = _noise_phase(pd) if fixed is None else pd.x
    var_stat = VAR_NAME[stat]
    alphas = np.empty(ms.size, dtype=np.int64)
    factors = np.ones(ms.size)
    edfs = np.full(ms.size, np.nan)
    lo = np.full(ms.size, np.nan)
    hi = np.full(ms.size, np.nan)
    var = var_raw.copy()
    runs = pd.runs()
    for k, m in enumerate(ms):
        m = int(m)
        if fixed is not None:
            a = int(fixed[k])
        else:
            prev = int(alphas[k - 1]) if k and alphas[k - 1] != ALPHA_UNKNOWN else None
            a = conf.alpha(xn, m, data_type, var_stat, prev)
        alphas[k] = a
        if bias_correction and stat in BIAS_STATS:
            f = conf.bias(var_stat, a, m, pd.n_phase)
            if np.isfinite(f):
                factors[k] = f
                var[k] = var_raw[k] / f
            else:
                notes.append(f"no bias factor at m={m} (alpha unknown or bias module missing)")
        if stat == "theobr":
            factors[k] = 1.0 / kf
        edfs[k], lo[k], hi[k] = conf.limits(var_stat, a, m, runs, var[k], confidence)
    notes.extend(n_ for n_ in conf.notes if n_ not in notes)
    tau = ms * tau0 * (0.75 if theo_stat else 1.0)
    return StatResult(
        stat=stat,
        data_type=data_type,
        rate_hz=float(rate),
        tau_s=tau.astype(np.float64),
        m=ms.astype(np.int64),
        n=n,
        var=var,
        dev=np.sqrt(var),
        ci_low=lo,
        ci_high=hi,
        alpha=alphas,
        edf=edfs,
        confidence=float(confidence),
        bias_corrected=bool(np.any(factors != 1.0)),
        bias_factor=factors,
        drift=drift,
        gaps=skipped,
        notes=tuple(dict.fromkeys(notes)),
    )


def _theobr_raw(
    pd: PhaseData, ms: np.ndarray, progress: Progress | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    support = _theo.theobr_support_m(pd.n_phase)
    if support.size == 0:
        raise StatsError(f"TheoBR needs at least 90 phase points (N={pd.n_phase})")
    allm = np.unique(np.concatenate([support, ms]))
    v, nn, sk = _theo.theo1var(pd, allm, progress)
    at = {int(m): float(val) for m, val in zip(allm, v, strict=True)}
    kf = _theo.theobr_kf(pd, _allan.oavar, at)
    idx = np.searchsorted(allm, ms)
    return kf * v[idx], nn[idx].astype(np.int64), sk[idx].astype(np.int64), kf


def _theoh(
    pd: PhaseData,
    drift: float | None,
    data_type: str,
    rate: float,
    taus: Any,
    confidence: float,
    alpha: Any,
    max_af: float | None,
    afs: Any,
    progress: Progress | None,
) -> StatResult:
    """TheoH: OAVAR for tau <= 0.1 T, TheoBR (tau = 0.75 m tau0) beyond (SP 1065 eq. (33))."""
    n_freq = pd.n_phase - 1
    k = int(np.floor(0.1 * n_freq))
    if afs is not None:
        ms_all = np.unique(np.asarray(afs, dtype=np.int64))
    else:
        ms_all = averaging_factors("theobr", n_freq, taus, pd.tau0_s, max_af)
        ms_all = np.unique(
            np.concatenate([averaging_factors("oadev", n_freq, taus, pd.tau0_s), ms_all])
        )
    m_av = ms_all[ms_all <= k]
    m_br = ms_all[(0.75 * ms_all > k) & (ms_all % 2 == 0)]
    if alpha is not None and np.ndim(alpha):
        raise StatsError("theoh takes a single alpha (or None), not one per tau")
    parts = [
        _compute_pd(
            name, pd, drift=drift, data_type=data_type, rate=rate, taus=taus,
            confidence=confidence, alpha=alpha, bias_correction=True, max_af=max_af,
            afs=sel, progress=progress,
        )
        for name, sel in (("oadev", m_av), ("theobr", m_br))
        if sel.size
    ]
    if not parts:
        raise StatsError(f"theoh: no averaging factor fits {n_freq} samples")

    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(p, name) for p in parts])

    notes: list[str] = [f"TheoH: OAVAR for m <= {k} (0.1 T), TheoBR beyond"]
    for p in parts:
        notes.extend(p.notes)
    return StatResult(
        stat="theoh",
        data_type=data_type,
        rate_hz=float(rate),
        tau_s=cat("tau_s"),
        m=cat("m"),
        n=cat("n"),
        var=cat("var"),
        dev=cat("dev"),
        ci_low=cat("ci_low"),
        ci_high=cat("ci_high"),
        alpha=cat("alpha"),
        edf=cat("edf"),
        confidence=float(confidence),
        bias_corrected=any(p.bias_corrected for p in parts),
        bias_factor=cat("bias_factor"),
        drift=drift,
        gaps=cat("gaps"),
        notes=tuple(dict.fromkeys(notes)),
    )
