"""Measured and model power spectral density of a rate channel, for the report's PSD plot.

Convention: the **two-sided** PSD S(f) of IEEE Std 952-1997 Annex C (eq. C.2: sigma^2(tau)
= 4 int_0^inf S(f) sin^4(pi f tau) / (pi f tau)^2 df), evaluated at f > 0. In it white
noise of coefficient N has S = N^2, so the amplitude spectral density sqrt(S) of the white
floor reads N in the datasheet's unit/sqrt(Hz) (the same N as ``noise_density`` in the
tables; a one-sided density would be sqrt(2) N).

Measured: the periodogram of the whole record (mean removed, NaN gaps set to the mean,
Hann window, ``scipy.signal.periodogram``, one-sided, halved to two-sided) averaged over
log-spaced frequency bands (:data:`BANDS_PER_DECADE` per decade), so the low frequencies
keep the resolution 1/T of the full record and the high ones average many bins.

Model: each term's spectrum from IEEE 952 Annex C (C.1 quantization (2 pi f)^2 Q^2 tau0,
C.2 white N^2, C.3 flicker B^2 / (2 pi f), C.4 random walk K^2 / (2 pi f)^2, C.6 Gauss-
Markov 2 sigma^2 T_c / (1 + (2 pi f T_c)^2), C.7 sine A^2/4 delta(f - f0)) in the exact
sampled-data form the AVAR kernels use (:func:`imubench.noisefit.kernels.term_spectrum`,
which tends to those expressions for f << rate), times the output low-pass |H(f)|^2
(:func:`~imubench.noisefit.kernels.filter_gain2`; ``output_white`` is added after it). A
sine is drawn at the band-averaged level the periodogram shows, (A^2/4) / (band width), in
the band holding f0. The resonance is its band-pass's PSD, height |H_bp(f)|^2 / 2 (its
height is a one-sided peak), times the output low-pass, averaged over each band (a peak
narrower than a band would be missed by the band centre). The rate ramp (C.5) is
deterministic and the mean-removed periodogram of one record does not follow its ensemble
form R^2/(2 pi f)^3: it is not drawn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imubench.noisefit.fit import ChannelFit
from imubench.noisefit.kernels import filter_gain2, resonance_psd, term_spectrum

BANDS_PER_DECADE: int = 10
"""Log-spaced frequency bands per decade of the smoothed spectrum."""
FIRST_BIN: int = 2
"""First periodogram bin used (bins 0 and 1 carry the removed mean through the window)."""


@dataclass(frozen=True)
class BandPSD:
    """A band-averaged two-sided PSD: per band its centre ``f_hz`` (geometric mean of its
    bins), lower and upper edges (Hz), mean ``psd`` (unit^2/Hz) and number of bins;
    ``df_hz`` the periodogram's bin spacing (rate / samples)."""

    f_hz: np.ndarray
    f_low_hz: np.ndarray
    f_high_hz: np.ndarray
    psd: np.ndarray
    bins: np.ndarray
    df_hz: float


def band_psd(y: np.ndarray, rate_hz: float, per_decade: int = BANDS_PER_DECADE) -> BandPSD:
    """The measured two-sided PSD of ``y`` (unit at ``rate_hz``) in log bands (module
    docstring). Needs at least 16 finite samples."""
    from scipy.signal import periodogram

    arr = np.asarray(y, dtype=np.float64)
    ok = np.isfinite(arr)
    if ok.sum() < 16:
        raise ValueError(f"PSD needs at least 16 finite samples, got {int(ok.sum())}")
    x = np.where(ok, arr - arr[ok].mean(), 0.0)
    f, p1 = periodogram(x, fs=rate_hz, window="hann", detrend=False, scaling="density")
    f, p = f[FIRST_BIN:], 0.5 * p1[FIRST_BIN:]
    decades = np.log10(f[-1] / f[0])
    n_bands = max(int(np.ceil(decades * per_decade)), 1)
    edges = np.geomspace(f[0], f[-1], n_bands + 1)
    edges[-1] = np.nextafter(edges[-1], np.inf)
    idx = np.digitize(f, edges) - 1
    counts = np.bincount(idx, minlength=n_bands)[:n_bands]
    sums = np.bincount(idx, weights=p, minlength=n_bands)[:n_bands]
    logf = np.bincount(idx, weights=np.log(f), minlength=n_bands)[:n_bands]
    used = counts > 0
    return BandPSD(np.exp(logf[used] / counts[used]), edges[:-1][used], edges[1:][used],
                   sums[used] / counts[used], counts[used], float(rate_hz) / x.size)


BAND_AVERAGE_POINTS = 256
"""Points per band at which the resonance's PSD is averaged (:func:`term_psds`)."""


def term_psds(fit: ChannelFit, bands: BandPSD) -> dict[str, np.ndarray]:
    """Two-sided PSD (unit^2/Hz) of each present term of ``fit`` at the band centres
    (module docstring); the sine only in its band (zero elsewhere)."""
    rate = fit.rate_hz
    tau0 = 1.0 / rate
    nu = bands.f_hz * tau0
    p = fit.params
    gain = filter_gain2(nu, float(p.get("bandwidth_hz", 0.0)), int(p.get("filter_order", 1)),
                        rate)
    out: dict[str, np.ndarray] = {}
    for term in ("white", "flicker", "random_walk", "quantization"):
        if term in fit.present and p.get(term, 0.0) > 0:
            out[term] = p[term] ** 2 * term_spectrum(term, nu, tau0) * tau0 * gain
    if "markov_sigma" in fit.present and p.get("markov_tau", 0.0) > 0:
        out["markov"] = (p["markov_sigma"] ** 2 * gain * tau0
                         * term_spectrum("markov", nu, tau0, tau_c_s=p["markov_tau"]))
    if "sine_amplitude" in fit.present and p.get("sine_freq", 0.0) > 0:
        f0 = p["sine_freq"]
        inside = (bands.f_low_hz <= f0) & (f0 < bands.f_high_hz)
        width = bands.bins * bands.df_hz
        g0 = filter_gain2(np.array([f0 * tau0]), float(p.get("bandwidth_hz", 0.0)),
                          int(p.get("filter_order", 1)), rate)[0]
        out["sine"] = np.where(inside, p["sine_amplitude"] ** 2 / 4.0 * g0 / width, 0.0)
    if "resonance_height" in fit.present:
        # averaged over each band as the periodogram is: a peak narrower than a band
        # sampled at the band centres was missed (a 0.5 Hz wide peak at 20.8 Hz drawn at
        # half the measured band level)
        u = (np.arange(BAND_AVERAGE_POINTS) + 0.5) / BAND_AVERAGE_POINTS
        f = bands.f_low_hz[:, None] + (bands.f_high_hz - bands.f_low_hz)[:, None] * u
        g = filter_gain2(f.ravel() * tau0, float(p.get("bandwidth_hz", 0.0)),
                         int(p.get("filter_order", 1)), rate).reshape(f.shape)
        out["resonance"] = np.mean(g * resonance_psd(f, p["resonance_height"],
                                                     p["resonance_freq_hz"],
                                                     p["resonance_width_hz"], rate), axis=1)
    if "output_white" in fit.present and p.get("output_white", 0.0) > 0:
        out["output_white"] = np.full(nu.size, p["output_white"] ** 2)
    return out


__all__ = ["BANDS_PER_DECADE", "BandPSD", "band_psd", "term_psds"]
