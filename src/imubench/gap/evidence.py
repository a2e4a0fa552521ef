"""Time-domain and spectral evidence: each estimator fits one effect to the REAL data.

* temperature: least squares of block means of the rate on ``dT`` and ``dT^2``,
  ``dT = T - temp_ref`` (block means low-pass both series so white noise does not dilute
  the regression; ordinary least squares, e.g. Draper & Smith, Applied Regression
  Analysis, ch. 2). A random walk or flicker level correlates spuriously with any slow
  temperature history in levels (Granger & Newbold 1974, J. Econometrics 2, "Spurious
  regressions in econometrics"), so the diagnosis only fits this candidate when the
  prewhitened (first-differenced) block means correlate with the temperature's
  increments beyond the realisations' chance level (``diagnose.Z_TEMP_CANDIDATE``); the
  coefficient itself comes from levels, because differencing the recorded temperature
  amplifies its quantization and noise and biases the slope toward zero (errors in
  variables).
* ramp: least-squares slope of the rate against time (unit/s; the model's ``ramp``; computed
  with the features, ``imubench.gap.curves.Features.trend_slope``).
* sine: the largest line of the Welch spectrum's ratio to the model's; frequency refined
  on the zero-padded periodogram of the whole fit part, amplitude by least squares of a
  sine and cosine at that frequency (Kay, Modern Spectral Estimation, sec. 13.3).
* outliers: impulses beyond ``T = TAIL_SIGMAS`` robust sigmas of the series minus its
  running median. With impulse plus noise ``a ~ N(0, v^2)`` observed only when
  ``|a| > T``, the truncated-normal moment ``E[a^2 | |a| > T] = v^2 (1 + u phi(u) / Q(u))``,
  ``u = T / v`` (Johnson, Kotz & Balakrishnan, Continuous Univariate Distributions 1,
  sec. 13.10.1) is solved for v; amplitude ``s = sqrt(v^2 - sigma^2)`` and rate
  ``lambda = n_detected / (duration 2 Q(u))``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.optimize import brentq, curve_fit
from scipy.stats import norm

from imubench.gap.curves import (
    TAIL_SIGMAS,
    highpass_residual,
    robust_sigma,
    temperature_blocks,
)


@dataclass(frozen=True)
class TemperatureFit:
    temp_coeff: float
    temp_coeff2: float
    temp_coeff_linear: float
    """Slope of the linear-only fit (unit/degC)."""
    block_temp_c: np.ndarray
    block_rate: np.ndarray


def fit_temperature(y: np.ndarray, temp_c: np.ndarray, rate_hz: float,
                    temp_ref_c: float) -> TemperatureFit | None:
    """Regress block means of y on (T - temp_ref), (T - temp_ref)^2; None if T is flat."""
    yb, tb = temperature_blocks(y, temp_c, rate_hz)
    if len(yb) < 5 or np.ptp(tb) < 1e-6:
        return None
    c2 = temperature_levels(yb, tb, temp_ref_c, quadratic=True)
    c1 = temperature_levels(yb, tb, temp_ref_c, quadratic=False)
    return TemperatureFit(float(c2[1]), float(c2[2]), float(c1[1]), tb, yb)


def temperature_levels(yb: np.ndarray, tb: np.ndarray, temp_ref_c: float, quadratic: bool
                       ) -> np.ndarray:
    """Least-squares coefficients (constant, dT[, dT^2]) of block means ``yb`` ((m,) or
    (m, k), one column per series) on ``dT = tb - temp_ref_c``."""
    dt = tb - temp_ref_c
    cols = [np.ones_like(dt), dt] + ([dt**2] if quadratic else [])
    coef, *_ = np.linalg.lstsq(np.column_stack(cols), yb, rcond=None)
    return np.asarray(coef)


@dataclass(frozen=True)
class SineFit:
    sine_amplitude: float
    sine_freq: float


def fit_sine(y: np.ndarray, rate_hz: float, f_guess_hz: float, bin_hz: float) -> SineFit:
    """Refine a line near f_guess_hz (within one Welch bin) and fit its peak amplitude.

    The frequency is the maximum of the 16x zero-padded periodogram of the whole series
    within one bin of the guess, refined by a parabola through the three highest
    log-power points; amplitude by least squares of sin and cos at that frequency.
    """
    v = np.where(np.isfinite(y), y - np.nanmean(y), 0.0)
    n = len(v)
    nfft = int(2 ** math.ceil(math.log2(16 * n)))
    power = np.abs(np.fft.rfft(v, nfft)) ** 2
    df = rate_hz / nfft
    lo = max(1, int((f_guess_hz - bin_hz) / df))
    hi = min(len(power) - 2, int((f_guess_hz + bin_hz) / df) + 1)
    k = lo + int(np.argmax(power[lo : hi + 1]))
    a, b, c = np.log(power[k - 1 : k + 2] + 1e-300)
    den = a - 2 * b + c
    shift = 0.5 * (a - c) / den if den < 0 else 0.0
    best = (k + float(np.clip(shift, -0.5, 0.5))) * df
    t = np.arange(n) / rate_hz
    basis = np.column_stack([np.sin(2 * math.pi * best * t), np.cos(2 * math.pi * best * t)])
    c2, *_ = np.linalg.lstsq(basis, v, rcond=None)
    return SineFit(float(math.hypot(c2[0], c2[1])), best)


@dataclass(frozen=True)
class OutlierFit:
    outlier_rate: float
    outlier_amplitude: float
    detected: np.ndarray
    """Residual values of the detected impulses (for the evidence histogram)."""
    sigma: float
    threshold: float


def fit_outliers(y: np.ndarray, rate_hz: float, false_per_record: float = 0.0
                 ) -> OutlierFit | None:
    """Rate (1/s) and amplitude of impulses from the detected tail; None if fewer than 3
    are found or their second moment is not above the threshold's normal-law tail (no
    impulse amplitude fits it: u = T / v beyond 30, where a rate of n / Q(u) would be
    astronomical)."""
    r = highpass_residual(y)
    sigma = robust_sigma(r)
    if not sigma > 0:
        return None
    thr = TAIL_SIGMAS * sigma
    hit = r[np.abs(r) > thr]
    n_hit = len(hit) - false_per_record
    if n_hit < 3:
        return None
    m2 = float(np.mean(hit**2))
    def excess(u: float) -> float:
        v2 = (thr / u) ** 2
        return v2 * (1.0 + u * norm.pdf(u) / norm.sf(u)) - m2

    if excess(30.0) >= 0.0:  # the tail is no heavier than a normal law's beyond thr
        return None
    # excess falls monotonically in u from +inf (u -> 0) to thr^2 - m2 < 0, and is
    # positive below u = thr / sqrt(m2), which lies below 1e-3 when the robust sigma is
    # far below the hits' size (a record that holds every sample for 7: a reviewer's
    # brentq failed there)
    u = brentq(excess, min(1e-3, 0.5 * thr / math.sqrt(m2)), 30.0)
    v = thr / u
    amp = math.sqrt(max(v * v - sigma * sigma, 0.0))
    duration = np.isfinite(y).sum() / rate_hz
    rate = n_hit / (duration * 2.0 * norm.sf(u))
    return OutlierFit(float(rate), float(amp), hit, sigma, thr)


STEP_BLOCKS = 256
"""Blocks of the whole record whose means the bias-step statistic compares."""
STEP_WINDOW_BLOCKS = 8
"""Blocks on each side of a located step whose means give its size."""


def mad_sigma(v: np.ndarray) -> float:
    """:func:`imubench.gap.curves.robust_sigma` of the finite values of ``v`` (NaN when
    there are none)."""
    v = v[np.isfinite(v)]
    return robust_sigma(v) if v.size else float("nan")


STEP_SCALES = (1, 2, 4, 8)
"""Widths in blocks of the windows whose means :func:`step_statistic` compares on either
side of each block boundary (and of each block, skipped)."""


def step_statistic(y: np.ndarray) -> tuple[float, int]:
    """(largest normalised jump of block means, block index of the jump).

    For each width w of STEP_SCALES, the mean of w block means after a boundary less the
    mean of the w before it, and the same with the block between them skipped (a step
    that falls inside a block splits between two adjacent differences otherwise); each
    family divided by its robust (MAD) sigma over the record; the largest absolute value.
    Gaussian increments (white, flicker, a random walk, a ramp: a constant increment)
    keep it near the maximum of a few hundred normals (about 3.5-4.5); a bias step puts
    the differences across it far out in the tail (Page 1954, Biometrika 41, 100-115: a
    change in mean is a jump of the cumulative sum; here one jump among Gaussian
    increments). Wider windows average the white noise down, so a step that white noise
    hides from single blocks shows across several: an outside reviewer's 10.6 mdps step
    in white 4.9 mdps/sqrt(Hz) and flicker 1 mdps over an hour read 3.7 on the 14 s
    blocks alone (`none`), about 9 on eight of them. The record is never split for this
    test, so a step at the fit/held-out boundary is seen like any other. The index is
    the first block after the boundary, or the skipped block.
    """
    best, where, _ = _step_scan(y)
    return best, where


def _step_scan(y: np.ndarray) -> tuple[float, int, int]:
    """:func:`step_statistic` and the window width (blocks) at which it was found."""
    m = step_block_means(y)
    best, where, width = 0.0, 0, 1
    for w in STEP_SCALES:
        if len(m) < 2 * w + 5:
            continue
        win = sliding_window_view(m, w).mean(axis=1)  # win[k] = mean of m[k:k+w]
        for gap in (0, 1):
            d = win[w + gap:] - win[:len(win) - w - gap]  # after (from k+w+gap) - before
            s = mad_sigma(d)
            if not s > 0:
                continue
            r = np.abs(d - np.nanmedian(d)) / s
            if np.isfinite(r).any():
                i = int(np.nanargmax(r))
                if r[i] > best:
                    best, where, width = float(r[i]), i + w, w
    return best, where, width


def block_means_of(y: np.ndarray, n_block: int) -> np.ndarray:
    nb = len(y) // n_block
    with np.errstate(invalid="ignore"):
        v = y[: nb * n_block].reshape(nb, n_block)
        ok = np.isfinite(v)
        cnt = ok.sum(axis=1)
        s = np.where(ok, v, 0.0).sum(axis=1)
    return np.where(cnt > 0, s / np.maximum(cnt, 1), np.nan)


@dataclass(frozen=True)
class StepFit:
    step_time_s: float
    step_size: float


def fit_bias_step(y: np.ndarray, rate_hz: float) -> StepFit:
    """Time and size of the largest bias step of the whole record.

    Located to a block by :func:`step_statistic`, then to a sample by the largest
    absolute cumulative sum of the mean-removed samples of the blocks around it, as many
    on each side as the statistic's window width and one more (the least-squares change
    point of a mean shift, Hinkley 1970, Biometrika 57, 1-17); the
    size is the difference of the means of STEP_WINDOW_BLOCKS blocks on either side,
    skipping the block the step falls in (a local estimate: a slow wander of the
    background does not bias it the way whole-record means would).
    """
    n_block = _step_block(len(y))
    _, jb, width = _step_scan(y)
    lo = max(0, (jb - width) * n_block)
    hi = min(len(y), (jb + width + 1) * n_block)
    seg = y[lo:hi]
    seg = np.where(np.isfinite(seg), seg, np.nanmean(seg))
    cs = np.cumsum(seg - seg.mean())
    k = lo + int(np.argmax(np.abs(cs))) + 1
    w = STEP_WINDOW_BLOCKS * n_block
    left = y[max(0, k - n_block // 2 - w): max(0, k - n_block // 2)]
    right = y[k + n_block // 2: k + n_block // 2 + w]
    size = float(np.nanmean(right) - np.nanmean(left)) if left.size and right.size else 0.0
    return StepFit(k / rate_hz, size)


STEP_PERSISTENCE = 0.5
"""Share of a located step's size that the record's far levels must keep
(:func:`step_persistence`)."""


def step_persistence(y: np.ndarray, rate_hz: float, step: StepFit) -> float:
    """How much of a located step the levels far from it keep (1 for a clean step).

    ``(median after - median before) / step_size`` over the STEP_BLOCKS block means of
    the whole record, leaving out the block the step falls in and its neighbours (the
    median, not the mean: a transient or an outlier burst moves a few blocks only). A
    bias step shifts every later level; a transient excursion (Samsung S5 gyro: -50 mdps
    for ten minutes, then back) gives a local size but no lasting shift, and a
    wandering background returns ~0 on average. NaN when a side holds fewer than three
    blocks (a step at the very edge is kept on its local size)."""
    return persistence_of_means(step_block_means(y), _step_block(len(y)), rate_hz, step)


def _step_block(n: int) -> int:
    """Samples per block of the :data:`STEP_BLOCKS` block means of ``n`` samples."""
    return max(1, n // STEP_BLOCKS)


def step_block_means(y: np.ndarray) -> np.ndarray:
    """The block means (:data:`STEP_BLOCKS` of them) :func:`step_persistence` compares."""
    return block_means_of(y, _step_block(len(y)))


def persistence_of_means(m: np.ndarray, n_block: int, rate_hz: float, step: StepFit
                         ) -> float:
    """:func:`step_persistence` from a record's block means ``m`` of ``n_block`` samples."""
    jb = int(step.step_time_s * rate_hz) // n_block
    before, after = m[: max(0, jb - 1)], m[jb + 2:]
    before, after = before[np.isfinite(before)], after[np.isfinite(after)]
    if before.size < 3 or after.size < 3 or step.step_size == 0:
        return float("nan")
    return float((np.median(after) - np.median(before)) / step.step_size)


STEP_WANDER_Z = 2.0
"""A step whose far levels keep less than :data:`STEP_PERSISTENCE` of it is refused only
when the share it keeps lies more than this many standard deviations of the model's own
wander (:func:`step_persistence_spread`) below 1."""


def step_persistence_spread(means: np.ndarray, n: int, rate_hz: float, step: StepFit
                            ) -> float:
    """Standard deviation over the model's realisations of :func:`step_persistence` at the
    record's located step, from their block means (``means``, K x :data:`STEP_BLOCKS`,
    :func:`step_block_means` of each realisation of ``n`` samples seen as the record is):
    how far the share a true step keeps moves with the model's slow noise alone. A random walk of
    4e-4 dps/sqrt(s) moves the far medians of an hour by ~K sqrt(1800 s) = 0.017 dps, as
    much as a 0.02 dps step (an outside reviewer's record, whose step kept 37 % of its
    size and was refused while the walk took it, read 53 % high). NaN with fewer than 3
    finite shares."""
    n_block = _step_block(n)
    shares = np.array([persistence_of_means(m, n_block, rate_hz, step) for m in means])
    shares = shares[np.isfinite(shares)]
    return float(np.std(shares, ddof=1)) if shares.size >= 3 else float("nan")


@dataclass(frozen=True)
class ResonanceFit:
    resonance_freq_hz: float
    resonance_width_hz: float
    resonance_height: float


RESONANCE_WINDOW_WIDTHS = 8.0
"""Half-width of the window of the Lorentzian fit, in first-guess widths (at least
RESONANCE_WINDOW_BINS bins): the half-maximum run of a noisy Welch excess ends early."""
RESONANCE_WINDOW_BINS = 40
RESONANCE_REFITS = 3
"""Lorentzian fits at most: a fit wider than its window's RESONANCE_WINDOW_WIDTHS is
fitted again over a window of its own width (a first guess cut short by a noisy dip gave
a window that held only the line's top: 0.51 Hz for 1 Hz on 3 of 24 seeds)."""


def _lorentzian(f: np.ndarray, fc: float, width: float, height: float) -> np.ndarray:
    return height / (1.0 + (2.0 * (f - fc) / width) ** 2)


def fit_resonance(f_hz: np.ndarray, psd_real: np.ndarray, psd_model: np.ndarray,
                  f_min_hz: float = 0.0) -> ResonanceFit | None:
    """Centre, -3 dB width and peak height (unit^2/Hz) of the largest spectral excess.

    First guess: the excess ``psd_real - psd_model`` (Welch, one-sided) smoothed over
    three bins, its highest bin at or above ``f_min_hz`` (and above the first two), the
    contiguous run of bins above half of it. Then a Lorentzian line ``H / (1 + (2 (f -
    fc) / w)^2)`` (peak H, full width at half maximum w) is fitted to the unsmoothed
    excess by weighted least squares over fc +- RESONANCE_WINDOW_WIDTHS first-guess
    widths, each bin weighted by the inverse of the smoothed real PSD (a Welch estimate's
    spread is proportional to its mean). The half-maximum run alone stopped at the first
    noisy dip: an injected 1 Hz wide peak at 8 Hz, 2-31 times the continuum, 30 min at
    104 Hz, came out 0.08-0.28 Hz wide with the peak 30-50 % high (measured, 12 seeds).
    A fit wider than its window allows is fitted again over a window of its own width
    (:data:`RESONANCE_REFITS`). None when there is no excess.
    """
    ex_raw = psd_real - psd_model
    ex = np.convolve(ex_raw, np.ones(3) / 3.0, mode="same")
    ex[:2] = -np.inf
    ex[f_hz < f_min_hz] = -np.inf
    i = int(np.argmax(ex))
    h = float(ex[i])
    if not h > 0:
        return None
    j0 = i
    while j0 > 2 and ex[j0 - 1] > h / 2:
        j0 -= 1
    j1 = i
    while j1 + 1 < len(ex) and ex[j1 + 1] > h / 2:
        j1 += 1
    df = float(f_hz[1] - f_hz[0])
    w = ex[j0:j1 + 1]
    fc = float(np.sum(f_hz[j0:j1 + 1] * w) / np.sum(w))
    width = max((j1 - j0 + 1) * df, df)
    sd_all = np.convolve(psd_real, np.ones(9) / 9.0, mode="same")
    best = ResonanceFit(fc, width, h)
    for _ in range(RESONANCE_REFITS):
        half = max(RESONANCE_WINDOW_WIDTHS * best.resonance_width_hz,
                   RESONANCE_WINDOW_BINS * df)
        win = (np.abs(f_hz - best.resonance_freq_hz) <= half) & (
            f_hz >= max(f_min_hz, float(f_hz[2])))
        sd = sd_all[win]
        if not (win.sum() > 6 and np.all(sd > 0)):
            break
        lo, hi = float(f_hz[win][0]), float(f_hz[win][-1])
        try:
            (fc_l, w_l, h_l), _ = curve_fit(
                _lorentzian, f_hz[win], ex_raw[win],
                p0=(best.resonance_freq_hz, best.resonance_width_hz, best.resonance_height),
                sigma=sd, bounds=([lo, df, 0.0], [hi, 2.0 * half, np.inf]), maxfev=2000)
        except (RuntimeError, ValueError):
            break
        if not h_l > 0:
            break
        best = ResonanceFit(float(fc_l), float(w_l), float(h_l))
        if RESONANCE_WINDOW_WIDTHS * w_l <= half:
            break
    return best


DRIFT_BLOCKS = 32
"""Blocks of the whole record whose increments the drift test averages."""
DRIFT_LAGS = 3
"""Bartlett lags of the Newey-West variance of the mean increment."""


def drift_statistic(y: np.ndarray, rate_hz: float) -> tuple[float, int]:
    """(t of the mean increment of block means, its degrees of freedom).

    A linear drift (a ramp) makes every increment of the block means positive on average;
    white, flicker and random-walk noise have zero-mean increments. The mean of the
    DRIFT_BLOCKS - 1 increments is divided by its Newey-West standard error (Bartlett
    weights, DRIFT_LAGS lags; Newey & West 1987, Econometrica 55, 703-708), so the test
    normalises itself on the record: against a random walk of density K it has the
    power ``R sqrt(T) / K`` of a drift R over the record length T, and for white noise
    (negatively correlated increments) it is conservative. Student t with
    ``DRIFT_BLOCKS - 2`` dof under no drift."""
    n_block = max(1, len(y) // DRIFT_BLOCKS)
    m = block_means_of(y, n_block)
    d = np.diff(m[np.isfinite(m)])
    if d.size < 8:
        return float("nan"), 1
    c = d - d.mean()
    var = float(np.mean(c * c))
    for lag in range(1, DRIFT_LAGS + 1):
        var += 2.0 * (1.0 - lag / (DRIFT_LAGS + 1)) * float(np.mean(c[lag:] * c[:-lag]))
    if not var > 0:
        return float("nan"), d.size - 1
    return float(d.mean() / math.sqrt(var / d.size)), d.size - 1
