"""Whittle (spectral) likelihood fit of the noise terms: ``fit_channel(..., method="whittle")``.

The Allan variance condenses a record into ~20 correlated numbers; the periodogram keeps
one nearly independent number per Fourier frequency, and the random walk's information
lives in the lowest few of them. This estimator maximises the Whittle likelihood of the
whole periodogram (Whittle 1953, Ark. Mat. 2, 423-434; Percival & Walden 1993, *Spectral
Analysis for Physical Applications*, sec. 6.6 and 7.5), in the debiased form of Sykulski
et al. (2019, Biometrika 106, 251-266) so that the likelihood is honest at the lowest
frequencies, where the terms of interest live.

**Increments.** Flicker and random walk are not stationary, their increments are; the fit
uses d_k = y_{k+1} - y_k (Velasco & Robinson 2000, JASA 95, 1229-1243, difference before a
tapered Whittle fit). A constant bias disappears. Each term's increment autocovariance is
the negative second difference of its generalized autocovariance G(k) from
:func:`imubench.noisefit.kernels.gacv_unit` (the same G the Allan fit's AVAR is built
from, so N, B, K, Q, sigma_M, tau_c mean exactly what the ``wls`` fit reports)::

    gamma_d(k) = -(G(k+1) - 2 G(k) + G(k-1)),  G(-1) = G(1).

Closed forms (unit amplitude, tau0 = 1/rate, two-sided PSD per unit normalised frequency
nu): white 2/tau0, -1/tau0 at lag 1 (PSD 4 sin^2(pi nu)/tau0); flicker 4/pi and
gamma(k) = gamma(k-1)(k - 3/2)/(k + 1/2) (PSD 2 sin(pi |nu|): the Kasdin-Walter 1/f
process, y-PSD B^2/(2 sin pi nu), AVAR floor (2 ln2/pi) B^2, IEEE 952 B); random walk of
interval means tau0 (2/3, 1/6) (PSD tau0 (1 - 2/3 sin^2 pi nu), an MA(1)); quantization
(6, -4, 1)/tau0^2 (PSD 16 sin^4(pi nu)/tau0^2); Gauss-Markov 2 g(k) - g(k-1) - g(k+1)
with g = phi^|k|. All exact for the sampled processes the model file describes.

**Periodogram.** d (gap samples zeroed) times a taper h, sum h^2 = 1: a Tukey (split
cosine) taper over :data:`TAPER_FRACTION` of the record, times cosine ramps of
:data:`GAP_RAMP_SAMPLES` at each side of every gap; I_k = |sum_t h_t d_t
e^{-2 pi i k t / M}|^2 at the Fourier frequencies nu_k = k/M, 0 < k < M/2. The taper is
needed: the white increments' PSD at Nyquist is ~1e7 times the random walk's near zero
frequency, and without a taper the record's edges leak ~30 times the random walk's level
into the lowest bins (Percival & Walden ch. 6).

**Debiased likelihood.** The expected tapered periodogram of a stationary series with
autocovariance gamma is exactly E I_k = sum_{|tau|<M} c(tau) gamma(tau) e^{-2 pi i k
tau/M}, c(tau) = sum_t h_t h_{t+tau} (Sykulski et al. 2019, eq. 5; with a gappy taper this
is their missing-data form). It is linear in the squared amplitudes theta, so each term's
E I is one FFT ("basis"). The negative log-likelihood is
``l(theta) = sum_k [log f_k + I_k / f_k]``, f = E I(theta), minimised over theta >= 0 by
Fisher scoring, i.e. iteratively reweighted non-negative least squares with weights 1/f^2
(the Gamma-GLM identity-link form of the Whittle likelihood). The output low-pass
multiplies the bases by |H(nu)|^2 (exact for the untapered spectrum; the taper's window is
~1 bin wide and |H|^2 changes over thousands of bins).

**Bands.** The lowest :data:`SINGLE_BINS` frequencies enter one by one; above, the
ordinates are averaged in bands of relative width :data:`BAND_RATIO` - 1 (about 1000
bands instead of 5e5 frequencies for 3 h at 100 Hz). A band mean of L ordinates is
treated as Gamma with the shape that matches its variance under the taper's correlation
of neighbouring ordinates (:func:`_band_shape`), so its term in -log L is
L_eff (log f + I/f): the Whittle likelihood for L = 1.

**Model selection** (``terms="auto"``), by likelihood ratio LR = 2 (l_without - l_with):
white, flicker, random walk, quantization start in; the output filter (with
``output_white``) and a Gauss-Markov term (tau_c in [2 tau0, T/30], as for ``wls``) enter
if their best setting gives LR > :data:`EXTENSION_LR`; then backward elimination drops
the linear term with the smallest LR while it is below :data:`TERM_LR` (a Gauss-Markov
amplitude: :data:`EXTENSION_LR`). ``reasons`` say per term why it was kept or dropped.
Ramp and sine are deterministic: the periodogram has no place for them (a ramp is the
increments' mean, dropped; a line is not a continuous spectrum), so ``whittle`` refuses
them in ``terms`` and does not look for them; use ``wls``.

**Intervals.** 95 % Wald intervals in the log of each parameter (squared amplitudes,
tau_c, bandwidth) from the observed information, the Hessian of l in log-parameters
(analytic in theta; finite differences for tau_c and the bandwidth); amplitudes are their
square roots. A base term judged absent gets (0, sqrt(theta + 1.645 se)) from a fit with
it included (one-sided 95 % upper limit; se from the expected information in theta).

**Gaps.** NaN samples are allowed: the increments touching them get taper weight 0 and the
taper ramps down over :data:`GAP_RAMP_SAMPLES` at each side, so the debiased E I stays
exact; no value is invented. Records with more than :data:`MAX_GAP_FRACTION` of their
increments missing are refused.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy.fft
from scipy.optimize import minimize_scalar, nnls
from scipy.signal.windows import tukey

from imubench.noisefit.errors import FitError
from imubench.noisefit.fit import (
    PARAM_KEYS,
    ChannelFit,
    Structure,
    avar_points,
    check_series,
    parse_terms,
)
from imubench.noisefit.kernels import AMPLITUDE_KEY, filter_gain2, gacv_unit
from imubench.noisefit.spectral_line import find_peak
from imubench.noisefit.units import (
    WHITE_EQUIVALENT,
    white_equivalent,
    white_equivalent_interval,
    white_equivalent_weights,
)

TAPER_FRACTION: float = 0.1
"""Fraction of the record under the Tukey taper's cosine ends (half at each end)."""
GAP_RAMP_SAMPLES: int = 256
"""Length (samples) of the cosine ramp on each side of a gap."""
SINGLE_BINS: int = 256
"""The lowest Fourier frequencies kept one by one (where the random walk lives)."""
BAND_RATIO: float = 1.01
"""Above them, frequencies are averaged in bands of this relative width: the terms' E I
varies by at most ~2 % across one, so the band's Gamma likelihood loses almost nothing."""
MAX_GAP_FRACTION: float = 0.5
"""Largest fraction of missing increments accepted."""
TERM_LR: float = 5.41
"""LR a linear term must reach to stay: its amplitude sits on the boundary (theta = 0) under
the null, so LR ~ 1/2 chi2_0 + 1/2 chi2_1 (Self & Liang 1987, JASA 82, 605-610); 5.41 is
the chi2_1 0.98 quantile, a 1 % false-term rate per term."""
EXTENSION_LR: float = 13.8
"""LR a searched extension (Gauss-Markov tau_c, filter bandwidth) must give: chi2_2 at
0.999, the same charge as ``wls`` for the look-elsewhere effect of the grid search."""
BASE: tuple[str, ...] = ("white", "flicker", "random_walk", "quantization")
UNSUPPORTED: tuple[str, ...] = ("ramp", "sine")
Z95: float = 1.959964
Z_UPPER: float = 1.644854
_FD_STEP: float = 0.02
"""Step in log tau_c / log bandwidth of the finite differences of the Hessian."""


@dataclass(frozen=True)
class Spectrum:
    """The tapered periodogram of a record's increments, in bands, and what E I needs."""

    pgram: np.ndarray
    """Band means of I_k (unit^2 per unit normalised frequency, two-sided)."""
    weight: np.ndarray
    """Effective number of independent ordinates per band (Gamma shape, see _band_shape)."""
    band_start: np.ndarray
    """Index (into nu) of each band's first frequency."""
    band_size: np.ndarray
    nu: np.ndarray
    """Every Fourier frequency k/M, k = 1..K (normalised)."""
    taper_acv: np.ndarray
    """c(tau), tau = 0..M-1."""
    n_increments: int
    rate_hz: float
    n_samples: int
    missing: int
    """Increments with taper weight 0 (touching a NaN sample)."""

    def band_mean(self, values: np.ndarray) -> np.ndarray:
        """Mean over each band of a per-frequency array."""
        return np.add.reduceat(values, self.band_start) / self.band_size


# ------------------------------------------------------------------------ periodogram
def _fast_length_below(n: int) -> int:
    """Largest 5-smooth length <= n (FFTs of it are fast; the few samples after it go)."""
    m = n
    while scipy.fft.next_fast_len(m, real=True) != m:
        m -= 1
    return m


def gap_taper(valid: np.ndarray, ramp: int = GAP_RAMP_SAMPLES) -> np.ndarray:
    """1 far from gaps, sin^2 ramps over ``ramp`` samples next to one, 0 inside it."""
    n = valid.size
    idx = np.arange(n)
    big = 4 * n + 4 * ramp
    last_bad = np.maximum.accumulate(np.where(valid, -big, idx))
    next_bad = np.minimum.accumulate(np.where(valid, big, idx)[::-1])[::-1]
    dist = np.minimum(idx - last_bad, next_bad - idx).astype(np.float64)
    w = np.sin(0.5 * np.pi * np.minimum(dist, ramp) / ramp) ** 2
    w[~valid] = 0.0
    return w


def spectrum(y: np.ndarray, rate_hz: float, channel: str = "gx") -> Spectrum:
    """Tapered periodogram of the increments of ``y`` (NaN = missing), module docstring."""
    d_full = np.diff(y)
    m = _fast_length_below(d_full.size)
    d = d_full[:m]
    valid = np.isfinite(d)
    missing = int(m - valid.sum())
    if missing > MAX_GAP_FRACTION * m:
        raise FitError(f"fit {channel}: {missing} of {m} increments touch missing samples "
                       f"(more than {MAX_GAP_FRACTION:.0%}); the whittle fit needs a "
                       "mostly continuous record")
    h = tukey(m, TAPER_FRACTION) * gap_taper(valid)
    h /= math.sqrt(float(np.sum(h * h)))
    x = np.where(valid, d, 0.0)
    x = np.where(valid, x - np.sum(h * h * x), 0.0)  # increments' mean (a ramp) out
    k_max = (m - 1) // 2
    if k_max < 8:
        raise FitError(f"fit {channel}: {m} increments are too few for a spectral fit")
    pgram = np.abs(scipy.fft.rfft(h * x))[1:k_max + 1] ** 2
    nfft = scipy.fft.next_fast_len(2 * m, real=True)
    c = scipy.fft.irfft(np.abs(scipy.fft.rfft(h, nfft)) ** 2, nfft)[:m]
    nu = np.arange(1, k_max + 1) / m
    start = band_starts(k_max)
    size = np.diff(np.append(start, k_max))
    means = np.add.reduceat(pgram, start) / size
    return Spectrum(means, _band_shape(size, h), start, size, nu, c, m, float(rate_hz),
                    int(y.size), missing)


def band_starts(k_max: int) -> np.ndarray:
    """First index of each band: :data:`SINGLE_BINS` single frequencies, then bands of
    relative width :data:`BAND_RATIO`."""
    n_geo = math.ceil(math.log(max(k_max / SINGLE_BINS, 1.0)) / math.log(BAND_RATIO))
    geo = np.rint(SINGLE_BINS * BAND_RATIO ** np.arange(n_geo + 1)).astype(np.int64)
    start = np.unique(np.concatenate([np.arange(min(SINGLE_BINS, k_max)), geo]))
    return start[start < k_max]


def _band_shape(size: np.ndarray, h: np.ndarray, max_lag: int = 64) -> np.ndarray:
    """Gamma shape of each band mean: L^2 / sum_{k,k' in band} rho(k - k').

    For Gaussian data the tapered ordinates have Cov(I_k, I_k') = f^2 rho(k - k') with
    rho(j) = |sum_t h_t^2 e^{-2 pi i j t/M}|^2 (Percival & Walden 1993, sec. 6.6 and
    eq. 7.2), rho(0) = 1: the mean of L of them has the variance of a Gamma of this shape
    (moment-matched), L for single frequencies, L / (M sum h^4) for wide bands.
    """
    rho = np.abs(scipy.fft.rfft(h * h))[: max_lag + 1] ** 2
    rho /= rho[0]
    out = np.empty(size.size)
    for s in np.unique(size):
        j = np.arange(1, min(int(s), max_lag + 1))
        out[size == s] = float(s) ** 2 / (s + 2.0 * np.sum((s - j) * rho[j]))
    return out


def increment_acv(term: str, n_lags: int, tau0_s: float, *, tau_c_s: float = 0.0
                  ) -> np.ndarray:
    """gamma_d(k), k = 0..n_lags-1, of a term's increments (unit amplitude; docstring)."""
    g = gacv_unit(term, n_lags, tau0_s, tau_c_s=tau_c_s)  # G(0..n_lags)
    g_prev = np.concatenate([[g[1]], g[:n_lags - 1]])  # G(k-1), G(-1) = G(1)
    return -(g[1:n_lags + 1] - 2.0 * g[:n_lags] + g_prev)


def expected_periodogram(acv: np.ndarray, sp: Spectrum) -> np.ndarray:
    """E I_k = sum_{|tau|<M} c(tau) gamma(tau) e^{-2 pi i k tau / M} (Sykulski et al. eq. 5)."""
    a = sp.taper_acv * acv
    a[0] *= 0.5
    return np.asarray(2.0 * scipy.fft.rfft(a).real[1:sp.nu.size + 1])


def term_basis(term: str, sp: Spectrum, *, tau_c_s: float = 0.0) -> np.ndarray:
    """E I of one term at unit amplitude (no filter)."""
    acv = increment_acv(term, sp.n_increments, 1.0 / sp.rate_hz, tau_c_s=tau_c_s)
    return expected_periodogram(acv, sp)


# ------------------------------------------------------------------------ model
class _Bases:
    """Unit-amplitude E I of every term for one spectrum (cached per nonlinear setting).

    Band means (what the likelihood uses). A filtered column is the band mean times the
    gain at the band's mean frequency: exact for the single frequencies, and second order
    in the band width above (< 1e-4 relative for a second-order Butterworth).
    """

    def __init__(self, sp: Spectrum) -> None:
        self.sp = sp
        self.nu_band = sp.band_mean(sp.nu)
        self._cols: dict[tuple[str, float], np.ndarray] = {}

    def gain(self, bandwidth_hz: float, order: int) -> np.ndarray:
        """|H|^2 of the output low-pass per band (1 without a filter)."""
        return filter_gain2(self.nu_band, bandwidth_hz, order, self.sp.rate_hz)

    def unfiltered(self, term: str, tau_c_s: float = 0.0) -> np.ndarray:
        """Band means of E I of ``term`` without the filter."""
        key = ("white" if term == "output_white" else term,
               tau_c_s if term == "markov" else 0.0)
        if key not in self._cols:
            self._cols[key] = self.sp.band_mean(term_basis(key[0], self.sp, tau_c_s=key[1]))
        return self._cols[key]

    def column(self, term: str, st: Structure) -> np.ndarray:
        """Band means of E I of ``term`` in ``st`` (filter gain on all but output_white)."""
        col = self.unfiltered(term, st.tau_c_s)
        if st.bandwidth_hz > 0 and term != "output_white":
            col = col * self.gain(st.bandwidth_hz, st.filter_order)
        return col

    def matrix(self, st: Structure) -> np.ndarray:
        return np.column_stack([self.column(t, st) for t in st.terms])


@dataclass
class _Fit:
    st: Structure
    theta: np.ndarray
    nll: float
    model: np.ndarray
    """Band means of E I at theta."""


def _nll(f: np.ndarray, sp: Spectrum) -> float:
    """-log L = sum_b L_b (log f_b + I_b / f_b) (Gamma bands; Whittle for L_b = 1)."""
    return float(np.sum(sp.weight * (np.log(f) + sp.pgram / f)))


def _smoothed(sp: Spectrum) -> np.ndarray:
    """Band means smoothed over 9 neighbouring bands: a positive start for the scoring."""
    kernel = np.ones(9) / 9.0
    padded = np.pad(sp.pgram, 4, mode="edge")
    return np.maximum(np.convolve(padded, kernel, mode="valid"), 1e-300)


def _wnnls(x: np.ndarray, target: np.ndarray, w: np.ndarray) -> np.ndarray:
    """min sum w^2 (x theta - target)^2, theta >= 0, via the p x p normal equations."""
    xw = x * w[:, None]
    a = xw.T @ xw
    b = xw.T @ (target * w)
    s = np.sqrt(np.diag(a))
    s[~(s > 0)] = 1.0
    a_s = a / np.outer(s, s) + 1e-12 * np.eye(s.size)
    chol = np.linalg.cholesky(a_s)
    t, _ = nnls(chol.T, np.linalg.solve(chol, b / s), maxiter=50 * s.size)
    return np.asarray(t / s)


def _fit_linear(st: Structure, bases: _Bases, max_iter: int = 500) -> _Fit:
    """Whittle fit of the squared amplitudes of ``st``, theta >= 0.

    Fisher scoring: the score is sum_b L_b X_b (I_b - f_b) / f_b^2, so each step is the
    non-negative least squares with weights L_b / f_b^2 (the Gamma GLM with identity
    link), halved while it does not lower -log L.
    """
    sp = bases.sp
    x = bases.matrix(st)
    sw = np.sqrt(sp.weight)
    theta = _wnnls(x, sp.pgram, sw / _smoothed(sp))
    floor = 1e-300
    f = np.maximum(x @ theta, floor)
    nll = _nll(f, sp)
    # weights 1/f: a candidate whose spectrum vanishes in some bands (f at the 1e-300
    # floor) overflowed the normal equations; 1e-9 of the data's median cannot matter
    # where the model is meaningful
    w_floor = 1e-9 * float(np.median(sp.pgram))
    for _ in range(max_iter):
        new = _wnnls(x, sp.pgram, sw / np.maximum(f, w_floor))
        step = 1.0
        while True:
            cand = theta + step * (new - theta)
            f_c = np.maximum(x @ cand, floor)
            nll_c = _nll(f_c, sp)
            if nll_c <= nll or step < 1e-3:
                break
            step *= 0.5
        if not nll_c <= nll:
            break
        done = nll - nll_c < 1e-8
        theta, f, nll = cand, f_c, nll_c
        if done:
            break
    return _Fit(st, theta, nll, f)


# ------------------------------------------------------------------------ extensions
def _with_markov(st: Structure, tau_c_s: float) -> Structure:
    terms = st.terms if "markov" in st.terms else (*st.terms, "markov")
    return replace(st, terms=terms, tau_c_s=tau_c_s)


def _with_filter(st: Structure, bandwidth_hz: float, order: int) -> Structure:
    terms = st.terms if "output_white" in st.terms else (*st.terms, "output_white")
    return replace(st, terms=terms, bandwidth_hz=bandwidth_hz, filter_order=order)


def _search_markov(st: Structure, bases: _Bases) -> _Fit:
    """Best Gauss-Markov tau_c in [2 tau0, T/30] (log grid of 20, then Brent in log)."""
    sp = bases.sp
    tau0 = 1.0 / sp.rate_hz
    grid = np.geomspace(2.0 * tau0, sp.n_samples * tau0 / 30.0, 20)
    fits = [_fit_linear(_with_markov(st, float(tc)), bases) for tc in grid]
    i = int(np.argmin([f.nll for f in fits]))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    r = minimize_scalar(lambda lt: _fit_linear(_with_markov(st, float(np.exp(lt))),
                                               bases).nll,
                        bounds=(math.log(lo), math.log(hi)), method="bounded",
                        options={"xatol": 1e-2})
    best = _fit_linear(_with_markov(st, float(np.exp(r.x))), bases)
    return best if best.nll < fits[i].nll else fits[i]


def _search_filter(st: Structure, bases: _Bases) -> _Fit:
    """Best output low-pass (order 1 or 2, bandwidth 0.02-0.45 x rate; grid then Brent)."""
    rate = bases.sp.rate_hz
    grid = np.geomspace(0.02 * rate, 0.45 * rate, 14)
    best: _Fit | None = None
    for order in (1, 2):
        fits = [_fit_linear(_with_filter(st, float(bw), order), bases) for bw in grid]
        i = int(np.argmin([f.nll for f in fits]))
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
        r = minimize_scalar(
            lambda lb, order=order: _fit_linear(
                _with_filter(st, float(np.exp(lb)), order), bases).nll,
            bounds=(math.log(lo), math.log(hi)), method="bounded", options={"xatol": 1e-2})
        cand = _fit_linear(_with_filter(st, float(np.exp(r.x)), order), bases)
        cand = cand if cand.nll < fits[i].nll else fits[i]
        if best is None or cand.nll < best.nll:
            best = cand
    assert best is not None
    return best


def _drop(st: Structure, term: str) -> Structure:
    terms = tuple(t for t in st.terms if t != term)
    return replace(st, terms=terms, tau_c_s=0.0 if term == "markov" else st.tau_c_s)


def _select(bases: _Bases, reasons: dict[str, str]) -> _Fit:
    """Likelihood-ratio model selection (module docstring); ``reasons`` gets, per term
    name, why it was kept or dropped (as :attr:`ChannelFit.reasons`)."""
    current = _fit_linear(Structure(BASE), bases)
    for kind in ("filter", "markov"):
        cand = (_search_filter if kind == "filter" else _search_markov)(current.st, bases)
        lr = 2.0 * (current.nll - cand.nll)
        setting = (f"bandwidth {cand.st.bandwidth_hz:.4g} Hz, order {cand.st.filter_order}"
                   if kind == "filter" else f"tau_c {cand.st.tau_c_s:.4g} s")
        if lr > EXTENSION_LR:
            reasons[kind] = f"kept, LR {lr:.1f} > {EXTENSION_LR}, best {setting}"
            current = cand
        else:
            reasons[kind] = f"dropped, LR {lr:.1f} <= {EXTENSION_LR} (best {setting})"
    while len(current.st.terms) > 1:
        lrs = {}
        reduced = {}
        for term in current.st.terms:
            red = _fit_linear(_drop(current.st, term), bases)
            reduced[term] = red
            lrs[term] = max(2.0 * (red.nll - current.nll), 0.0)
        need = {t: EXTENSION_LR if t == "markov" else TERM_LR for t in lrs}
        weakest = min(lrs, key=lambda t: lrs[t] - need[t])
        if lrs[weakest] >= need[weakest]:
            for t in current.st.terms:
                if t not in ("markov", "output_white"):  # their reason is the search's
                    reasons[t] = f"kept, LR {lrs[t]:.1f} >= {need[t]}"
            break
        reasons[weakest] = f"dropped, LR {lrs[weakest]:.2f} < {need[weakest]}"
        current = reduced[weakest]
    return current


# ------------------------------------------------------------------------ intervals
def _observed_information(fit: _Fit, bases: _Bases) -> tuple[list[str], np.ndarray,
                                                               np.ndarray]:
    """Hessian of -log L in log-parameters (names, observed H, expected information F).

    With f_a = df/dphi_a and f_ab the second derivatives (band means),
    H_ab = sum_b L_b [f_a f_b (2 I/f^3 - 1/f^2) + f_ab (1/f - I/f^2)],
    F_ab = sum_b L_b f_a f_b / f^2. phi: log theta_j of the terms with theta_j > 0, then
    log tau_c and log bandwidth (their derivatives by central differences).
    """
    st, sp, f = fit.st, bases.sp, fit.model
    lin = [j for j, _ in enumerate(st.terms) if fit.theta[j] > 0]
    names = [st.terms[j] for j in lin]
    d1 = [fit.theta[j] * bases.column(st.terms[j], st) for j in lin]
    d2: dict[tuple[int, int], np.ndarray] = {(a, a): d1[a] for a in range(len(lin))}
    h = _FD_STEP
    gain = bases.gain(st.bandwidth_hz, st.filter_order)
    d_markov: np.ndarray | None = None
    if "markov" in names:
        a_m = names.index("markov")
        th = fit.theta[st.terms.index("markov")]
        tc = st.tau_c_s
        b_p = bases.unfiltered("markov", tc * math.exp(h))
        b_m = bases.unfiltered("markov", tc * math.exp(-h))
        b_0 = bases.unfiltered("markov", tc)
        d_markov = th * (b_p - b_m) / (2 * h)
        i = len(names)
        names.append("markov_tau")
        d1.append(gain * d_markov)
        d2[(i, i)] = gain * th * (b_p - 2 * b_0 + b_m) / h**2
        d2[(a_m, i)] = d1[i]
    if st.bandwidth_hz > 0:
        bw, order = st.bandwidth_hz, st.filter_order
        g_p, g_m = bases.gain(bw * math.exp(h), order), bases.gain(bw * math.exp(-h), order)
        dg = (g_p - g_m) / (2 * h)
        d2g = (g_p - 2 * gain + g_m) / h**2
        inner = np.zeros_like(f)
        i = len(names)
        for a, j in enumerate(lin):
            term = st.terms[j]
            if term == "output_white":
                continue
            part = fit.theta[j] * bases.unfiltered(term, st.tau_c_s)
            inner += part
            d2[(a, i)] = dg * part
        names.append("bandwidth_hz")
        d1.append(dg * inner)
        d2[(i, i)] = d2g * inner
        if d_markov is not None:
            d2[(names.index("markov_tau"), i)] = dg * d_markov
    u = np.column_stack(d1) / f[:, None]
    r = sp.pgram / f
    w = sp.weight
    fisher = (u * w[:, None]).T @ u
    obs = (u * (w * (2.0 * r - 1.0))[:, None]).T @ u
    for (a, b), v in d2.items():
        s = float(np.sum(w * v / f * (1.0 - r)))
        obs[a, b] += s
        if a != b:
            obs[b, a] += s
    return names, obs, fisher


def _upper_limits(fit: _Fit, bases: _Bases, absent: Sequence[str]) -> dict[str, float]:
    """One-sided 95 % upper limit of each absent base term's amplitude (docstring)."""
    st = replace(fit.st, terms=(*fit.st.terms, *absent))
    full = _fit_linear(st, bases)
    x = bases.matrix(st) / full.model[:, None]
    cov = np.linalg.pinv((x * bases.sp.weight[:, None]).T @ x, rcond=1e-12)
    out = {}
    for term in absent:
        j = st.terms.index(term)
        se = math.sqrt(max(float(cov[j, j]), 0.0))
        out[term] = math.sqrt(max(float(full.theta[j]) + Z_UPPER * se, 0.0))
    return out


# ------------------------------------------------------------------------ public
def _explicit(wanted: Sequence[str], bases: _Bases, channel: str) -> _Fit:
    bad = [t for t in wanted if t in UNSUPPORTED]
    if bad:
        raise FitError(f"fit {channel}: terms {bad} are deterministic and not fitted by the "
                       "whittle method (the periodogram has no place for a ramp or a line); "
                       "use --method wls for them")
    if "resonance" in wanted:
        raise FitError("--method whittle/exact: the resonance term is fitted by --method wls "
                       "only (on the Allan variance, at the spectrum's narrowband peak; the "
                       "spectral likelihood here models a smooth spectrum)")
    st = Structure(tuple(t for t in wanted if t in BASE))
    if not st.terms and "filter" not in wanted and "markov" not in wanted:
        raise FitError(f"fit {channel}: no term to fit among {list(wanted)}")
    if "filter" in wanted:
        st = _search_filter(st, bases).st
    if "markov" in wanted:
        st = _search_markov(st, bases).st
    return _fit_linear(st, bases)


def fit_whittle(y: np.ndarray, rate_hz: float, *, terms: str | Iterable[str] = "auto",
                channel: str = "gx", taus: Sequence[float] | None = None) -> ChannelFit:
    """Debiased Whittle fit of the noise terms to the periodogram (module docstring).

    ``taus`` only chooses the Allan points returned for plots; the fit does not use them.
    """
    arr = check_series(y, rate_hz, channel)
    wanted = parse_terms(terms)
    sp = spectrum(arr, rate_hz, channel)
    bases = _Bases(sp)
    notes: list[str] = []
    if sp.missing:
        notes.append(f"{sp.missing} of {sp.n_increments} increments touch missing samples: "
                     f"taper weight 0 there, {GAP_RAMP_SAMPLES}-sample cosine ramps around "
                     "each gap")
    reasons: dict[str, str] = {}
    if wanted is None:
        fit = _select(bases, reasons)
        peak = find_peak(arr, rate_hz)
        if peak is not None:
            reasons["resonance"] = (
                f"not fitted: {peak.describe()} is in the spectrum, and this method has no "
                "resonance term, so the terms fitted here absorb it (use --method wls)")
            notes.append(f"{peak.describe()} is not modelled by --method whittle/exact: "
                         "the white-equivalent density and the short-tau terms include it; "
                         "--method wls fits it as a resonance")
    else:
        fit = _explicit(wanted, bases, channel)
        reasons = {t: "fitted as asked (terms list, no selection)" for t in wanted}
    st = fit.st
    names, obs, fisher = _observed_information(fit, bases)
    try:
        np.linalg.cholesky(obs)
        cov = np.linalg.inv(obs)
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(fisher, rcond=1e-12)
        notes.append("observed information not positive definite: intervals from the "
                     "expected information")
    se = dict(zip(names, np.sqrt(np.maximum(np.diag(cov), 0.0)), strict=True))
    params: dict[str, float] = dict.fromkeys(PARAM_KEYS, 0.0)
    params["filter_order"] = 1
    ci: dict[str, tuple[float, float]] = {}
    present: list[str] = []
    for j, term in enumerate(st.terms):
        key = AMPLITUDE_KEY[term]
        theta = float(fit.theta[j])
        params[key] = math.sqrt(max(theta, 0.0))
        if theta > 0:
            present.append(key)
            half = Z95 * se[term]
            ci[key] = (math.sqrt(theta * math.exp(-half)), math.sqrt(theta * math.exp(half)))
    if "markov" in names:
        params["markov_tau"] = st.tau_c_s
        present.append("markov_tau")
        half = Z95 * se["markov_tau"]
        ci["markov_tau"] = (st.tau_c_s * math.exp(-half), st.tau_c_s * math.exp(half))
    if st.bandwidth_hz > 0:
        params["bandwidth_hz"] = st.bandwidth_hz
        params["filter_order"] = st.filter_order
        present.extend(["bandwidth_hz", "filter_order"])
        half = Z95 * se["bandwidth_hz"]  # a bandwidth lies below Nyquist
        ci["bandwidth_hz"] = (st.bandwidth_hz * math.exp(-half),
                              min(st.bandwidth_hz * math.exp(half), 0.5 * rate_hz))
    n2 = white_equivalent(params, rate_hz) ** 2
    if n2 > 0:  # delta method; cov is in log theta (and log tau_c)
        weights = white_equivalent_weights(st.terms, st.tau_c_s)
        grad = np.zeros(len(names))
        for j, term in enumerate(st.terms):
            if term in names:
                grad[names.index(term)] = weights[j] * float(fit.theta[j])
                if term == "markov" and weights[j] > 0 and "markov_tau" in names:
                    grad[names.index("markov_tau")] = weights[j] * float(fit.theta[j])
        ci[WHITE_EQUIVALENT] = white_equivalent_interval(n2, float(grad @ cov @ grad))
    absent = [t for t in BASE if AMPLITUDE_KEY[t] not in present]
    for term, upper in _upper_limits(fit, bases, absent).items():
        ci[AMPLITUDE_KEY[term]] = (0.0, upper)
    notes.append(f"whittle: {sp.nu.size} Fourier frequencies of {sp.n_increments} "
                 f"increments in {sp.pgram.size} bands, -log L = {fit.nll:.6g}")
    pts = avar_points(arr, rate_hz, taus, channel)
    return ChannelFit(channel, float(rate_hz), "whittle", params, ci, tuple(present),
                      pts.tau_s, pts.avar, pts.edf, float(np.nanmean(arr)),
                      notes=tuple(notes), reasons=reasons)


__all__ = [
    "EXTENSION_LR",
    "GAP_RAMP_SAMPLES",
    "MAX_GAP_FRACTION",
    "TAPER_FRACTION",
    "TERM_LR",
    "Spectrum",
    "expected_periodogram",
    "fit_whittle",
    "gap_taper",
    "increment_acv",
    "spectrum",
    "term_basis",
]
