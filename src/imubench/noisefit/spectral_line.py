"""Is there a spectral line near a frequency? The test that backs a fitted sine.

A sine found on the Allan variance curve alone can be any bump of the curve (the AVAR of
a sine is a band-pass view of the spectrum, wide in frequency). A real sinusoid puts a
line in the periodogram; this module looks for it.

Method (Welch 1967; Percival & Walden 1993, "Spectral Analysis for Physical
Applications", sections 6.16-6.17 and 10.9):

* Welch periodogram of the mean-removed series with a Hann window and **non-overlapping**
  segments of L samples, so that under a continuum without a line each bin's estimate
  is P_j = S(f_j) chi2_{2K} / (2K) with K segments (independent segments; the Hann
  window's bins are independent up to the adjacent-bin leakage, which only matters for
  the continuum estimate below). L is the largest power of two leaving
  :data:`MIN_SEGMENTS` segments, but long enough that the candidate frequency sits at
  least :data:`MIN_BIN` bins above 0 (a line needs a continuum on both sides); K >=
  :data:`FEWEST_SEGMENTS` (the threshold below is that of chi2_{2K}, so fewer segments
  only ask more of a line).
* Local continuum at bin j: median of the bins j-W..j+W (W = :data:`HALF_WIDTH`) outside
  a guard of +-:data:`GUARD` bins (the Hann main lobe), divided by the median of
  chi2_{2K}/(2K) (median -> mean). For a monotone continuum the median of a symmetric
  window is the continuum at its centre; other lines in the window do not move it.
* Test: the largest ratio P_j / continuum_j over the bins checked (those covering the
  candidate's frequency interval, at least +-2 bins around it) against
  ``chi2.ppf(1 - alpha / n_bins, 2K) / (2K)`` (Bonferroni over the bins checked,
  family-wise level ``alpha`` = :data:`LINE_ALPHA`), widened by 2.33 standard errors of
  the continuum estimate (relative s.e. of a median of n chi2_{2K}/(2K) values
  ~ 1.2533 / sqrt(n K)).

A band with no line can still hold a narrowband *peak*: a resonance a few bins wide
(:func:`peak_test`). It is not a sine; the noise model's ``resonance`` term describes it,
and :func:`find_peak` scans the spectrum for the one the fit tries.

A line of amplitude A (peak) at a bin centre adds (A^2/2) / ENBW to the one-sided PSD,
ENBW = 1.5 fs / L for the Hann window: with white noise of density N (one-sided PSD
2 N^2), the ratio is 1 + A^2 L / (6 N^2 fs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import welch
from scipy.stats import chi2

LINE_ALPHA: float = 1e-3
"""Family-wise false-alarm probability of the line test (over the bins checked)."""
MIN_SEGMENTS: int = 32
"""Segments wanted in the Welch average (fewer, down to :data:`FEWEST_SEGMENTS`, when
the frequency is low)."""
FEWEST_SEGMENTS: int = 4
"""Fewest Welch segments the line test runs on. It was 8, which left a 10 min record of
an ADIS16405 accelerometer with no test for its 0.54 Hz line (360 periods): the sine was
dropped untested, and the white-only model was 2x off at tau0 (discrepancy floor 0.44).
With K = 4 a line must stand ~5x above the continuum (chi2_8 at 1e-3 / bins)."""
MIN_BIN: int = 24
"""The candidate frequency must sit at least this many bins above 0."""
HALF_WIDTH: int = 16
"""Half-width (bins) of the window the local continuum is taken from."""
GUARD: int = 3
"""Bins on each side of the tested bin left out of its continuum (Hann main lobe +- 2)."""


@dataclass(frozen=True)
class LineTest:
    """Outcome of :func:`line_test`.

    ``freq_hz`` the bin with the largest ratio, ``ratio`` its periodogram over the local
    continuum, ``threshold`` the ratio a line needs, ``segments`` K, ``bins`` the number
    of bins checked; ``amplitude`` the peak amplitude of a sine carrying the line's
    power (sqrt(2 sum (P_j - continuum_j) df) over the main lobe, bins j* +- 2; unit of
    the series); ``testable`` False when the record holds too few periods for the test
    (then ``ratio``, ``threshold`` and ``amplitude`` are NaN).
    """

    freq_hz: float
    ratio: float
    threshold: float
    segments: int
    bins: int
    testable: bool = True
    amplitude: float = math.nan
    resolution_hz: float = math.nan
    """Bin width fs / L of the periodogram."""

    @property
    def present(self) -> bool:
        """True when the periodogram shows a significant line."""
        return self.testable and self.ratio > self.threshold

    def describe(self) -> str:
        """Plain words, e.g. "spectral line at 0.5 Hz 43x the continuum (needs 2.1x)"."""
        if not self.testable:
            return (f"no spectral-line test possible at {self.freq_hz:.3g} Hz (the record "
                    f"holds too few periods: {FEWEST_SEGMENTS} Welch segments must each put it "
                    f">= {MIN_BIN} bins above 0)")
        head = "spectral line" if self.present else "no spectral line"
        return (f"{head} at {self.freq_hz:.3g} Hz (peak {self.ratio:.1f}x the continuum, "
                f"needs {self.threshold:.1f}x)")


def segment_length(n: int, rate_hz: float, f_hz: float) -> int | None:
    """Welch segment length L (power of two) for a line near ``f_hz``, None if too short."""
    need = MIN_BIN * rate_hz / f_hz  # L >= MIN_BIN fs / f puts f at bin >= MIN_BIN
    length = 2 ** math.floor(math.log2(max(n // MIN_SEGMENTS, 2)))
    while length < need:
        length *= 2
    if n // length < FEWEST_SEGMENTS or length < 2 * (MIN_BIN + HALF_WIDTH):
        return None
    return length


def line_test(y: np.ndarray, rate_hz: float, f_lo_hz: float, f_hi_hz: float,
              alpha: float = LINE_ALPHA) -> LineTest:
    """Test for a spectral line between ``f_lo_hz`` and ``f_hi_hz`` (module docstring).

    ``y`` is the rate series (NaN where samples were lost: set to the mean, which only
    lowers a line's ratio). The band is usually the fitted sine frequency's profile
    interval.
    """
    arr = np.asarray(y, dtype=float)
    arr = np.where(np.isfinite(arr), arr, np.nanmean(arr)) - np.nanmean(arr)
    f_lo, f_hi = sorted((float(f_lo_hz), float(f_hi_hz)))
    f_mid = math.sqrt(max(f_lo, 1e-12) * f_hi)
    length = segment_length(arr.size, rate_hz, max(f_lo, 1e-12))
    if length is None:
        return LineTest(f_mid, math.nan, math.nan, 0, 0, testable=False)
    k = arr.size // length
    freq, p = welch(arr[: k * length], fs=rate_hz, window="hann", nperseg=length,
                    noverlap=0, detrend="constant", scaling="density")
    df = rate_hz / length
    j_lo = max(math.floor(f_lo / df) - 2, 1 + HALF_WIDTH)
    j_hi = min(math.ceil(f_hi / df) + 2, p.size - 1 - HALF_WIDTH)
    if j_hi < j_lo:
        return LineTest(f_mid, math.nan, math.nan, k, 0, testable=False)
    offsets = np.r_[np.arange(-HALF_WIDTH, -GUARD), np.arange(GUARD + 1, HALF_WIDTH + 1)]
    bins = np.arange(j_lo, j_hi + 1)
    neighbours = p[bins[:, None] + offsets[None, :]]
    median_to_mean = chi2.median(2 * k) / (2 * k)
    continuum = np.median(neighbours, axis=1) / median_to_mean
    ratios = p[bins] / continuum
    i = int(np.argmax(ratios))
    se_continuum = 1.2533 / math.sqrt(offsets.size * k)
    threshold = chi2.ppf(1.0 - alpha / bins.size, 2 * k) / (2 * k) * math.exp(2.33 * se_continuum)
    lobe = bins[i] + np.arange(-2, 3)
    lobe = lobe[(lobe > 0) & (lobe < p.size)]
    excess = float(np.sum(p[lobe] - continuum[i]) * df)
    return LineTest(float(freq[bins[i]]), float(ratios[i]), float(threshold), k, int(bins.size),
                    amplitude=math.sqrt(2.0 * max(excess, 0.0)), resolution_hz=df)


PEAK_BINS: int = 24
"""Welch bins the tested band of :func:`peak_test` is resolved into (at least)."""
PEAK_RATIO: float = 2.0
"""Highest PSD over continuum a narrowband peak must reach: a smooth continuum that the
flanks' straight line only approximates (a filter's roll-off bends by less) stays below."""
PEAK_Z: float = 5.0
"""z of the band's excess power over its standard error a peak must exceed."""


@dataclass(frozen=True)
class PeakTest:
    """Outcome of :func:`peak_test`: ``freq_hz`` the excess-weighted centre, ``width_hz``
    its full width at half maximum, ``ratio`` the highest PSD over the continuum, ``z``
    the band's excess power over its standard error."""

    freq_hz: float
    width_hz: float
    ratio: float
    z: float
    resolution_hz: float = math.nan
    """Bin width fs / L of the periodogram (Hz)."""

    @property
    def present(self) -> bool:
        """True for a significant peak of at least :data:`PEAK_RATIO` times the continuum."""
        return self.ratio >= PEAK_RATIO and self.z > PEAK_Z

    def describe(self) -> str:
        """Plain words, e.g. "a narrowband peak at 19.6 Hz, 1.9 Hz wide, 9.8x the continuum"."""
        return (f"a narrowband peak at {self.freq_hz:.3g} Hz, {self.width_hz:.2g} Hz wide, "
                f"{self.ratio:.1f}x the continuum")


def peak_test(y: np.ndarray, rate_hz: float, f_lo_hz: float, f_hi_hz: float
              ) -> PeakTest | None:
    """A narrowband peak (not a line) between ``f_lo_hz`` and ``f_hi_hz``?

    Welch periodogram (Hann, non-overlapping segments of L samples, K segments) resolving
    the band into at least :data:`PEAK_BINS` bins. The continuum is the least-squares
    straight line in log f - log P through the flanks, the bins within one band-width
    below and above the band (clipped to (0, 0.49 fs)). Under no peak each band bin is
    continuum x chi2_{2K}/(2K), so the band's excess power sum (P_j - C_j) df has standard
    error sqrt(sum C_j^2 / K) df (the flank line's own error is added, scaled by the
    band-to-flank bin count ratio). None when the band cannot be resolved or has no
    flank."""
    arr = np.asarray(y, dtype=float)
    arr = np.where(np.isfinite(arr), arr, np.nanmean(arr)) - np.nanmean(arr)
    f_lo, f_hi = sorted((float(f_lo_hz), float(f_hi_hz)))
    width = f_hi - f_lo
    if not width > 0:
        return None
    length = 2 ** math.ceil(math.log2(PEAK_BINS * rate_hz / width))
    k = arr.size // length
    if k < 8:
        return None
    freq, p = welch(arr[: k * length], fs=rate_hz, window="hann", nperseg=length,
                    noverlap=0, detrend="constant", scaling="density")
    band = (freq >= f_lo) & (freq <= f_hi)
    flank = (((freq >= f_lo - width) & (freq < f_lo)) | ((freq > f_hi)
             & (freq <= f_hi + width))) & (freq > 0) & (freq < 0.49 * rate_hz)
    if band.sum() < 3 or flank.sum() < 4:
        return None
    coef = np.polyfit(np.log(freq[flank]), np.log(p[flank]), 1)
    cont = np.exp(np.polyval(coef, np.log(freq[band])))
    excess = p[band] - cont
    df = rate_hz / length
    se = math.sqrt(float(np.sum(cont**2)) / k) * df
    se *= math.sqrt(1.0 + band.sum() / flank.sum())
    z = float(excess.sum() * df / se) if se > 0 else 0.0
    ratio = p[band] / cont
    top = float(excess.max())
    fb = freq[band]
    half = excess > top / 2
    centre = float(np.sum(fb[half] * excess[half]) / np.sum(excess[half])) if top > 0 else \
        float(fb[int(np.argmax(ratio))])
    return PeakTest(centre, float(half.sum()) * df, float(ratio.max()), z, df)


PEAK_MIN_BINS: int = 3
"""Bins above half maximum a peak needs in :func:`find_peak` to be a resonance, not a line."""
SCAN_BAND: float = 1.25
""":func:`find_peak` tests the bands [fc / SCAN_BAND, fc SCAN_BAND], fc stepped by this
factor (neighbouring bands overlap by half)."""
SCAN_LOW_FRACTION: float = 0.01
"""Lowest band centre of :func:`find_peak`, as a fraction of the sample rate."""
SCAN_HIGH_FRACTION: float = 0.45
"""Highest band edge of :func:`find_peak`, as a fraction of the sample rate."""


def find_peak(y: np.ndarray, rate_hz: float) -> PeakTest | None:
    """The most significant narrowband peak wider than a line, or None.

    :func:`peak_test` on the bands [fc / :data:`SCAN_BAND`, fc :data:`SCAN_BAND`] with
    centres fc from :data:`SCAN_LOW_FRACTION` fs stepped by SCAN_BAND while the band's
    top stays below :data:`SCAN_HIGH_FRACTION` fs (about 17 bands: the Bonferroni cost of
    the scan is small against the z > :data:`PEAK_Z`, p ~ 3e-7, a peak needs). Of the
    present peaks at least :data:`PEAK_MIN_BINS` bins wide at half maximum (a line, the
    sine's, is one or two: the Hann main lobe), the one of the largest z is tested again
    in a band centred on it, which places it better than a band it straddles.
    """
    def wide(p: PeakTest | None) -> bool:
        return p is not None and p.present and p.width_hz >= PEAK_MIN_BINS * p.resolution_hz

    best: PeakTest | None = None
    fc = SCAN_LOW_FRACTION * rate_hz
    while fc * SCAN_BAND <= SCAN_HIGH_FRACTION * rate_hz:
        peak = peak_test(y, rate_hz, fc / SCAN_BAND, fc * SCAN_BAND)
        if peak is not None and wide(peak) and (best is None or peak.z > best.z):
            best = peak
        fc *= SCAN_BAND
    if best is None:
        return None
    f0 = min(best.freq_hz, SCAN_HIGH_FRACTION * rate_hz / SCAN_BAND)
    again = peak_test(y, rate_hz, f0 / SCAN_BAND, f0 * SCAN_BAND)
    return again if again is not None and wide(again) else best


__all__ = ["LINE_ALPHA", "LineTest", "PeakTest", "find_peak", "line_test", "peak_test",
           "segment_length"]
