"""Fit of the model file's noise terms to a recording's Allan variance curve.

Method ``wls`` (default), in four steps:

1. **Points.** The overlapping AVAR ``a_i`` at octave averaging factors (or the caller's
   taus) with its EDF (Greenhall & Riley, PTTI 2003, per identified noise type), from
   :func:`imubench.stats.oadev`.
2. **Linear terms.** With the nonlinear settings fixed (Markov correlation time, sine
   frequency, output filter bandwidth/order, resonance centre/width), the model AVAR is
   linear in the squared amplitudes theta = (N^2, B^2, K^2, R^2, Q^2, sigma_M^2, A^2) and
   the resonance's PSD height h (linear itself): ``a ~ X theta`` with X the
   exact sampled-data AVAR of each term at unit amplitude (:mod:`.kernels`). theta >= 0 is
   solved by non-negative generalized least squares with the covariance
   ``Sigma_ij = r_ij sqrt(V_i V_j)``, ``V_i = 2 A_i^2 / edf_i`` (chi-squared variance of an
   AVAR estimate, SP 1065 eq. 44) at the *model* AVAR A_i (iterated: weights from the data
   bias the fit low), and r_ij the correlation of overlapping estimates from the model
   (:mod:`.covariance`).
3. **Model selection** (``terms="auto"``; every term gets a reason in
   :attr:`ChannelFit.reasons` and its statistic in :attr:`ChannelFit.chi2_drop`).
   (a) Nonlinear extensions (output filter, Gauss-Markov, sine, and a resonance where the
   spectrum has a narrowband peak: :func:`.spectral_line.find_peak` gives its centre,
   its width is searched about the peak's) are searched on log grids (then refined); a
   subset of them is chosen by GLS chi-squared charged :data:`EXTENSION_DCHI2` per
   extension (:func:`_select_extensions`). (b) Each chosen
   extension must be backed by the data (:func:`_extension_verdict`): Markov tau_c's
   profile interval within the data's taus, the filter's bandwidth interval excluding
   "no filter" and its estimate off the search's lower edge, a sine backed by a
   significant spectral line carrying half its amplitude (:mod:`.spectral_line`); one
   that fails is excluded and the subsets compared again (:func:`_backed_extensions`).
   (c) Base terms enter by stepwise likelihood ratio, a term entering when it lowers
   chi2 by more than :func:`entry_dchi2` (:func:`_stepwise`). (d) Finally every
   reported amplitude's 95 % interval must exclude 0; the weakest term failing that is
   dropped and the rest refitted (:func:`_validate`).
4. **Intervals.** 95 % intervals on theta from the GLS covariance (X' Sigma^-1 X)^-1,
   mapped to amplitudes by the square root (clipped at 0); absent terms get
   (0, sqrt(theta + 1.645 se)) from a fit that includes them. Markov time, sine frequency
   and bandwidth get profile intervals (chi-squared rise <= 3.84); the amplitudes'
   intervals are at the fitted settings.

``tangent`` lives in :mod:`.tangent`. (GMWM, Guerrier et al. 2013, is not implemented:
its estimator is this GLS with a nonparametric instead of a model-based weight matrix.)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np
from lsm6ds_sim.model import ChannelModel
from scipy.optimize import minimize_scalar, nnls

from imubench.errors import StatsError
from imubench.noisefit.covariance import oavar_correlation, oavar_edf
from imubench.noisefit.errors import FitError
from imubench.noisefit.kernels import (
    AMPLITUDE_KEY,
    HEIGHT_TERMS,
    averaging_factors,
    key_value,
    term_avar,
)
from imubench.noisefit.misfit import broad_misfit, curve_misfit
from imubench.noisefit.model_avar import model_avar
from imubench.noisefit.spectral_line import PeakTest, find_peak
from imubench.noisefit.temperature import TemperatureResponse
from imubench.noisefit.units import (
    WHITE_EQUIVALENT,
    param_units,
    term_value,
    white_equivalent,
    white_equivalent_interval,
    white_equivalent_weights,
)

BASE_TERMS: tuple[str, ...] = ("white", "flicker", "random_walk", "ramp", "quantization")
EXTENSIONS: tuple[str, ...] = ("filter", "markov", "sine", "resonance")
TERM_NAMES: tuple[str, ...] = BASE_TERMS + EXTENSIONS
Z_PRESENT: float = 1.645
"""One-sided z (5 %) of the upper limit reported for a term judged absent."""
LINEAR_DCHI2: float = 9.55
"""GLS chi-squared drop flicker, ramp or quantization must give to enter: for theta >= 0 on the
boundary the likelihood-ratio statistic is distributed as (chi2_0 + chi2_1) / 2 (Self &
Liang 1987), so 9.55 = chi2_1 at 0.998 is a 0.1 % test per term."""
CORE_TERMS: tuple[str, ...] = ("white", "random_walk")
"""Terms tested at 1 % (:data:`CORE_DCHI2`); flicker, ramp and quantization at 0.1 %.

Calibrated by simulation (bench/bench_fit_acceptance.py, shipped chip models, 30 min at
104 Hz, seeds 1-16): where the truth lacks them, white's drop exceeded 5.41 in 0.4 %
of about 270 fits and random walk's never (largest 3.3), while flicker's, where the
truth has a weak random walk instead, exceeded 5.41 in 4.4 % and 9.55 in 1 % of fits (the
two are nearly collinear over a short record). Flicker is strong wherever it is present
(drops of 50-400), so the stricter level costs it little."""
CORE_DCHI2: float = 5.41
"""GLS chi-squared drop white or random walk must give to enter: chi2_1 at 0.98, a 1 %
test on the boundary. (At 9.55 the random walk of white 0.004 + flicker 0.002 + random
walk 2e-4 over 3 h at 100 Hz, drops of 9-15, was missed on 6 of 10 seeds.)"""


def entry_dchi2(term: str) -> float:
    """Chi-squared drop a base term must give to enter the model."""
    return CORE_DCHI2 if term in CORE_TERMS else LINEAR_DCHI2
EXTENSION_DCHI2: float = 13.8
"""GLS chi-squared drop an extension (2 parameters) must give: chi2_2 at 0.999, which
covers the look-elsewhere effect of the grid search better than BIC's 2 ln(n)."""
MIN_SPARE_DOF: int = 3
"""Degrees of freedom (AVAR points less parameters) the reference subset of the
extension search must leave."""
SEARCH_DELTA: float = 0.02
"""Relative floor used while searching the nonlinear settings only: it smooths the chi2
landscape that points with EDF ~1e6 make rugged (final fits use the estimated delta)."""
FILTER_MIN_FRACTION: float = 0.02
"""Lowest output-filter bandwidth searched, as a fraction of the sample rate."""
FILTER_FLOOR_STEP: float = 4.0
"""A filter pinned at the lowest bandwidth searched is searched again above this factor
times it (:func:`_backed_extensions`) ..."""
FILTER_FLOOR_MAX: float = 0.2
"""... while that floor stays below this fraction of the rate."""
DELTA_LEVEL: float = 0.99
"""Quantile of chi2(n - p) the GLS chi2 must exceed before a discrepancy floor is added."""
Z95: float = 1.959964
METHODS: tuple[str, ...] = ("wls", "tangent", "whittle", "exact")
PARAM_KEYS: tuple[str, ...] = (
    "white", "flicker", "random_walk", "ramp", "quantization", "markov_sigma",
    "markov_tau", "sine_amplitude", "sine_freq", "bandwidth_hz", "filter_order",
    "output_white", "resonance_freq_hz", "resonance_width_hz", "resonance_height",
)


@dataclass(frozen=True)
class Structure:
    """Which linear terms, and the nonlinear settings they are evaluated with."""

    terms: tuple[str, ...]
    tau_c_s: float = 0.0
    f0_hz: float = 0.0
    bandwidth_hz: float = 0.0
    filter_order: int = 1
    res_freq_hz: float = 0.0
    """Centre of the resonance (Hz), from the spectrum's peak (:attr:`Points.peak`)."""
    res_width_hz: float = 0.0
    """-3 dB width of the resonance (Hz); > 0 when the structure carries one."""


@dataclass(frozen=True)
class Points:
    """The AVAR points a fit uses."""

    tau_s: np.ndarray
    m: np.ndarray
    avar: np.ndarray
    edf: np.ndarray
    n_terms: np.ndarray
    rate_hz: float
    n_samples: int
    delta: float = 0.0
    """Relative model-discrepancy std added to every point (see :func:`_estimate_delta`)."""
    filter_min_hz: float = 0.0
    """Lowest output-filter bandwidth searched (Hz); 0: :data:`FILTER_MIN_FRACTION` x rate."""
    filter_bounded: bool = False
    """The search floor cannot be raised further (:func:`_backed_extensions`): a filter
    pinned at it is kept when the data need its shape, reported as bounded above only."""
    peak: PeakTest | None = None
    """The spectrum's narrowband peak (:func:`.spectral_line.find_peak`) the resonance
    extension is tried at; None: no resonance is tried."""

    @property
    def filter_floor_hz(self) -> float:
        """Lowest output-filter bandwidth searched (Hz)."""
        return self.filter_min_hz or FILTER_MIN_FRACTION * self.rate_hz


@dataclass(frozen=True)
class ChannelFit:
    """Result of fitting one channel (see docs/noise-fit.md).

    ``params`` model-file keys -> value (model units: dps or g based), ``ci`` 95 %
    intervals, ``present`` keys of the terms judged present, ``tau_s/avar/edf`` the points
    used. ``bias`` is the data mean (unit), ``chi2``/``dof`` the GLS fit statistic.
    """

    channel: str
    rate_hz: float
    method: str
    params: dict[str, float]
    ci: dict[str, tuple[float, float]]
    present: tuple[str, ...]
    tau_s: np.ndarray
    avar: np.ndarray
    edf: np.ndarray
    bias: float = 0.0
    chi2: float = float("nan")
    dof: int = 0
    notes: tuple[str, ...] = field(default=())
    reasons: dict[str, str] = field(default_factory=dict)
    """Term name (:data:`TERM_NAMES`) -> why it was kept or dropped, in plain words."""
    chi2_drop: dict[str, float] = field(default_factory=dict)
    """Term name -> its likelihood-ratio statistic in the selection (GLS chi2 without it
    minus with it; extensions: best setting of the search), compared with
    :func:`entry_dchi2` or :data:`EXTENSION_DCHI2`."""
    temperature: TemperatureResponse | None = None
    """The response to the die temperature taken out of the data before the noise terms
    were fitted (``imubench fit --fit-temperature``), written to the model file."""
    temperature_check: TemperatureResponse | None = None
    """The response the temperature check estimated, taken out or not (the numbers of
    the fit's temperature warning; None without a usable temperature)."""

    def channel_model(self, base: ChannelModel | None = None) -> ChannelModel:
        """A ChannelModel with the fitted noise keys over ``base``.

        The data mean (``bias``) is not written: for an accelerometer it holds gravity,
        which the simulator adds itself.
        """
        cm = base if base is not None else ChannelModel()
        vals: dict[str, float] = {k: float(v) for k, v in self.params.items()}
        vals["filter_order"] = int(self.params.get("filter_order", 1))
        if self.temperature is not None:
            vals.update(self.temperature.terms._asdict())
        return cm.replace(**vals)

    def coefficient(self, key: str) -> tuple[float, tuple[float, float] | None]:
        """(value, 95 % interval) of a coefficient: a model-file key, or the
        white-equivalent density (:func:`~imubench.noisefit.units.white_equivalent`; its
        interval is the fit's ``white_equivalent`` one, or ``white``'s when white is its
        only part). Value 0 when the fit judged it absent; the interval is then (0, upper
        limit) or None."""
        present = {k: v for k, v in self.params.items() if k in self.present}
        value = term_value(present, key, self.rate_hz)
        ci = self.ci.get(key)
        if key == WHITE_EQUIVALENT and ci is None and (
                value <= 0 or math.isclose(value, float(present.get("white", 0.0)))):
            ci = self.ci.get("white")
        return value, None if ci is None else (float(ci[0]), float(ci[1]))

    def model_avar(self, tau_s: Sequence[float] | np.ndarray,
                   rate_hz: float | None = None) -> np.ndarray:
        """Predicted AVAR (unit^2) at ``tau_s`` for data at ``rate_hz`` (default: the fit's)."""
        return model_avar(self.channel_model(), tau_s, self.rate_hz if rate_hz is None
                          else rate_hz)

    def term_avars(self, tau_s: Sequence[float] | np.ndarray,
                   rate_hz: float | None = None) -> dict[str, np.ndarray]:
        """AVAR of each present term alone (filter included) at ``tau_s``: for plots."""
        rate = self.rate_hz if rate_hz is None else rate_hz
        cm0 = ChannelModel().replace(
            bandwidth_hz=self.params.get("bandwidth_hz", 0.0),
            filter_order=int(self.params.get("filter_order", 1)))
        out: dict[str, np.ndarray] = {}
        for term, key in AMPLITUDE_KEY.items():
            if key not in self.present:
                continue
            extra: dict[str, float] = {key: self.params[key]}
            if term == "markov":
                extra["markov_tau"] = self.params["markov_tau"]
            if term == "sine":
                extra["sine_freq"] = self.params["sine_freq"]
            if term == "resonance":
                extra["resonance_freq_hz"] = self.params["resonance_freq_hz"]
                extra["resonance_width_hz"] = self.params["resonance_width_hz"]
            out[term] = model_avar(cm0.replace(**extra), tau_s, rate)
        return out

    def to_dict(self) -> dict[str, object]:
        """JSON-ready summary."""
        return {
            "channel": self.channel,
            "rate_hz": self.rate_hz,
            "method": self.method,
            "params": dict(self.params),
            "ci95": {k: [_finite(a), _finite(b)] for k, (a, b) in self.ci.items()},
            "present": list(self.present),
            "bias": self.bias,
            "chi2": None if not math.isfinite(self.chi2) else self.chi2,
            "dof": self.dof,
            "points": {"tau_s": self.tau_s.tolist(), "avar": self.avar.tolist(),
                       "edf": self.edf.tolist()},
            "notes": list(self.notes),
            "reasons": dict(self.reasons),
            "chi2_drop": {k: _finite(v) for k, v in self.chi2_drop.items()},
            "temperature_response": (
                None if self.temperature is None
                else self.temperature.to_dict(param_units(self.channel)["bias"])),
            "temperature_check": (
                None if self.temperature_check is None
                else {**self.temperature_check.to_dict(param_units(self.channel)["bias"]),
                      "taken_out": self.temperature is not None}),
        }


# ------------------------------------------------------------------------ input
def check_series(y: np.ndarray | Sequence[float], rate_hz: float, channel: str) -> np.ndarray:
    """The rate series as float64, or FitError saying what is wrong with it."""
    arr = np.asarray(y, dtype=np.float64)
    if arr.ndim != 1:
        raise FitError(f"fit {channel}: data must be 1-D, got shape {arr.shape}")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise FitError(f"fit {channel}: rate_hz must be > 0, got {rate_hz}")
    ok = np.isfinite(arr)
    if ok.sum() < 64:
        raise FitError(f"fit {channel}: needs at least 64 finite samples, got {int(ok.sum())}")
    if np.nanstd(arr) == 0.0:
        raise FitError(f"fit {channel}: the data are constant; there is no noise to fit")
    return arr


def parse_terms(terms: str | Iterable[str]) -> tuple[str, ...] | None:
    """None for "auto", else the validated tuple of term names."""
    if isinstance(terms, str):
        if terms.strip().lower() == "auto":
            return None
        items = [t.strip() for t in terms.split(",") if t.strip()]
    else:
        items = [str(t).strip() for t in terms]
    if not items:
        raise FitError("terms: empty list; use 'auto' or names among " + ", ".join(TERM_NAMES))
    bad = [t for t in items if t not in TERM_NAMES]
    if bad:
        raise FitError(f"terms: unknown term(s) {bad}; use 'auto' or names among "
                       + ", ".join(TERM_NAMES))
    return tuple(dict.fromkeys(items))


def avar_points(y: np.ndarray, rate_hz: float, taus: Sequence[float] | str | None,
                channel: str) -> Points:
    """OAVAR with EDF at octave m (or the given taus) via :func:`imubench.stats.oadev`."""
    from imubench.stats import oadev

    try:
        res = oadev(y, rate_hz, "freq", "octave" if taus is None else taus, confidence=0.95)
    except StatsError as exc:
        raise FitError(f"fit {channel}: {exc}") from exc
    ok = np.isfinite(res.var) & (res.var > 0) & np.isfinite(res.edf) & (res.edf > 0)
    if ok.sum() < 3:
        raise FitError(f"fit {channel}: only {int(ok.sum())} usable Allan variance points; "
                       "the record is too short for a fit")
    return Points(res.tau_s[ok], res.m[ok].astype(np.int64), res.var[ok], res.edf[ok],
                  res.n[ok].astype(np.int64), float(rate_hz), int(y.size))


# ------------------------------------------------------------------------ linear algebra
def design(st: Structure, pts: Points) -> np.ndarray:
    """Columns: AVAR of each linear term of ``st`` at unit amplitude at the points."""
    key = pts.m.tobytes()
    cols = [_column(term, key, pts.rate_hz, st.tau_c_s if term == "markov" else 0.0,
                    _frequency(st, term), st.bandwidth_hz, st.filter_order,
                    st.res_width_hz if term == "resonance" else 0.0)
            for term in st.terms]
    return np.column_stack(cols) if cols else np.zeros((pts.m.size, 0))


def _frequency(st: Structure, term: str) -> float:
    """The frequency setting (Hz) a term's column is evaluated at (0 when it has none)."""
    return st.f0_hz if term == "sine" else st.res_freq_hz if term == "resonance" else 0.0


@lru_cache(maxsize=4096)
def _column(term: str, m_bytes: bytes, rate_hz: float, tau_c_s: float, f0_hz: float,
            bandwidth_hz: float, filter_order: int, width_hz: float) -> np.ndarray:
    m = np.frombuffer(m_bytes, dtype=np.int64)
    return term_avar(term, m, rate_hz, tau_c_s=tau_c_s, f0_hz=f0_hz,
                     bandwidth_hz=bandwidth_hz, filter_order=filter_order, width_hz=width_hz)


@dataclass
class _Solution:
    theta: np.ndarray
    cov_theta: np.ndarray
    chi2: float
    sigma: np.ndarray


def _solve(x: np.ndarray, a: np.ndarray, sigma: np.ndarray) -> _Solution:
    """Non-negative GLS: min (X t - a)' Sigma^-1 (X t - a), t >= 0; covariance of t."""
    chol = np.linalg.cholesky(sigma)
    xw = np.linalg.solve(chol, x)
    aw = np.linalg.solve(chol, a)
    peak = np.max(np.abs(xw), axis=0) if xw.size else np.zeros(0)
    peak[~(peak > 0)] = 1.0
    scale = peak * np.linalg.norm(xw / peak, axis=0)  # no overflow of the squares
    scale[scale == 0] = 1.0
    t_scaled, _ = nnls(xw / scale, aw, maxiter=50 * max(x.shape[1], 1))
    theta = t_scaled / scale
    r = xw @ theta - aw
    fisher = (xw / scale).T @ (xw / scale)
    cov_scaled = np.linalg.pinv(fisher, rcond=1e-12)
    cov = cov_scaled / scale[:, None] / scale[None, :]
    return _Solution(theta, cov, float(r @ r), sigma)


def _amp2(st: Structure, theta: np.ndarray) -> dict[str, float]:
    return {t: float(v) for t, v in zip(st.terms, theta, strict=True)}


def _correlation(st: Structure, sol: _Solution, pts: Points) -> np.ndarray:
    """Model correlation of the OAVAR points for the fitted structure (:mod:`.covariance`)."""
    return oavar_correlation(pts.m, pts.n_terms, _amp2(st, sol.theta), pts.rate_hz,
                             tau_c_s=st.tau_c_s, bandwidth_hz=st.bandwidth_hz,
                             filter_order=st.filter_order,
                             resonance=(st.res_freq_hz, st.res_width_hz))


def _with_model_edf(st: Structure, sol: _Solution, pts: Points) -> Points:
    """Points whose EDF is min(Greenhall-Riley EDF, model EDF) (:func:`.oavar_edf`).

    The Greenhall-Riley EDF of :func:`imubench.stats.oadev` assumes one power law per
    tau; on mixtures it overstates the information of the points (white + flicker + random
    walk, 3 h at 100 Hz, 120-seed Monte Carlo EDF vs Greenhall / model: m = 1 6.5e5 vs
    8.5e5 / 7.2e5; m = 131072 4.7 vs 10.2 / 7.1; m = 262144 1.8 vs 4.2 / 2.7, see
    docs/noise-fit.md), which made the intervals too narrow. The smaller of the two is
    the closer at every tau checked.
    """
    amp2 = _amp2(st, sol.theta)
    model = design(st, pts) @ sol.theta
    edf = oavar_edf(pts.m, pts.n_terms, amp2, model, pts.rate_hz, tau_c_s=st.tau_c_s,
                    bandwidth_hz=st.bandwidth_hz, filter_order=st.filter_order,
                    resonance=(st.res_freq_hz, st.res_width_hz))
    return replace(pts, edf=np.minimum(pts.edf, edf))


def _fit_structure(st: Structure, pts: Points, corr: np.ndarray | None = None,
                   iterations: int = 3) -> _Solution:
    """Iteratively reweighted non-negative GLS of the linear terms of ``st``.

    The variances follow the model (V = 2 A_model^2 / edf, starting from the data); the
    correlation ``corr`` is held fixed (identity when None).
    """
    x = design(st, pts)
    a = pts.avar
    corr = np.eye(a.size) if corr is None else corr
    model = a.copy()
    sol: _Solution | None = None
    for _ in range(iterations):
        mod = np.maximum(model, 1e-3 * a)
        v = 2.0 * mod**2 / pts.edf
        sigma = corr * np.sqrt(np.outer(v, v)) + np.diag((pts.delta * mod) ** 2)
        sol = _solve(x, a, sigma)
        model = x @ sol.theta
    assert sol is not None
    return sol


def _fit_gls(st: Structure, pts: Points) -> tuple[_Solution, np.ndarray]:
    """Diagonal fit, model correlation from it, then the GLS fit with that correlation."""
    sol = _fit_structure(st, pts, None, iterations=2)
    corr = _correlation(st, sol, pts)
    return _fit_structure(st, pts, corr), corr


def _chi2_fixed_sigma(st: Structure, pts: Points, sigma: np.ndarray) -> tuple[float, _Solution]:
    sol = _solve(design(st, pts), pts.avar, sigma)
    return sol.chi2, sol


# ------------------------------------------------------------------------ nonlinear search
def _grid(kind: str, pts: Points) -> np.ndarray:
    tau0 = 1.0 / pts.rate_hz
    span = pts.n_samples * tau0
    if kind == "markov":  # a correlation time needs many of itself in the record
        return np.geomspace(2.0 * tau0, span / 30.0, 20)
    if kind == "sine":  # ... and a sine many periods, else it is low-frequency noise
        return np.geomspace(30.0 / span, 0.45 * pts.rate_hz, 160)
    if kind == "resonance":  # widths about the peak's FWHM (a Welch estimate, widened
        lo, hi = _resonance_width_range(pts)  # by the window)
        return np.geomspace(lo, hi, 9)
    return np.geomspace(pts.filter_floor_hz, 0.45 * pts.rate_hz, 14)


RESONANCE_WIDTH_SPAN: float = 3.0
"""The resonance's width is searched within this factor of the peak test's FWHM."""


def _resonance_width_range(pts: Points) -> tuple[float, float]:
    """(lowest, highest) resonance width searched (Hz): :data:`RESONANCE_WIDTH_SPAN`
    about the peak's FWHM, at most the centre frequency and below 0.45 fs."""
    assert pts.peak is not None
    w = pts.peak.width_hz
    hi = min(w * RESONANCE_WIDTH_SPAN, pts.peak.freq_hz, 0.45 * pts.rate_hz)
    return min(w / RESONANCE_WIDTH_SPAN, hi), hi


def _with(st: Structure, kind: str, value: float, order: int = 1) -> Structure:
    if kind == "resonance":
        terms = st.terms if "resonance" in st.terms else (*st.terms, "resonance")
        return replace(st, terms=terms, res_width_hz=value)
    if kind == "markov":
        terms = st.terms if "markov" in st.terms else (*st.terms, "markov")
        return replace(st, terms=terms, tau_c_s=value)
    if kind == "sine":
        terms = st.terms if "sine" in st.terms else (*st.terms, "sine")
        return replace(st, terms=terms, f0_hz=value)
    terms = st.terms if "output_white" in st.terms else (*st.terms, "output_white")
    return replace(st, terms=terms, bandwidth_hz=value, filter_order=order)


def _search(st: Structure, kind: str, pts: Points,
            corr: np.ndarray | None = None) -> tuple[Structure, float]:
    """Best value of one nonlinear setting (fixed correlation ``corr``; grid then refine)."""
    return _search_scored(st, kind, pts,
                          lambda cand: _fit_structure(cand, pts, corr, iterations=2).chi2)


def _search_scored(st: Structure, kind: str, pts: Points,
                   score: Callable[[Structure], float]) -> tuple[Structure, float]:
    """The value of one nonlinear setting of lowest ``score`` (chi2 of the structure):
    :func:`_grid`, then bounded refinement between the best point's neighbours (a filter:
    for each order, 1 and 2)."""
    orders = (1, 2) if kind == "filter" else (1,)
    best: tuple[float, Structure] | None = None
    grid = _grid(kind, pts)
    for order in orders:
        def f(logv: float, order: int = order) -> float:
            return score(_with(st, kind, float(np.exp(logv)), order))

        chis = [f(math.log(v)) for v in grid]
        i = int(np.argmin(chis))
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
        if hi > lo:
            r = minimize_scalar(f, bounds=(math.log(lo), math.log(hi)), method="bounded",
                                options={"xatol": 1e-3})
            v, c = float(np.exp(r.x)), float(r.fun)
            if c > chis[i]:
                v, c = float(grid[i]), float(chis[i])
        else:
            v, c = float(grid[i]), float(chis[i])
        if best is None or c < best[0]:
            best = (c, _with(st, kind, v, order))
    assert best is not None
    return best[1], best[0]


def _optimise(st: Structure, kinds: Sequence[str], pts: Points,
              corr: np.ndarray | None = None, rounds: int = 2) -> Structure:
    """Coordinate search of the nonlinear settings of ``kinds`` (filter first)."""
    current = st
    for _ in range(rounds if len(kinds) > 1 else 1):
        for kind in kinds:
            current, _ = _search(current, kind, pts, corr)
    return current


def _settings(st: Structure, kinds: Sequence[str]) -> list[float]:
    return [math.log(getattr(st, _SETTING[k])) for k in kinds]


def _polish(st: Structure, kinds: Sequence[str], pts: Points,
            corr: np.ndarray | None = None) -> Structure:
    """Joint Nelder-Mead refinement (log space) of the nonlinear settings of ``kinds``."""
    from scipy.optimize import minimize

    kinds = [k for k in kinds if k != "filter" or st.bandwidth_hz > 0]
    if not kinds:
        return st

    def build(logs: np.ndarray) -> Structure:
        cand = st
        for k, lv in zip(kinds, logs, strict=True):
            v = float(np.exp(lv))
            if k == "filter":
                # the output filter shapes the shortest taus: keep it in its grid's range
                v = min(max(v, pts.filter_floor_hz), 0.49 * pts.rate_hz)
            if k == "resonance":  # the width: within its grid's range
                lo, hi = _resonance_width_range(pts)
                v = min(max(v, lo), hi)
            cand = _with(cand, k, v, st.filter_order)
        return cand

    def f(logs: np.ndarray) -> float:
        return _fit_structure(build(logs), pts, corr, iterations=2).chi2

    x0 = np.array(_settings(st, kinds))
    r = minimize(f, x0, method="Nelder-Mead",
                 options={"xatol": 1e-4, "fatol": 1e-3, "maxfev": 150 * len(kinds)})
    return build(r.x) if r.fun <= f(x0) else st


def _estimate_delta(st: Structure, pts: Points, corr: np.ndarray, n_nonlinear: int) -> float:
    """Relative model-discrepancy std delta that brings chi2 to its degrees of freedom.

    A real sensor is never exactly the model, and its short-tau AVAR points have EDFs of
    1e5 and more: without a floor, 1 % of misfit there outweighs everything else. Each
    point's variance becomes V_i + (delta A_i)^2 with delta the smallest value for which
    the GLS chi2 of the richest model equals n - p (the Birge-ratio / excess-scatter
    convention). The floor is only added when the misfit is significant (chi2 above its
    :data:`DELTA_LEVEL` quantile): a chi2 above n - p by chance, as on half of the
    records a model describes exactly, would otherwise widen some intervals tenfold
    (the short-tau points, EDF ~1e6, lose their weight) and narrow others.
    """
    from scipy.optimize import brentq
    from scipy.stats import chi2

    dof = max(pts.avar.size - len(st.terms) - n_nonlinear, 1)

    def excess(log_delta: float) -> float:
        p = replace(pts, delta=float(np.exp(log_delta)))
        return _fit_structure(st, p, corr).chi2 - dof

    if _fit_structure(st, pts, corr).chi2 <= chi2.ppf(DELTA_LEVEL, dof):
        return 0.0
    lo, hi = math.log(1e-5), math.log(2.0)
    if excess(hi) > 0:
        return 2.0
    if excess(lo) < 0:
        return 1e-5
    return float(np.exp(brentq(excess, lo, hi, xtol=1e-3)))


def _select_extensions(st: Structure, pts: Points, allowed: Sequence[str]
                       ) -> tuple[Structure, Points, dict[str, float]]:
    """Best subset of the nonlinear extensions (filter, Markov, sine, resonance; the
    resonance only when ``pts.peak`` holds a narrowband peak).

    Every subset is fitted (settings by coordinate search with diagonal weights); the best
    fitting one (lowest chi2) is refined and gives the reference covariance (model
    correlation and discrepancy floor delta); all subsets are compared by their GLS
    chi-squared on that covariance, each charged :data:`EXTENSION_DCHI2` per extension.
    Also returns each extension's chi2 drop against the chosen subset (the chosen subset
    with the extension vs without it), for the reasons of :func:`_validate`.
    """
    from itertools import combinations

    kinds = [k for k in EXTENSIONS if k in allowed and (k != "resonance" or pts.peak)]
    subsets = [c for r in range(len(kinds) + 1) for c in combinations(kinds, r)]
    coarse = replace(pts, delta=SEARCH_DELTA)
    fitted = {sub: _optimise(st, sub, coarse) for sub in subsets}
    chi2_diag = {sub: _fit_structure(fitted[sub], coarse, None).chi2 for sub in subsets}
    # the reference must leave degrees of freedom for the discrepancy floor: a subset
    # with as many parameters as points fits anything and makes every drop look small
    def spare(sb: tuple[str, ...]) -> int:
        return int(pts.avar.size - len(fitted[sb].terms) - 2 * len(sb))

    usable = [sb for sb in subsets if spare(sb) >= MIN_SPARE_DOF] or [()]
    ref_sub = min(usable, key=lambda sb: chi2_diag[sb])
    reference = _polish(_polish(fitted[ref_sub], ref_sub, coarse), ref_sub, pts)
    fitted[ref_sub] = reference
    sol_ref = _fit_structure(reference, pts, None, iterations=3)
    pts = _with_model_edf(reference, sol_ref, pts)
    sol_ref = _fit_structure(reference, pts, None, iterations=3)
    corr = _correlation(reference, sol_ref, pts)
    pts = replace(pts, delta=_estimate_delta(reference, pts, corr, 2 * len(ref_sub)))
    sigma = _fit_structure(reference, pts, corr).sigma
    # each subset's filter searched again on that covariance: its bandwidth was chosen with
    # the coarse floor's weights, and judged at it on the reference covariance the other
    # extensions absorbed its misplacement (white + flicker + quantization behind a 20 Hz
    # filter, no Markov term: "Markov chi2 drop 43", "sine 24.5")
    for sub in subsets:
        fitted[sub] = _filter_profiled(fitted[sub], pts, sigma)[1]
    chi2s = {sub: _chi2_fixed_sigma(fitted[sub], pts, sigma)[0] for sub in subsets}
    best_sub = min(subsets, key=lambda sb: chi2s[sb] + EXTENSION_DCHI2 * len(sb))
    # chi2 drop of each extension against the chosen subset: with it vs without it
    drops: dict[str, float] = {}
    for k in kinds:
        with_k = tuple(x for x in kinds if x in best_sub or x == k)
        without_k = tuple(x for x in kinds if x in best_sub and x != k)
        drops[k] = float(chi2s[without_k] - chi2s[with_k])
    chosen = fitted[best_sub]
    chosen_kinds = tuple(k for k in kinds if (k == "filter" and chosen.bandwidth_hz > 0)
                         or (k != "filter" and k in chosen.terms))
    return _polish(chosen, chosen_kinds, pts, corr), pts, drops


def _filter_profiled(st: Structure, pts: Points, sigma: np.ndarray
                     ) -> tuple[float, Structure]:
    """Chi2 of ``st`` on the fixed covariance ``sigma`` with its output filter's bandwidth
    and order searched again (``st`` itself when it has no filter), and that structure.

    The bandwidth trades with the base terms that shape the same taus (white,
    quantization): searched with every base term present, it can sit where a term is
    needed that a filter elsewhere makes unnecessary. ADIS16405 rep 1 gy, second hour:
    quantization 0.0062 dps s was kept, "chi2 drop 3788", beside a filter at 7.5 Hz; with
    the bandwidth searched again for each set of terms its drop is 0 (threshold 9.55) and
    the filter sits at 24.2 [23.8, 24.7] Hz.
    The chi2 difference of two structures each at its own best bandwidth is the
    profile likelihood ratio of the term, the filter's setting a nuisance parameter.
    """
    chi2 = _chi2_fixed_sigma(st, pts, sigma)[0]
    if st.bandwidth_hz <= 0:
        return chi2, st
    searched, c = _search_scored(st, "filter", pts,
                                 lambda cand: _chi2_fixed_sigma(cand, pts, sigma)[0])
    return (c, searched) if c < chi2 else (chi2, st)


def _stepwise(st: Structure, pts: Points
              ) -> tuple[Structure, _Solution, dict[str, float]]:
    """Stepwise choice of the base terms by their likelihood ratio.

    On the covariance of the GLS fit of ``st`` (all base terms and the chosen
    extensions; held fixed, so chi2 differences are likelihood-ratio statistics of a
    Gaussian model with known covariance; the output filter's bandwidth is searched
    again for every set of base terms, :func:`_filter_profiled`), base terms are added
    one at a time, the one
    with the largest chi2 drop over its threshold first, while that drop exceeds the
    threshold (:func:`entry_dchi2`); then any term whose removal raises chi2 by less
    than its threshold is removed
    (smallest rise first) and the forward step resumes, until neither step changes the
    set. Forward from the extensions alone (rather than backward from every term) keeps,
    of two terms the data cannot tell apart (flicker and random walk in a short record),
    the one that explains more; backward elimination by z dropped whichever was weaker in
    the joint fit and then reported the other. Also returns each base term's chi2 change
    at the end: the drop it gives when added, or the rise its removal gives.

    (Scoring each candidate by -2 ln L = chi2 + ln det Sigma with Sigma at its own model
    was tried: it fits ADIS16405 rep 1 gz far better, but its null distribution is not
    chi2-like (a ramp absent from the truth got drops up to 45, flicker up to 195: 6 false
    terms in 68 simulated channel fits), so it is not used.)
    """
    sigma = _fit_gls(st, pts)[0].sigma
    fixed = tuple(t for t in st.terms if t not in BASE_TERMS)
    chosen: list[str] = []
    profiled: dict[tuple[str, ...], tuple[float, Structure]] = {}

    def fit_of(base: Sequence[str]) -> tuple[float, Structure]:
        terms = tuple(t for t in BASE_TERMS if t in base) + fixed
        if terms not in profiled:
            if not terms:
                profiled[terms] = (float(pts.avar @ np.linalg.solve(sigma, pts.avar)), st)
            else:
                profiled[terms] = _filter_profiled(replace(st, terms=terms), pts, sigma)
        return profiled[terms]

    def chi2_of(base: Sequence[str]) -> float:
        return fit_of(base)[0]

    for _ in range(4 * len(BASE_TERMS)):
        changed = False
        now = chi2_of(chosen)
        gains = {t: now - chi2_of([*chosen, t]) for t in BASE_TERMS
                 if t in st.terms and t not in chosen}
        if gains:
            best = max(gains, key=lambda t: gains[t] - entry_dchi2(t))
            if gains[best] > entry_dchi2(best):
                chosen.append(best)
                changed = True
        if len(chosen) > 1:
            now = chi2_of(chosen)
            rises = {t: chi2_of([c for c in chosen if c != t]) - now for t in chosen}
            worst = min(rises, key=lambda t: rises[t] - entry_dchi2(t))
            if rises[worst] < entry_dchi2(worst):
                chosen.remove(worst)
                changed = True
        if not changed:
            break
    if not chosen and not fixed:  # nothing is significant: keep the largest term
        chosen = [max((t for t in BASE_TERMS if t in st.terms),
                      key=lambda t: chi2_of([]) - chi2_of([t]))]
    current = fit_of(chosen)[1]
    now = chi2_of(chosen)
    change = {t: (chi2_of([c for c in chosen if c != t]) - now if t in chosen
                  else now - chi2_of([*chosen, t])) for t in BASE_TERMS if t in st.terms}
    return current, _fit_gls(current, pts)[0], change


# ------------------------------------------------------------------------ cross-validation
CV_MARKOV_SPAN: tuple[float, float] = (1e-3, 1.0 / 30.0)
"""Correlation times (fractions of the record) tried for a long-tau Gauss-Markov term."""


def _long_markov(st: Structure, pts: Points) -> Structure | None:
    """``st`` plus a Gauss-Markov term with tau_c in :data:`CV_MARKOV_SPAN` x the record.

    The bias of a real sensor wanders with a finite memory (a Gauss-Markov "bias
    instability", as in INS practice): between the flicker floor and the record length
    its OADEV rises and bends, which flicker + random walk only follow loosely.
    """
    if "markov" in st.terms:
        return None
    span = pts.n_samples / pts.rate_hz
    best: tuple[float, Structure] | None = None
    for tc in np.geomspace(CV_MARKOV_SPAN[0] * span, CV_MARKOV_SPAN[1] * span, 12):
        cand = _with(st, "markov", float(tc))
        chi2 = _fit_structure(cand, pts, None, iterations=2).chi2
        if best is None or chi2 < best[0]:
            best = (chi2, cand)
    return None if best is None else best[1]


def _cv_error(st: Structure, halves: Sequence[Points]) -> float:
    """Two-fold prediction error of ``st``: amplitudes fitted on one half of the record,
    RMS over taus up to a tenth of the half of ln(OADEV_other / OADEV_predicted)."""
    errs = []
    for a, b in ((0, 1), (1, 0)):
        sol = _fit_structure(st, halves[a], None)
        pred = design(st, halves[b]) @ sol.theta
        keep = (halves[b].tau_s <= 0.1 * halves[b].n_samples / halves[b].rate_hz) & (pred > 0)
        if not keep.any():
            return math.inf
        errs.append(float(np.mean((0.5 * np.log(halves[b].avar[keep] / pred[keep])) ** 2)))
    return math.sqrt(float(np.mean(errs)))


def _cross_validate(st: Structure, sol: _Solution, arr: np.ndarray, pts: Points
                    ) -> tuple[Structure, _Solution]:
    """Model choice by prediction, for records the model does not fit (delta > 0).

    When the chi2 test says the model is only an approximation, significance tests on
    its terms say little about which approximation *generalises*. The candidates (the
    selected structure; it plus random walk; it plus a long-tau Gauss-Markov term) are
    scored by two-fold cross-validation within the record (:func:`_cv_error`: fit one
    half, predict the other half's OADEV) and the best kept (settings of the nonlinear
    terms from the whole record).
    """
    cands = [st]
    if "random_walk" not in st.terms:
        cands.append(replace(st, terms=(*st.terms, "random_walk")))
    gm = _long_markov(st, pts)
    if gm is not None:
        cands.append(gm)
    if len(cands) == 1:
        return st, sol
    half = arr.size // 2
    try:
        halves = [replace(avar_points(h, pts.rate_hz, None, "cv"), delta=pts.delta)
                  for h in (arr[:half], arr[half:2 * half])]
    except FitError:
        return st, sol
    scores = [_cv_error(c, halves) for c in cands]
    best = cands[int(np.argmin(scores))]
    if best is st:
        return st, sol
    return best, _fit_gls(best, pts)[0]


# ------------------------------------------------------------------------ intervals
def _se_at(x: np.ndarray, theta: np.ndarray, j: int, value: float, pts: Points,
           corr: np.ndarray, free: Sequence[np.ndarray] = ()) -> float:
    """Standard error of theta_j with the covariance evaluated where theta_j = value.

    ``free``: per nonlinear setting estimated alongside, the matrix D with d(model
    AVAR)/d(ln setting) = D theta (:func:`_setting_derivatives`), taken at the theta the
    covariance is evaluated at; those columns enter the Fisher information as nuisance
    parameters, so the standard error is the one with those settings free (the
    Gauss-Newton covariance of separable least squares, Golub & Pereyra 2003), not the
    one at their estimates.
    """
    t = theta.copy()
    t[j] = max(value, 0.0)
    mod = np.maximum(x @ t, 1e-3 * pts.avar)
    v = 2.0 * mod**2 / pts.edf
    sigma = corr * np.sqrt(np.outer(v, v)) + np.diag((pts.delta * mod) ** 2)
    chol = np.linalg.cholesky(sigma)
    xw = np.linalg.solve(chol, np.column_stack([x, *(d @ t for d in free)]))
    scale = np.linalg.norm(xw, axis=0)
    scale[scale == 0] = 1.0
    cov = np.linalg.pinv((xw / scale).T @ (xw / scale), rcond=1e-12) / np.outer(scale, scale)
    return math.sqrt(max(cov[j, j], 0.0))


def _endpoint_ci(x: np.ndarray, theta: np.ndarray, j: int, pts: Points,
                 corr: np.ndarray, free: Sequence[np.ndarray] = ()) -> tuple[float, float]:
    """95 % interval of amplitude j: theta_j -/+ 1.96 se, se taken *at each endpoint*.

    The variance of an AVAR point is proportional to the model AVAR squared, so a Wald
    interval with the variance at the estimate is too narrow above a low estimate and too
    wide below a high one (the chi-squared skew of small-EDF points); evaluating the
    standard error at the endpoint (three fixed-point steps, a score-type interval) fixes
    that. Mapped to the amplitude by the square root, clipped at 0. ``free``: as in
    :func:`_se_at`.
    """
    t0 = float(theta[j])
    se0 = _se_at(x, theta, j, t0, pts, corr, free)
    hi, lo = t0 + Z95 * se0, t0 - Z95 * se0
    for _ in range(3):
        hi = t0 + Z95 * _se_at(x, theta, j, hi, pts, corr, free)
        lo = t0 - Z95 * _se_at(x, theta, j, max(lo, 0.0), pts, corr, free)
    return math.sqrt(max(lo, 0.0)), math.sqrt(max(hi, 0.0))


SETTING_STEP: float = 1e-3
"""Step in ln(setting) of the central differences of :func:`_setting_derivatives`."""


def _setting_derivatives(st: Structure, pts: Points) -> list[np.ndarray]:
    """Per nonlinear setting of ``st`` (filter bandwidth, Markov tau_c, sine frequency,
    resonance width) the matrix D with d(model AVAR)/d(ln setting) = D theta at the
    points (the model is linear in theta), by central differences of
    :data:`SETTING_STEP`."""
    out = []
    for kind in _extensions_in(st):
        v = float(getattr(st, _SETTING[kind]))
        up = _with(st, kind, v * math.exp(SETTING_STEP), st.filter_order)
        down = _with(st, kind, v * math.exp(-SETTING_STEP), st.filter_order)
        out.append((design(up, pts) - design(down, pts)) / (2 * SETTING_STEP))
    return out


MARKOV_MIN_SAMPLES = 2.0
"""A Gauss-Markov term's tau_c must be at least this many sample periods to count as a
bias process: a shorter one is white noise through a first-order low-pass (the two are
the same process), the output filter's shape at the shortest taus, not a correlated bias.
An outside reviewer's ADIS16405 gz (first hour of replicate 1, 100 Hz) kept sigma 0.184
dps at tau_c 0.0118 s (1.2 samples) beside quantization and an output white term (their
amplitudes correlated at -0.99 and -1.00) and no white term; the second hour, whose
short-tau Allan curve agrees within 4 %, fits white + flicker."""
DEGENERATE_PROFILE = 0.01
"""A setting's profile interval narrower than this (relative) is degenerate: the whole
74.5 h CATS record (non-stationary) gave tau_c 1.991 s [1.991, 1.991] and a bandwidth
0.03392 Hz [0.03392, 0.03392], both kept as identified; the term is then dropped."""


def _profile(st: Structure, kind: str, pts: Points, sigma: np.ndarray,
             chi2_min: float) -> tuple[tuple[float, float], list[Structure]]:
    """Profile 95 % interval of one nonlinear setting: chi-squared rise <= 3.84.

    The linear amplitudes are refitted (fixed covariance) along the profile; the bound is
    found by doubling steps in log space, then Brent's method. Returns the interval and
    the structures at its two ends (for the amplitudes' projected intervals).
    """
    from scipy.optimize import brentq

    v0 = float(getattr(st, _SETTING[kind]))
    upper = math.log(0.49 * pts.rate_hz) if kind != "markov" else math.log(
        pts.n_samples / pts.rate_hz)
    # a filter slower than 1/1000 of the rate is no longer "the shortest taus" (and its
    # impulse response gets very long): the profile stops there
    lower = math.log(1e-3 * pts.rate_hz) if kind == "filter" else -math.inf
    if kind == "resonance":  # the width: within the range searched
        lower, upper = (math.log(v) for v in _resonance_width_range(pts))

    def at(lv: float) -> Structure:
        return _with(st, kind, float(math.exp(lv)), st.filter_order)

    def rise(lv: float) -> float:
        return _chi2_fixed_sigma(at(lv), pts, sigma)[0] - chi2_min - 3.841

    ends: list[float] = []
    lv0 = math.log(v0)
    for direction in (-1.0, 1.0):
        step, prev = 1e-3, lv0
        end = None
        while step < 8.0:
            lv = lv0 + direction * step
            if direction > 0 and lv >= upper:
                end = upper
                break
            if direction < 0 and lv <= lower:
                end = lower
                break
            if rise(lv) > 0:
                end = brentq(rise, min(prev, lv), max(prev, lv), xtol=1e-4)
                break
            prev, step = lv, step * 2.0
        ends.append(lv0 + direction * 8.0 if end is None else end)
    lo, hi = sorted(ends)
    return (math.exp(lo), math.exp(hi)), [at(lo), at(hi)]


def _settings_free_intervals(st: Structure, sol: _Solution, pts: Points
                             ) -> dict[str, tuple[float, float]]:
    """95 % intervals of the amplitudes with the nonlinear settings free (nuisance
    parameters, :func:`_se_at`), for the terms of a structure that has any; empty
    otherwise.

    The intervals of :func:`_intervals` hold at the fitted settings. Where a term shares
    its taus with a setting, they are far too narrow: quantization 6e-4 dps s at the
    input of an order-2 8 Hz filter (1 h at 104 Hz) was reported as 5.80e-4 [5.77e-4,
    5.83e-4] with the bandwidth at 8.12 [8.00, 8.25] Hz, the truth outside on 3 of 4
    seeds. They are what the selection judges (a term the data need is not dropped
    because a poorly fixed bandwidth could take it over); these are the ones reported.
    """
    if not _extensions_in(st):
        return {}
    corr = _correlation(st, sol, pts)
    x = design(st, pts)
    free = _setting_derivatives(st, pts)
    ci: dict[str, tuple[float, float]] = {}
    for j, term in enumerate(st.terms):
        lo_a, hi_a = _endpoint_ci(x, sol.theta, j, pts, corr, free)
        ci[AMPLITUDE_KEY[term]] = (lo_a**2, hi_a**2) if term in HEIGHT_TERMS else (lo_a, hi_a)
    return ci


def _settings_named(st: Structure) -> str:
    """The nonlinear settings of ``st`` in words ("filter bandwidth and Markov tau_c")."""
    names = {"markov": "Markov tau_c", "sine": "sine frequency", "filter": "filter bandwidth",
             "resonance": "resonance width"}
    words = [names[k] for k in _extensions_in(st)]
    return " and ".join(words) if len(words) < 3 else ", ".join(words[:-1]) + " and " + words[-1]


# ------------------------------------------------------------------------ selection
_SETTING = {"markov": "tau_c_s", "sine": "f0_hz", "filter": "bandwidth_hz",
            "resonance": "res_width_hz"}
_SETTING_KEY = {"markov": "markov_tau", "sine": "sine_freq", "filter": "bandwidth_hz",
                "resonance": "resonance_width_hz"}
_OWN_AMPLITUDE = {"markov": "markov", "sine": "sine", "filter": "output_white",
                  "resonance": "resonance"}
SINE_BAND: float = 1.25
"""The spectral line is looked for within this factor of the fitted sine frequency
(intersected with its profile interval)."""
SINE_LINE_SHARE: float = 0.5
"""The line must carry at least this fraction of the fitted sine's amplitude (a quarter
of its power): a significant but weak line under a broad bump the Allan variance took
for a sine does not back it."""
EDGE_MARGIN: float = 0.1
"""A setting within this relative distance of its search range's end is pinned there,
not estimated."""


def _filter_pinned(st: Structure, pts: Points) -> bool:
    """Whether the structure's output filter sits at the bandwidth search's floor (within
    :data:`EDGE_MARGIN`): an optimum on the search's edge, not one the data fix."""
    return st.bandwidth_hz <= pts.filter_floor_hz * (1 + EDGE_MARGIN)


VERDICT_ORDER: tuple[str, ...] = ("markov", "sine", "resonance", "filter")
"""Order in which extensions are judged and, when several fail, the one excluded first:
a Markov term with tau_c below the shortest tau competes with the output filter and can
pin it at the search's edge; without it the filter is searched again."""


def _extensions_in(st: Structure) -> list[str]:
    return [k for k in VERDICT_ORDER if getattr(st, _SETTING[k]) > 0]


def _without(st: Structure, term: str) -> Structure:
    """``st`` without one term (an extension takes its setting with it)."""
    if term == "filter":
        # without the filter, white noise after it is white noise
        terms = tuple("white" if t == "output_white" else t for t in st.terms)
        return replace(st, terms=tuple(dict.fromkeys(terms)), bandwidth_hz=0.0,
                       filter_order=1)
    return replace(st, terms=tuple(t for t in st.terms if t != term),
                   tau_c_s=0.0 if term == "markov" else st.tau_c_s,
                   f0_hz=0.0 if term == "sine" else st.f0_hz,
                   res_width_hz=0.0 if term == "resonance" else st.res_width_hz)


def _finite(x: float) -> float | None:
    """``x``, or None (JSON null) when it is NaN or infinite (no interval)."""
    return float(x) if math.isfinite(x) else None


def _resonance_edge(st: Structure, pts: Points) -> str:
    """``lowest`` or ``highest`` when the resonance's width is at that end of the range
    searched (the Allan variance then fixes the band's power, not the peak's height and
    width), else ``""``."""
    w_lo, w_hi = _resonance_width_range(pts)
    return ("lowest" if st.res_width_hz <= w_lo * (1 + EDGE_MARGIN) else
            "highest" if st.res_width_hz >= w_hi / (1 + EDGE_MARGIN) else "")


def _intervals(st: Structure, sol: _Solution, pts: Points) -> dict[str, tuple[float, float]]:
    """95 % intervals of the fitted structure (module docstring, step 4).

    Amplitudes: score-type intervals (:func:`_endpoint_ci`) at the fitted nonlinear
    settings; the settings: profile intervals (:func:`_profile`); an extension's own
    amplitude (Markov sigma, sine amplitude, output_white) the union of its intervals at
    its setting's profile ends (projection; without it the sine amplitude covered 70 %
    of 10 seeds). The base terms are not projected: over a poorly determined bandwidth
    the union reached 0 for every term sharing the band, and a flicker the data need
    (chi2 drop 4e3) was reported with an interval including 0.
    """
    ci: dict[str, tuple[float, float]] = {}
    corr = _correlation(st, sol, pts)
    x = design(st, pts)
    for j, term in enumerate(st.terms):
        lo_a, hi_a = _endpoint_ci(x, sol.theta, j, pts, corr)
        # _endpoint_ci maps by the square root; a height is the coefficient itself
        ci[AMPLITUDE_KEY[term]] = (lo_a**2, hi_a**2) if term in HEIGHT_TERMS else (lo_a, hi_a)
    for kind in _extensions_in(st):
        ci[_SETTING_KEY[kind]], ends = _profile(st, kind, pts, sol.sigma, sol.chi2)
        own = _OWN_AMPLITUDE[kind]
        for end in ends:  # the extension's own amplitude: union over its profile ends
            _, s_end = _chi2_fixed_sigma(end, pts, sol.sigma)
            if own in end.terms and AMPLITUDE_KEY[own] in ci:
                j = end.terms.index(own)
                se = math.sqrt(max(float(s_end.cov_theta[j, j]), 0.0))
                lo = key_value(own, s_end.theta[j] - Z95 * se)
                hi = key_value(own, s_end.theta[j] + Z95 * se)
                old = ci[AMPLITUDE_KEY[own]]
                ci[AMPLITUDE_KEY[own]] = (min(old[0], lo), max(old[1], hi))
    return ci


def _extension_verdict(kind: str, st: Structure, sol: _Solution,
                       ci: dict[str, tuple[float, float]], pts: Points, arr: np.ndarray,
                       drop: float, amplitude: float) -> tuple[bool, str, float | None]:
    """Is extension ``kind`` of ``st`` backed by the data? (kept, reason in plain words,
    for a sine the frequency of the spectral line found, else None).

    Markov: tau_c's profile interval must lie within the AVAR points' tau range (else the
    data do not say where the correlation time is: a slope change of white/flicker/random
    walk in disguise). Filter: removing it from the model at hand (its ``output_white``
    becoming white) must raise chi2 (covariance of ``sol``) by more than
    :data:`EXTENSION_DCHI2`, and the estimate must not sit at the lowest bandwidth
    searched (:attr:`Points.filter_floor_hz`: then the optimum is the search's edge).
    Its profile interval is reported, not used: at 0.49 x the rate a bilinear
    Butterworth still shapes the band near Nyquist, so an interval reaching there does
    not mean "no filter". Sine: a spectral line must back it
    (:func:`imubench.noisefit.spectral_line.line_test`) and carry at least
    :data:`SINE_LINE_SHARE` of the fitted amplitude (``amplitude``, unit); without a line,
    a narrowband peak there (:func:`~imubench.noisefit.spectral_line.peak_test`) is named
    in the reason as a resonance (the resonance term's). Resonance: kept (it was tried
    only at a narrowband peak, and chosen by its chi2 drop); the reason names the peak
    and the width's profile interval.
    """
    from imubench.noisefit.spectral_line import line_test, peak_test

    value = float(getattr(st, _SETTING[kind]))
    lo, hi = ci[_SETTING_KEY[kind]]
    head = (f"chi2 drop {drop:.1f} > {EXTENSION_DCHI2:g}" if math.isfinite(drop) else
            "added by the two-fold cross-validation (the model does not fit: delta > 0)")
    if kind == "markov":
        t0, t1 = float(pts.tau_s[0]), float(pts.tau_s[-1])
        where = f"tau_c {value:.3g} s, profile 95 % interval [{lo:.3g}, {hi:.3g}] s"
        if hi / lo - 1.0 < DEGENERATE_PROFILE:
            return False, (f"dropped, tau_c not identified ({where}: a profile this narrow "
                           "is the optimiser's, not the data's)"), None
        if value < MARKOV_MIN_SAMPLES / pts.rate_hz:
            return False, (f"dropped, tau_c {value:.3g} s is within {MARKOV_MIN_SAMPLES:g} "
                           f"sample periods ({MARKOV_MIN_SAMPLES / pts.rate_hz:.3g} s): white "
                           "noise through a low-pass, not a correlated bias"), None
        if lo >= t0 and hi <= t1:
            return (True, f"kept, {head}, {where} within the data's taus "
                    f"[{t0:.3g}, {t1:.3g}] s", None)
        return False, (f"dropped, tau_c not identified ({where} not within the data's "
                       f"taus [{t0:.3g}, {t1:.3g}] s)"), None
    if kind == "filter":
        where = f"bandwidth {value:.3g} Hz, profile 95 % interval [{lo:.3g}, {hi:.3g}] Hz"
        if hi / lo - 1.0 < DEGENERATE_PROFILE:
            return False, (f"dropped, bandwidth not identified ({where}: a profile this "
                           "narrow is the optimiser's, not the data's)"), None
        pinned = _filter_pinned(st, pts)
        if pinned and not pts.filter_bounded:
            return False, (f"dropped, bandwidth not identified ({value:.3g} Hz is the lowest "
                           "searched: the optimum is the search's edge, not the data's)"), None
        gain = _chi2_fixed_sigma(_without(st, "filter"), pts, sol.sigma)[0] - sol.chi2
        if gain > EXTENSION_DCHI2 and pinned:
            return True, (f"kept, {head}, without it chi2 rises {gain:.1f}: the data need "
                          f"its shape but do not fix its bandwidth ({where}; the optimum is "
                          "the lowest searched)"), None
        if gain > EXTENSION_DCHI2:
            return True, f"kept, {head}, {where}, without it chi2 rises {gain:.1f}", None
        return False, (f"dropped, the final model without it fits as well (chi2 rise "
                       f"{gain:.1f} < {EXTENSION_DCHI2:g})"), None
    if kind == "resonance":  # its chi2 drop passed in _select_extensions; centre fixed
        where = "" if pts.peak is None else f" at {pts.peak.describe()} (peak test)"
        edge = _resonance_edge(st, pts)
        shape = (f": the width is the {edge} searched, so the Allan variance does not fix "
                 "it; the band's power is fitted, the peak's height and width are not "
                 "(read them from the spectrum)" if edge else "")
        interval = (f", profile 95 % interval [{lo:.3g}, {hi:.3g}] Hz"
                    if math.isfinite(lo) and math.isfinite(hi) else "")
        return True, (f"kept, {head}{where}; -3 dB width {value:.3g} Hz{interval}, centre "
                      f"{st.res_freq_hz:.4g} Hz from the peak test{shape}"), None
    band = (max(lo, value / SINE_BAND), min(hi, value * SINE_BAND))
    test = line_test(arr, pts.rate_hz, *band)
    if not test.present:
        peak = peak_test(arr, pts.rate_hz, value / SINE_BAND, value * SINE_BAND)
        if peak is not None and peak.present:
            return False, (f"dropped, {test.describe()}; but {peak.describe()}: a resonance "
                           "(the 'resonance' term's, not a sine's)"), None
        return False, f"dropped, {test.describe()}", None
    if test.amplitude < SINE_LINE_SHARE * amplitude:
        return False, (f"dropped, the {test.describe()} carries amplitude "
                       f"{test.amplitude:.3g}, less than {SINE_LINE_SHARE:g} x the "
                       f"{amplitude:.3g} fitted"), None
    # the periodogram locates the line to a bin; the Allan variance's optimum is finer
    # when it lies in the line's main lobe, and only roughly placed when it does not
    moved = test.freq_hz if abs(test.freq_hz - value) > 2 * test.resolution_hz else None
    return True, f"kept, {head}, {test.describe()}", moved


def _not_chosen(kind: str, drop: float, pts: Points) -> str:
    """The reason of an extension the subset selection did not choose."""
    if kind == "resonance" and pts.peak is None:
        return ("dropped, no narrowband peak in the spectrum (none significant, 2x the "
                "continuum and wider than a line)")
    where = f" (tried at {pts.peak.describe()})" if kind == "resonance" and pts.peak else ""
    return f"dropped, chi2 drop {drop:.1f} < {EXTENSION_DCHI2:g} needed{where}"


def _validate(st: Structure, pts: Points, arr: np.ndarray, drops: dict[str, float],
              amplitudes: bool = True, reasons: dict[str, str] | None = None
              ) -> tuple[Structure, _Solution, dict[str, tuple[float, float]], dict[str, str]]:
    """Drop, one at a time, the terms the data do not back; the reason for every term.

    A term stays only when (1) extensions: it passed the chi2 criterion of
    :func:`_select_extensions` and :func:`_extension_verdict`; (2) every amplitude
    (extensions' included; ``output_white`` belongs to the filter) has a 95 % interval
    excluding 0 (at the fitted nonlinear settings, as reported). Extensions are judged
    first (they change the linear fit), then the
    linear term with the smallest z = theta / se among those whose interval includes 0;
    the structure is refitted after each drop. A sine backed by a line more than two
    bins from its fitted frequency is moved once to the line's periodogram frequency
    (the Allan variance can place a sine off its line: 3.28 Hz for a 3 Hz line).
    ``amplitudes=False`` judges the extensions only (before the base terms are chosen);
    ``reasons`` are those of an earlier call (kept for the terms already dropped).
    """
    reasons = {} if reasons is None else dict(reasons)
    for kind in EXTENSIONS:
        if kind not in _extensions_in(st) and kind not in reasons:
            reasons[kind] = _not_chosen(kind, drops.get(kind, 0.0), pts)
    line_moved = False
    while True:
        sol, _ = _fit_gls(st, pts)
        ci = _intervals(st, sol, pts)
        failed: str | None = None
        for kind in _extensions_in(st):
            amp = math.sqrt(max(sol.theta[st.terms.index("sine")], 0.0)) if kind == "sine" \
                else math.nan
            ok, why, line_hz = _extension_verdict(kind, st, sol, ci, pts, arr,
                                                  drops.get(kind, math.nan), amp)
            reasons[kind] = why
            if not ok:
                failed = kind
                break
            if line_hz is not None and not line_moved:
                # the periodogram locates a line to fs/L; the AVAR's bump only roughly
                st, line_moved = _with(st, "sine", line_hz), True
                failed = ""
                break
        if failed == "":
            continue
        if failed is None and amplitudes and len(st.terms) > 1:
            se = np.sqrt(np.maximum(np.diag(sol.cov_theta), 0.0))
            worst: tuple[float, str] | None = None
            for j, term in enumerate(st.terms):
                if term == "output_white" or ci[AMPLITUDE_KEY[term]][0] > 0:
                    continue
                z = sol.theta[j] / se[j] if se[j] > 0 else 0.0
                if worst is None or z < worst[0]:
                    worst = (float(z), term)
            if worst is not None:
                failed = worst[1]
                name = {"markov": "amplitude", "sine": "amplitude",
                        "resonance": "height"}.get(failed, "95 %")
                reasons[failed] = (f"dropped, {name} interval includes 0 "
                                   f"(upper limit {ci[AMPLITUDE_KEY[failed]][1]:.3g})")
        if failed is None:
            return st, sol, ci, reasons
        st = _without(st, failed)


def _first_to_exclude(failed: list[str], st: Structure, pts: Points,
                      filter_pinned: bool) -> str:
    """Which of the extensions that failed their verdict is excluded (or, a filter pinned
    at the search's floor, searched above it) first: the first in
    :data:`VERDICT_ORDER`, except a Markov term whose tau_c is within the data's taus
    beside a filter that failed pinned at the lowest bandwidth searched. A filter pinned
    there shapes the same taus as the Markov term and leaves its tau_c profile
    degenerate (Samsung S5 gx, first 2 h at 10 Hz: tau_c 0.404 s [0.404, 0.404] beside a
    filter at 0.2 Hz; the Markov term, chi2 drop 487, was excluded, then the filter, and
    the model kept flicker alone with a discrepancy floor of 0.89; with the filter
    searched above its floor first the model keeps the Markov term, tau_c 1.23 s [0.84,
    1.39], beside a random walk, discrepancy 0.235). ``filter_pinned``: the filter failed
    and sits at the lowest bandwidth searched, not yet known to be bounded from above only."""
    if failed[0] == "markov" and filter_pinned and st.tau_c_s >= float(pts.tau_s[0]):
        return "filter"
    return failed[0]


def _backed_extensions(pts: Points, arr: np.ndarray
                       ) -> tuple[Structure, Points, dict[str, float], dict[str, str]]:
    """The best subset of extensions (:func:`_select_extensions`) among those the data
    back (:func:`_extension_verdict`): the first extension that fails (in
    :data:`VERDICT_ORDER`) is excluded and the subsets without it searched and compared
    again, so that a failed filter does not leave a Markov
    term that the comparison had passed over unconsidered. Returns the structure (all
    base terms and the backed extensions), its points, the chi2 drops and the reasons
    of the extensions excluded."""
    banned: list[str] = []
    reasons: dict[str, str] = {}
    all_drops: dict[str, float] = {}
    while True:
        allowed = [k for k in EXTENSIONS if k not in banned]
        st, sel_pts, drops = _select_extensions(_base_structure(pts), pts, allowed)
        all_drops.update(drops)
        backed, _, _, why = _validate(st, sel_pts, arr, all_drops, amplitudes=False,
                                      reasons=reasons)
        failed = [k for k in _extensions_in(st) if k not in _extensions_in(backed)]
        if not failed:
            return backed, sel_pts, all_drops, reasons
        # one at a time: the others were judged with settings searched alongside it
        filter_pinned = ("filter" in failed and _filter_pinned(st, pts)
                         and not pts.filter_bounded)  # refused as "the lowest searched"
        first = _first_to_exclude(failed, st, pts, filter_pinned)
        floor = pts.filter_floor_hz * FILTER_FLOOR_STEP
        pinned = first == "filter" and filter_pinned
        if pinned and floor < FILTER_FLOOR_MAX * pts.rate_hz:
            # pinned at the search's edge: search above it (a local optimum, or a slow
            # "filter" standing in for a term that is not there)
            pts = replace(pts, filter_min_hz=floor)
            continue
        if pinned:
            # pinned at every floor: the bandwidth is bounded only from above (an order-1
            # filter over a white floor fits alike at any lower bandwidth); keep the filter
            # if the short taus need its shape (judged by _extension_verdict)
            pts = replace(pts, filter_bounded=True)
            continue
        # the reason of an exclusion only: a filter searched again above its floor is
        # judged again (its "lowest searched" refusal had outlived the new search)
        reasons[first] = why[first]
        banned.append(first)


def _base_structure(pts: Points, terms: tuple[str, ...] = BASE_TERMS) -> Structure:
    """``terms`` with the resonance's centre at the spectrum's peak (when there is one)."""
    return Structure(terms, res_freq_hz=0.0 if pts.peak is None else pts.peak.freq_hz)


# ------------------------------------------------------------------------ public
def fit_wls(y: np.ndarray, rate_hz: float, *, terms: str | Iterable[str] = "auto",
            channel: str = "gx", taus: Sequence[float] | None = None) -> ChannelFit:
    """GLS/WLS fit of the model terms to the OAVAR curve (module docstring)."""
    arr = check_series(y, rate_hz, channel)
    wanted = parse_terms(terms)
    pts = avar_points(arr, rate_hz, taus, channel)
    if wanted is None or "resonance" in wanted:
        pts = replace(pts, peak=find_peak(arr, rate_hz))
    if wanted is not None and "resonance" in wanted and pts.peak is None:
        raise FitError(f"fit {channel}: --terms asks for 'resonance', but this channel's "
                       "spectrum has no narrowband peak (none significant, at least 2x the "
                       "continuum and wider than a line); fit the channels with a peak "
                       "separately (--channels)")
    notes: list[str] = []
    if wanted is None:
        backed, pts, drops, reasons = _backed_extensions(pts, arr)
        for _ in range(len(EXTENSIONS) + 1):
            st, sol, changes = _stepwise(backed, pts)
            drops.update(changes)
            if pts.delta > 0:
                before = st.terms
                st, sol = _cross_validate(st, sol, arr, pts)
                for term in st.terms:
                    if term not in before:
                        drops[term] = math.nan  # chosen by cross-validation, not by chi2
            st, sol, ci, reasons = _validate(st, pts, arr, drops, reasons=reasons)
            lost = [k for k in _extensions_in(backed) if k not in _extensions_in(st)]
            if not lost:
                break
            # an extension failed once the base terms were chosen: choose them again
            # without it (they were chosen alongside it). The discrepancy floor stays the
            # reference's: re-estimated for the poorer structure it absorbed the misfit the
            # lost term leaves (ADIS16405 rep 3 ay: 0.037 -> 0.26), every short-tau point
            # lost its weight, and white, filter and sine fell out one after the other
            for k in lost:
                backed = _without(backed, k)
    else:
        st = _base_structure(pts, tuple(t for t in wanted if t in BASE_TERMS))
        kinds = [k for k in EXTENSIONS if k in wanted]
        st = _polish(_optimise(st, kinds, pts), kinds, pts)
        sol0 = _fit_structure(st, pts, None)
        pts = _with_model_edf(st, sol0, pts)
        sol0 = _fit_structure(st, pts, None)
        pts = replace(pts, delta=_estimate_delta(st, pts, _correlation(st, sol0, pts),
                                                 2 * len(kinds)))
        sol, _ = _fit_gls(st, pts)
        ci = _intervals(st, sol, pts)
        reasons = {t: "fitted as asked (terms list, no selection)" for t in wanted}
        drops = {}
    at_settings = dict(ci)  # what the selection judged; reported: with the settings free
    for key, (lo, hi) in _settings_free_intervals(st, sol, pts).items():
        ci[key] = (min(ci[key][0], lo), max(ci[key][1], hi))
    params = dict.fromkeys(PARAM_KEYS, 0.0)
    params["filter_order"] = 1
    present: list[str] = []
    for j, term in enumerate(st.terms):
        key = AMPLITUDE_KEY[term]
        params[key] = key_value(term, sol.theta[j])
        if sol.theta[j] > 0:
            present.append(key)
    if "markov_sigma" in present:
        params["markov_tau"] = st.tau_c_s
        present.append("markov_tau")
    if "sine_amplitude" in present:
        params["sine_freq"] = st.f0_hz
        present.append("sine_freq")
    if "resonance_height" in present:
        params["resonance_freq_hz"] = st.res_freq_hz
        params["resonance_width_hz"] = st.res_width_hz
        present += ["resonance_freq_hz", "resonance_width_hz"]
    if st.bandwidth_hz > 0:
        params["bandwidth_hz"] = st.bandwidth_hz
        params["filter_order"] = st.filter_order
        present.extend(["bandwidth_hz", "filter_order"])
    if "ramp" in present:  # AVAR sees R^2: the sign comes from the LS slope
        t = np.arange(arr.size) / rate_hz
        ok = np.isfinite(arr)
        slope = np.polyfit(t[ok], arr[ok], 1)[0]
        if slope < 0:
            params["ramp"] = -params["ramp"]
            lo, hi = ci["ramp"]
            ci["ramp"] = (-hi, -lo)
    # upper limits for the base terms judged absent: fitted with them included, weighted
    # by that model's own variances and correlation (weighted by the reduced model's, a
    # random walk's long-tau rise looked far more certain than it is: every one of 11
    # undetected K of 1e-4 beside flicker got an upper limit below 1e-4)
    absent = [t for t in BASE_TERMS if AMPLITUDE_KEY[t] not in present]
    if absent:
        withall = replace(st, terms=tuple(dict.fromkeys((*st.terms, *absent))))
        sol_all, _ = _fit_gls(withall, pts)
        se_all = np.sqrt(np.maximum(np.diag(sol_all.cov_theta), 0.0))
        for term in absent:
            j = withall.terms.index(term)
            ci[AMPLITUDE_KEY[term]] = (0.0, math.sqrt(max(sol_all.theta[j], 0.0)
                                                   + Z_PRESENT * se_all[j]))
    n2 = white_equivalent(params, rate_hz) ** 2
    if n2 > 0:  # delta method on the squared amplitudes (tau_c held at its estimate)
        g = white_equivalent_weights(st.terms, st.tau_c_s, st.res_freq_hz, st.res_width_hz,
                                     rate_hz)
        ci[WHITE_EQUIVALENT] = white_equivalent_interval(n2, float(g @ sol.cov_theta @ g))
    if wanted is None:
        for term in BASE_TERMS:
            lo, hi = ci[AMPLITUDE_KEY[term]]
            d = drops.get(term, math.nan)
            if AMPLITUDE_KEY[term] in present:
                how = (f"chi2 drop {d:.1f} > {entry_dchi2(term):g}" if math.isfinite(d) else
                       "added by the two-fold cross-validation (the model does not fit: "
                       "delta > 0)")
                if lo > 0:
                    reasons[term] = (f"kept, {how}, 95 % interval [{lo:.3g}, {hi:.3g}] "
                                     "excludes 0")
                elif not _extensions_in(st):  # the one term kept when none is significant
                    reasons[term] = f"kept, {how}, 95 % interval [{lo:.3g}, {hi:.3g}]"
                else:
                    clo, chi = at_settings[AMPLITUDE_KEY[term]]
                    reasons[term] = (f"kept, {how}; 95 % interval [{lo:.3g}, {hi:.3g}] with "
                                     f"the {_settings_named(st)} free, [{clo:.3g}, "
                                     f"{chi:.3g}] at the fitted {_settings_named(st)}")
            elif term in reasons:  # dropped by _validate: interval includes 0
                reasons[term] = (f"dropped, 95 % interval includes 0 (one-sided 95 % upper "
                                 f"limit {hi:.3g})")
            else:
                reasons[term] = (f"dropped, chi2 drop {d:.1f} < {entry_dchi2(term):g} needed "
                                 f"(one-sided 95 % upper limit {hi:.3g})")
    dof = int(pts.avar.size - len(st.terms) - 2 * sum(
        1 for v in (st.tau_c_s, st.f0_hz, st.bandwidth_hz, st.res_width_hz) if v > 0))
    bias = float(np.nanmean(arr))
    if pts.delta > 0:
        notes.append(f"model discrepancy floor delta = {pts.delta:.3g} (relative std added "
                     "to every AVAR point so that chi2 = dof)")
    notes.extend(entangled_terms(st.terms, sol.cov_theta))
    notes.extend(curve_misfit(pts.tau_s, pts.avar, design(st, pts) @ sol.theta, pts.edf,
                              pts.delta))
    notes.extend(broad_misfit(pts.delta))
    if "bandwidth_hz" in present:
        lo, hi = ci.get("bandwidth_hz", (math.nan, math.nan))
        if not (lo > 0 and hi / lo <= UNIDENTIFIED_RANGE):
            shaped = [t for t in ("white", "output_white", "quantization", "markov",
                                  "resonance")
                      if AMPLITUDE_KEY[t] in present]
            notes.append(f"the output filter's bandwidth is not identified (95 % interval "
                         f"[{lo:.3g}, {hi:.3g}] Hz): the intervals of "
                         f"{', '.join(shaped) or 'the filtered terms'} take its uncertainty "
                         f"in linearised about the fitted {st.bandwidth_hz:.3g} Hz only, and "
                         "a small change of the record can move them beyond (the "
                         "white-equivalent N is robust)")
    if "bandwidth_hz" in present and AMPLITUDE_KEY["quantization"] in present:
        notes.append(f"quantization is fitted through the output filter ({st.bandwidth_hz:.3g}"
                     " Hz): it is the angle quantization at the filter's input, not the IEEE "
                     "952 Q read off the curve (sqrt(3) Q / tau0 is not the measured ADEV at "
                     "tau0); a rate LSB rounded after the filter is white noise of "
                     "LSB / sqrt(12 rate)")
    if AMPLITUDE_KEY["resonance"] in present and _resonance_edge(st, pts):
        # a width at the search's edge: the height and width are not identified, so no
        # interval is stated for them (the ADIS16405 gz peak was printed as 0.1715 [0.137,
        # 0.173] dps^2/Hz, 1.6x the spectrum's, while the reason said "read them from the
        # spectrum"); the selection above used the conditional intervals
        for key in (AMPLITUDE_KEY["resonance"], _SETTING_KEY["resonance"]):
            ci[key] = (math.nan, math.nan)
    return ChannelFit(channel, float(rate_hz), "wls", params, ci, tuple(present), pts.tau_s,
                      pts.avar, pts.edf, bias, sol.chi2, dof, tuple(notes), reasons,
                      {k: float(v) for k, v in drops.items()})


UNIDENTIFIED_RANGE: float = 10.0
"""A nonlinear parameter whose 95 % interval spans more than this factor (or reaches 0)
is not identified, and the amplitude intervals computed at its estimate are conditional
on it: ADIS16405 gx, 1 h, bandwidth [0.0076, 24.8] Hz; one lost sample moved the
bandwidth from 22.6 to 19.2 Hz and the quantization term from 0.00067 [0.00048, 0.00082]
to 0.00139 dps*s."""
ENTANGLED_CORRELATION: float = 0.9
"""Two terms whose estimates (squared amplitudes) correlate beyond this are reported as
not separately identified: the data fix their sum, not their split."""


def entangled_terms(terms: Sequence[str], cov_theta: np.ndarray) -> list[str]:
    """A note for each pair of fitted terms whose estimates correlate by more than
    :data:`ENTANGLED_CORRELATION` in ``cov_theta`` (the squared amplitudes' covariance):
    e.g. white noise before and after the output filter, or a quantization term and the
    filter's shape, on the ADIS16405 gyros, whose split moved outside its own intervals
    between two hours of one record, and when one sample was lost, while their sum (N)
    stayed within 0.03 %."""
    sd = np.sqrt(np.maximum(np.diag(cov_theta), 0.0))
    notes = []
    for i in range(len(terms)):
        for j in range(i + 1, len(terms)):
            if sd[i] > 0 and sd[j] > 0:
                r = float(cov_theta[i, j] / (sd[i] * sd[j]))
                if abs(r) > ENTANGLED_CORRELATION:
                    notes.append(f"{terms[i]} and {terms[j]} are not separately identified "
                                 f"(their estimates correlate {r:+.2f}): the data fix their "
                                 "joint effect, not the split; their intervals are the "
                                 "model's, and a small change of the record can move the "
                                 "split beyond them (the white-equivalent N is robust)")
    return notes


def fit_channel(y: np.ndarray | Sequence[float], rate_hz: float, *,
                terms: str | Iterable[str] = "auto", method: str = "wls", channel: str = "gx",
                taus: Sequence[float] | None = None) -> ChannelFit:
    """Fit the model file's noise terms to one channel's rate samples.

    Args:
        y: rate samples (dps or g), NaN where samples were lost.
        rate_hz: sample rate (Hz).
        terms: "auto" (model selection) or a list / comma string of term names among
            white flicker random_walk ramp quantization markov sine filter resonance.
        method: "wls" (GLS on the OAVAR curve), "tangent" (datasheet practice) or
            "whittle" (spectral likelihood, :mod:`.whittle`) or "exact" (whittle, then
            flicker and random walk by the exact block-mean likelihood, :mod:`.exactfit`).
        channel: label for messages and the result (gx gy gz ax ay az).
        taus: tau values (s) for the AVAR points; default octave averaging factors.

    Raises:
        FitError: bad data, rate, terms or method (the message names which).
    """
    if method == "wls":
        return fit_wls(np.asarray(y, dtype=float), rate_hz, terms=terms, channel=channel,
                       taus=taus)
    if method == "tangent":
        from imubench.noisefit.tangent import fit_tangent

        return fit_tangent(np.asarray(y, dtype=float), rate_hz, channel=channel, taus=taus)
    if method == "whittle":
        from imubench.noisefit.whittle import fit_whittle

        return fit_whittle(np.asarray(y, dtype=float), rate_hz, terms=terms, channel=channel,
                           taus=taus)
    if method == "exact":
        from imubench.noisefit.exactfit import fit_exact

        return fit_exact(np.asarray(y, dtype=float), rate_hz, terms=terms, channel=channel,
                         taus=taus)
    raise FitError(f"fit {channel}: unknown method {method!r}; use one of "
                   + ", ".join(METHODS))


__all__ = [
    "BASE_TERMS",
    "EXTENSIONS",
    "METHODS",
    "PARAM_KEYS",
    "TERM_NAMES",
    "ChannelFit",
    "Points",
    "Structure",
    "avar_points",
    "averaging_factors",
    "check_series",
    "design",
    "fit_channel",
    "fit_wls",
    "parse_terms",
]
