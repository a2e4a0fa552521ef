"""White + flicker + random-walk rate noise written directly with numpy, independent of
the project's simulator (``lsm6ds_sim``) and of the fit code: the round-trip reference of
``tests/test_whittle.py`` and ``bench/bench_fit_roundtrip.py``.

Conventions (the meaning the fit gives N, B, K; ``imubench.noisefit.units``), tau0 = 1/rate:

* white, density N (unit/sqrt(Hz)): iid normal samples of std N / sqrt(tau0), so
  AVAR = N^2 / tau.
* flicker, coefficient B (unit): increments d_k = y_k - y_{k-1} are the fractionally
  differenced noise of order d = -1/2, y = B (1 - z^-1)^(-1/2) w, whose increments have the
  two-sided PSD B^2 |1 - e^{-2 pi i nu}| = 2 B^2 sin(pi |nu|) per unit normalised frequency
  nu. So y has the (generalised) PSD B^2 / (2 sin(pi |nu|)): one-sided S_y(f) = B^2 / (pi f)
  for f << rate, h_-1 = B^2 / pi, AVAR floor 2 ln2 h_-1 = (2 ln2 / pi) B^2, ADEV floor
  0.664 B (NIST SP 1065 Table 3; IEEE Std 952-1997 C.3). The increments are drawn exactly
  by circulant embedding (Davies & Harte 1987, Biometrika 74, 95-101; Wood & Chan 1994)
  from their autocovariance, the ARFIMA(0, d, 0) recursion (Hosking 1981, Biometrika 68,
  165-176): gamma(0) = Gamma(1 - 2d) / Gamma(1 - d)^2 = 4 / pi,
  gamma(k) = gamma(k - 1) (k - 1 + d) / (k - d). The embedding is non-negative definite
  for d < 0 (all gamma(k), k >= 1, negative; Craigmile 2003, J. Time Ser. Anal. 24).
  The level is a stationary-increment process (infinitely long past), not started at rest.
* random walk, coefficient K (unit/sqrt(s)): each sample is the mean over its interval of
  a Wiener process of intensity K^2, drawn jointly with the interval's end value (mean
  W_start + K sqrt(tau0) (z1/2 + z2/sqrt(12)), end W_start + K sqrt(tau0) z1), so
  AVAR = K^2 tau / 3 exactly.
"""

from __future__ import annotations

import math

import numpy as np


def flicker_increment_acv(n: int) -> np.ndarray:
    """Autocovariance (lags 0..n-1) of the d = -1/2 fractional noise with unit innovations."""
    k = np.arange(1, n, dtype=np.float64)
    ratios = (k - 1.5) / (k + 0.5)
    return (4.0 / math.pi) * np.concatenate([[1.0], np.cumprod(ratios)])


def circulant_gaussian(acv: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One exact draw of length len(acv) of a stationary Gaussian series (Davies-Harte)."""
    n = acv.size
    row = np.concatenate([acv, acv[-2:0:-1]])  # circulant of size 2(n - 1)
    lam = np.fft.rfft(row).real
    if lam.min() < -1e-9 * lam.max():
        raise ValueError("circulant embedding is not non-negative definite")
    m = row.size
    z = np.fft.irfft(np.sqrt(np.maximum(lam, 0.0) / m)
                     * _hermitian_normal(m, rng), m) * m
    return z[:n]


def _hermitian_normal(m: int, rng: np.random.Generator) -> np.ndarray:
    """rfft-layout complex normals such that irfft(.) * m has covariance of unit weights."""
    half = m // 2 + 1
    z = (rng.standard_normal(half) + 1j * rng.standard_normal(half)) / math.sqrt(2.0)
    z[0] = rng.standard_normal()
    if m % 2 == 0:
        z[-1] = rng.standard_normal()
    return z


def white_flicker_walk(n: int, rate_hz: float, *, white: float, flicker: float,
                       random_walk: float, seed: int) -> np.ndarray:
    """n rate samples (unit) of white N + flicker B + random walk K (module docstring)."""
    rng = np.random.default_rng(seed)
    tau0 = 1.0 / rate_hz
    y = rng.standard_normal(n) * (white / math.sqrt(tau0))
    if flicker > 0:
        y += flicker * np.cumsum(circulant_gaussian(flicker_increment_acv(n), rng))
    if random_walk > 0:
        z = rng.standard_normal((n, 2))
        s = random_walk * math.sqrt(tau0)
        starts = np.concatenate([[0.0], np.cumsum(s * z[:-1, 0])])
        y += starts + s * (0.5 * z[:, 0] + z[:, 1] / math.sqrt(12.0))
    return y


__all__ = ["circulant_gaussian", "flicker_increment_acv", "white_flicker_walk"]
