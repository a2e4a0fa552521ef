"""AVAR of a whole model channel (all noise terms and the output filter), sampled data.

``model_avar(channel_model, tau_s, rate_hz)`` sums the generalized autocovariances of the
channel's terms (:mod:`imubench.noisefit.kernels`), passes the sum through the output
low-pass once, and evaluates the exact sampled-data Allan variance at m = round(tau_s *
rate_hz). Without a filter it equals the closed forms (N^2/tau, K^2 tau/3, R^2 tau^2/2,
3 Q^2/tau^2, the sampled sine) exactly, and tends to (2 ln2/pi) B^2 (flicker) and IEEE 952
C.6 (Gauss-Markov) as m grows; with a filter it is what the closed forms cannot give. The
resonance's AVAR is the closed form at its complex pole, :func:`kernels.resonance_avar`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from lsm6ds_sim.model import ChannelModel

from imubench.noisefit.covariance import oavar_edf
from imubench.noisefit.errors import FitError
from imubench.noisefit.kernels import (
    apply_filter,
    avar_from_gacv,
    averaging_factors,
    filter_autocorrelation,
    gacv_unit,
    resonance_gacv,
    sum_variance,
    term_avar,
)


def channel_terms(cm: ChannelModel) -> list[tuple[str, float, dict[str, float]]]:
    """(term, linear coefficient, extra kwargs) of every noise term the channel carries:
    the squared amplitude, or the resonance's height (kernels.HEIGHT_TERMS)."""
    out: list[tuple[str, float, dict[str, float]]] = []
    for term, key in (("white", "white"), ("flicker", "flicker"),
                      ("random_walk", "random_walk"), ("ramp", "ramp"),
                      ("quantization", "quantization")):
        v = float(getattr(cm, key))
        if v != 0.0:
            out.append((term, v * v, {}))
    if cm.markov_sigma > 0 and cm.markov_tau > 0:
        out.append(("markov", cm.markov_sigma**2, {"tau_c_s": cm.markov_tau}))
    if cm.sine_amplitude > 0 and cm.sine_freq > 0:
        out.append(("sine", cm.sine_amplitude**2, {"f0_hz": cm.sine_freq}))
    if cm.resonance_height > 0:  # the model file's rules make its centre and width > 0
        out.append(("resonance", cm.resonance_height,
                    {"f0_hz": cm.resonance_freq_hz, "width_hz": cm.resonance_width_hz}))
    if cm.outlier_rate > 0 and cm.outlier_amplitude > 0:
        out.append(("outliers", cm.outlier_rate * cm.outlier_amplitude**2, {}))
    return out


def stochastic_amplitudes(cm: ChannelModel) -> dict[str, float]:
    """The channel's stochastic terms as :mod:`imubench.noisefit.covariance` takes them:
    squared amplitudes (white, flicker, random walk, quantization, output white, Markov
    sigma) and the resonance's PSD height; deterministic terms (ramp, sine) are left out,
    as that module's covariance leaves them out."""
    amp2 = {"white": cm.white**2, "flicker": cm.flicker**2,
            "random_walk": cm.random_walk**2, "quantization": cm.quantization**2,
            "output_white": cm.output_white**2}
    if cm.markov_sigma > 0 and cm.markov_tau > 0:
        amp2["markov"] = cm.markov_sigma**2
    if cm.resonance_height > 0:
        amp2["resonance"] = cm.resonance_height
    return amp2


def model_oavar_edf(cm: ChannelModel, m: np.ndarray, n_terms: np.ndarray,
                    rate_hz: float) -> np.ndarray:
    """EDF of OAVAR estimates at averaging factors ``m`` (``n_terms`` terms each) of data
    that ``cm`` describes (:func:`imubench.noisefit.covariance.oavar_edf`: 2 A^2 / Var(A)
    under the model's covariance, SP 1065 eq. 44)."""
    m = np.asarray(m, dtype=np.int64)
    return oavar_edf(m, np.asarray(n_terms, dtype=np.int64), stochastic_amplitudes(cm),
                     model_avar_m(cm, m, rate_hz), rate_hz,
                     tau_c_s=float(cm.markov_tau) if cm.markov_sigma > 0 else 0.0,
                     bandwidth_hz=float(cm.bandwidth_hz), filter_order=int(cm.filter_order),
                     resonance=(cm.resonance_freq_hz, cm.resonance_width_hz))


def model_avar_m(cm: ChannelModel, m: np.ndarray, rate_hz: float) -> np.ndarray:
    """AVAR (unit^2) of ``cm`` at integer averaging factors ``m``."""
    m = np.asarray(m, dtype=np.int64)
    if m.size == 0:
        return np.zeros(0)
    rho = filter_autocorrelation(float(cm.bandwidth_hz), int(cm.filter_order), float(rate_hz))
    kmax = 2 * int(m.max()) + rho.size
    g = np.zeros(kmax + 1)
    out = np.zeros(m.size)
    for term, amp2, extra in channel_terms(cm):
        if term in ("markov", "sine", "resonance"):  # filtered on their own
            out += amp2 * term_avar(term, m, rate_hz, bandwidth_hz=cm.bandwidth_hz,
                                    filter_order=cm.filter_order, **extra)
        else:
            g += amp2 * gacv_unit(term, kmax, 1.0 / rate_hz, **extra)
    out += cm.output_white**2 * rate_hz / m.astype(np.float64)  # after the filter
    return out + avar_from_gacv(apply_filter(g, rho), m)


BLOCK_TERMS = ("white", "flicker", "random_walk", "quantization", "outliers")
"""Terms that enter :func:`block_increment_acv` through the generalized autocovariance
(the Gauss-Markov term, the resonance and the white noise after the filter enter too, on
their own)."""


def block_increment_key(cm: ChannelModel) -> tuple[float, ...]:
    """The fields of ``cm`` that :func:`block_increment_acv` reads: two channel models with
    the same key have the same block-increment covariance."""
    return (cm.white, cm.flicker, cm.random_walk, cm.quantization, cm.outlier_rate,
            cm.outlier_amplitude, cm.markov_sigma, cm.markov_tau, cm.bandwidth_hz,
            float(cm.filter_order), cm.output_white, cm.resonance_height,
            cm.resonance_freq_hz, cm.resonance_width_hz)


def block_increment_acv(cm: ChannelModel, m: int, n_lags: int, rate_hz: float) -> np.ndarray:
    """Autocovariance (unit^2) at lags 0..n_lags-1 (in blocks) of the first differences
    ``D_j = ybar_{j+1} - ybar_j`` of the means of consecutive non-overlapping blocks of
    ``m`` samples, for the channel's stochastic terms.

    With ``V(h)`` the variance of a sum of h consecutive samples (the structure function
    of the integrated series, ``V(h) = h G(0) + 2 sum_{l=1}^{h-1} (h - l) G(l)`` from the
    generalized autocovariance G, :func:`kernels.sum_variance`) and ``X_j`` the
    partial sums at the block boundaries, ``D_j = (X_{j+2} - 2 X_{j+1} + X_j) / m``; for
    a process with stationary increments ``E[(X_a - X_b)(X_c - X_d)] = (V(a - d) +
    V(b - c) - V(a - c) - V(b - d)) / 2`` (Yaglom 1987, Correlation Theory of Stationary
    and Related Random Functions, sec. 23), so with ``c = (1, -2, 1)``::

        Cov(D_0, D_k) = -1 / (2 m^2) sum_{a,b=0..2} c_a c_b V(|k + b - a| m)

    and the lag-0 value is ``2 AVAR(m)`` (:func:`model_avar_m`). Flicker and random walk
    have no autocovariance but a generalized one; the constant it is defined up to cancels
    because ``sum c = 0``. The output filter is applied as in :func:`model_avar_m`; the
    resonance enters with its filtered autocovariance (:func:`kernels.resonance_gacv`:
    block means of seconds keep its lines' floor near 0 Hz, about 2 (width / 2 f0)^2 of
    its height). Left out: ramp and sine (deterministic).
    """
    if m < 1 or n_lags < 1:
        raise FitError(f"block increment covariance: m {m} and n_lags {n_lags} must be >= 1")
    rho = filter_autocorrelation(float(cm.bandwidth_hz), int(cm.filter_order), float(rate_hz))
    kmax = (n_lags + 2) * m + rho.size
    tau0 = 1.0 / rate_hz
    g = np.zeros(kmax + 1)
    for term, amp2, extra in channel_terms(cm):
        if term in BLOCK_TERMS:
            g += amp2 * gacv_unit(term, kmax, tau0, **extra)
    g = apply_filter(g, rho)
    if cm.markov_sigma > 0 and cm.markov_tau > 0:
        g += cm.markov_sigma**2 * apply_filter(
            gacv_unit("markov", kmax, tau0, tau_c_s=float(cm.markov_tau)), rho,
            multiplicative=True)
    if cm.resonance_height > 0:
        g += cm.resonance_height * resonance_gacv(
            g.size - 1, rate_hz, float(cm.resonance_freq_hz), float(cm.resonance_width_hz),
            float(cm.bandwidth_hz), int(cm.filter_order))
    g[0] += cm.output_white**2 * rate_hz  # white after the filter
    v = sum_variance(g, np.arange(n_lags + 2, dtype=np.int64) * m)
    c = np.array([1.0, -2.0, 1.0])
    out = np.zeros(n_lags)
    for a in range(3):
        for b in range(3):
            out -= c[a] * c[b] * v[np.abs(np.arange(n_lags) + b - a)]
    return out / (2.0 * m * m)


def model_avar(channel_model: ChannelModel, tau_s: Sequence[float] | np.ndarray,
               rate_hz: float) -> np.ndarray:
    """AVAR (unit^2: dps^2 or g^2) of a model channel at ``tau_s`` for data at ``rate_hz``.

    tau_s is rounded to whole samples (m = round(tau_s rate_hz) >= 1). See the module
    docstring for the method; bias and temperature terms do not enter.

    Raises:
        FitError: rate_hz not > 0, or a tau_s not > 0 / not finite.
    """
    if not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise FitError(f"model AVAR: rate_hz must be > 0, got {rate_hz}")
    tau = np.asarray(tau_s, dtype=float)
    if tau.size and not (np.all(np.isfinite(tau)) and np.all(tau > 0)):
        raise FitError(f"model AVAR: every tau_s must be finite and > 0, got {tau.tolist()}")
    return model_avar_m(channel_model, averaging_factors(tau, rate_hz), rate_hz)


__all__ = ["block_increment_acv", "channel_terms", "model_avar", "model_avar_m",
           "model_oavar_edf", "stochastic_amplitudes"]
