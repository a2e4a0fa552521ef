"""Covariance model of overlapping Allan variance estimates at several averaging times.

OAVAR estimates at neighbouring taus share data and are strongly correlated (for white
noise about 0.5 between octaves), so a fit that treats them as independent reports
intervals that are too narrow. For a Gaussian process the estimate at m is
``A(m) = 1/(2n) sum_i D_i^2`` with ``D_i = ybar_{i+m} - ybar_i`` (n overlapping terms),
and, because ``Cov(X^2, Y^2) = 2 Cov(X, Y)^2`` for jointly Gaussian zero-mean X, Y::

    Cov(A(m1), A(m2)) = 1/(2 n1 n2) sum_d ov(d) c12(d)^2,
    c12(d) = Cov(D_i^(m1), D_{i+d}^(m2)) = int S(nu) W1(nu) conj(W2(nu)) e^{2 pi i nu d} dnu

with S the two-sided PSD of the model (:func:`imubench.noisefit.kernels.term_spectrum`),
W_m the transfer function of the Allan difference of m-averages and ov(d) the number of
index pairs (i, i + d). c12 is computed with one inverse FFT per pair. Only the
*correlation* is taken from this model; the variances of the fit keep the EDF of each point
(var = 2 AVAR^2 / edf, Greenhall & Riley EDF), as the issue asks. Large averaging factors
are handled by scale invariance: block means of s samples of white, random walk,
quantization and (approximately) flicker and Gauss-Markov noise are the same term at the
sample time s tau0, so the pair (m1, m2) is evaluated at (m1/s, m2/s) with rate/s (the
output filter is dropped there: it only acts on the shortest taus). Deterministic terms
(ramp, sine) are left out of the covariance (documented limitation). The resonance
(``amp2["resonance"]`` = its PSD height, centre and width in ``resonance``) enters with
its line-pair spectrum at the original sampling only: block means of s >= 2 samples
average a resonance near the Nyquist frequency away, so the rescaled pairs leave it out,
as they leave out the output filter.
"""

from __future__ import annotations

from collections.abc import Mapping
from functools import lru_cache

import numpy as np

from imubench.noisefit.kernels import filter_gain2, resonance_psd, term_spectrum

FFT_MAX: int = 1 << 14
"""Longest FFT used for one pair (larger pairs are rescaled)."""
MAX_RATIO: int = 64
"""Pairs whose averaging factors differ by more than this are taken as uncorrelated (the
correlation halves per octave for random walk, faster for the other terms: < 0.02 here)."""

_STOCHASTIC = ("white", "flicker", "random_walk", "quantization", "markov")


def _allan_weights(m: int, length: int) -> np.ndarray:
    a = np.zeros(length)
    a[:m] = -1.0 / m
    a[m:2 * m] = 1.0 / m
    return a


@lru_cache(maxsize=512)
def _spectrum(term: str, length: int, tau0_s: float, tau_c_s: float) -> np.ndarray:
    return term_spectrum(term, np.fft.rfftfreq(length), tau0_s, tau_c_s=tau_c_s)


@lru_cache(maxsize=64)
def _resonance_spectrum(length: int, rate_hz: float, f0_hz: float, width_hz: float
                        ) -> np.ndarray:
    """Two-sided PSD per unit normalised frequency of a unit-height resonance on the rfft
    grid of ``length`` (unit^2/Hz x rate: the module's convention)."""
    nu = np.fft.rfftfreq(length)
    return resonance_psd(nu * rate_hz, 1.0, f0_hz, width_hz, rate_hz) * rate_hz


@lru_cache(maxsize=512)
def _weights_fft(m: int, length: int) -> np.ndarray:
    return np.fft.rfft(_allan_weights(m, length))


def _overlap(n1: int, n2: int, d: np.ndarray) -> np.ndarray:
    """Number of (i, j) with 0 <= i < n1, 0 <= j < n2, j - i = d."""
    lo = np.maximum(0, -d)
    hi = np.minimum(n1, n2 - d)
    return np.maximum(hi - lo, 0).astype(np.float64)


def _pair_cov(m1: int, m2: int, n1: int, n2: int, amp2: Mapping[str, float], rate_hz: float,
              tau_c_s: float, bandwidth_hz: float, filter_order: int,
              resonance: tuple[float, float]) -> tuple[float, float, float]:
    """(Cov11, Cov22, Cov12) up to a common factor for the pair (m1, m2)."""
    s = 1
    while 8 * (m1 + m2) // s > FFT_MAX and 2 * s <= min(m1, m2):
        s *= 2
    m1s, m2s, rate = m1 // s, m2 // s, rate_hz / s
    n1s, n2s = max(n1 // s, 1), max(n2 // s, 1)
    length = 1 << int(np.ceil(np.log2(8 * (m1s + m2s) + 64)))
    nu = np.fft.rfftfreq(length)
    tau0 = 1.0 / rate
    spec = np.zeros(nu.size)
    for term in _STOCHASTIC:
        a2 = float(amp2.get(term, 0.0))
        if a2 > 0 and (term != "markov" or tau_c_s > 0):
            spec += a2 * _spectrum(term, length, tau0, tau_c_s)
    height = float(amp2.get("resonance", 0.0))
    if s == 1 and height > 0 and resonance[1] > 0:
        spec += height * _resonance_spectrum(length, rate_hz, *resonance)
    if s == 1:
        spec *= filter_gain2(nu, bandwidth_hz, filter_order, rate_hz)
    spec += float(amp2.get("output_white", 0.0)) / tau0  # white after the filter
    w1 = _weights_fft(m1s, length)
    w2 = _weights_fft(m2s, length)
    d = np.fft.fftfreq(length, 1.0 / length).astype(np.int64)
    out = []
    for wa, wb, na, nb in ((w1, w1, n1s, n1s), (w2, w2, n2s, n2s), (w1, w2, n1s, n2s)):
        c = np.fft.irfft(spec * wa * np.conj(wb), n=length)
        out.append(float(np.sum(_overlap(na, nb, d) * c * c)) / (2.0 * na * nb))
    return out[0], out[1], out[2]


def oavar_correlation(m: np.ndarray, n_terms: np.ndarray, amp2: Mapping[str, float],
                      rate_hz: float, *, tau_c_s: float = 0.0, bandwidth_hz: float = 0.0,
                      filter_order: int = 1, resonance: tuple[float, float] = (0.0, 0.0)
                      ) -> np.ndarray:
    """Correlation matrix of the OAVAR estimates at averaging factors ``m``.

    Args:
        m: averaging factors (samples).
        n_terms: number of overlapping terms of each estimate (Stable32 "#": N - 2m).
        amp2: squared amplitudes of the model's stochastic terms by term name
            (``white`` N^2, ``flicker`` B^2, ``random_walk`` K^2, ``quantization`` Q^2,
            ``markov`` sigma^2; ``resonance`` its PSD height), model units.
        rate_hz: sample rate; tau_c_s: Markov correlation time; bandwidth_hz/filter_order:
            the output low-pass; resonance: the resonance's (centre, width) in Hz.
    """
    m = np.asarray(m, dtype=np.int64)
    k = m.size
    corr = np.eye(k)
    if not any(float(amp2.get(t, 0.0)) > 0 for t in (*_STOCHASTIC, "output_white", "resonance")):
        return corr
    for i in range(k):
        for j in range(i + 1, k):
            if max(m[i], m[j]) > MAX_RATIO * min(m[i], m[j]):
                continue
            c11, c22, c12 = _pair_cov(int(m[i]), int(m[j]), int(n_terms[i]), int(n_terms[j]),
                                      amp2, rate_hz, tau_c_s, bandwidth_hz, filter_order,
                                      resonance)
            if c11 > 0 and c22 > 0:
                corr[i, j] = corr[j, i] = min(c12 / np.sqrt(c11 * c22), 0.999)
    return nearest_correlation(corr)


CORR_EIG_FLOOR = 1e-6
"""Smallest eigenvalue :func:`nearest_correlation` leaves in a correlation matrix."""


def nearest_correlation(corr: np.ndarray) -> np.ndarray:
    """``corr`` made positive definite: eigenvalues floored at CORR_EIG_FLOOR, then the
    diagonal rescaled to one (unchanged when it already is).

    The pairs left at zero beyond MAX_RATIO and the 0.999 clip are approximations that
    can leave a slightly negative eigenvalue (Samsung S5 accelerometer, 15 taus of a
    Markov + random-walk structure: -0.018), and the noise fit's Cholesky factorisation of
    the covariance then failed with a traceback (``imubench fit`` on a real record)."""
    w, v = np.linalg.eigh(0.5 * (corr + corr.T))
    if w.min() >= CORR_EIG_FLOOR:
        return corr
    c = (v * np.maximum(w, CORR_EIG_FLOOR)) @ v.T
    d = np.sqrt(np.diag(c))
    return np.asarray(c / np.outer(d, d))


def oavar_edf(m: np.ndarray, n_terms: np.ndarray, amp2: Mapping[str, float], avar: np.ndarray,
              rate_hz: float, *, tau_c_s: float = 0.0, bandwidth_hz: float = 0.0,
              filter_order: int = 1, resonance: tuple[float, float] = (0.0, 0.0)
              ) -> np.ndarray:
    """EDF of the OAVAR estimates under the model: 2 A_i^2 / Var(A_i) (SP 1065 eq. 44).

    ``avar`` is the model AVAR A_i at the points, ``Var`` the diagonal of the module's
    covariance (arguments as :func:`oavar_correlation`). Unlike the Greenhall-Riley EDF of
    a single identified power law it holds for mixtures (white + flicker at the shortest
    taus, flicker + random walk at the longest). inf where the model has no stochastic
    term.
    """
    m = np.asarray(m, dtype=np.int64)
    out = np.full(m.size, np.inf)
    if not any(float(amp2.get(t, 0.0)) > 0 for t in (*_STOCHASTIC, "output_white", "resonance")):
        return out
    for i in range(m.size):
        c11, _, _ = _pair_cov(int(m[i]), int(m[i]), int(n_terms[i]), int(n_terms[i]), amp2,
                              rate_hz, tau_c_s, bandwidth_hz, filter_order, resonance)
        if c11 > 0:
            out[i] = 2.0 * float(avar[i]) ** 2 / c11
    return out


__all__ = ["FFT_MAX", "MAX_RATIO", "oavar_correlation", "oavar_edf"]
