"""Exact Gaussian likelihood of differenced block means (the low-frequency part of ``exact``).

The random walk's information sits in the lowest ~10 Fourier frequencies of a record
(3 h at 100 Hz: K dominates flicker below ~7e-4 Hz). The Whittle likelihood treats those
ordinates as independent exponentials with the tapered expected periodogram; with so few
of them its finite-sample loss is large (measured spread of ln K 0.34 against a
Cramer-Rao bound of 0.22). Here the low-frequency content is fitted with the *exact*
Gaussian likelihood instead, on a series short enough for an O(n^2) Toeplitz solver.

**Block means.** The record is averaged in blocks of m samples, Y_i = (1/m) sum_{t<m}
y_{im+t}, and differenced, D_i = Y_{i+1} - Y_i. D is a zero-sum linear functional of y,
D_i = sum_s w_s y_{im+s} with w = (-1, ..., -1, 1, ..., 1)/m (2m weights), so for a process
with stationary increments and generalized autocovariance G (``kernels.gacv_unit``; for
flicker and random walk minus the structure function, defined up to a constant that the
zero-sum weights cancel)

    gamma_D(k) = Cov(D_0, D_k) = sum_{s,t} w_s w_t G(km + t - s)
               = sum_{|l| < 2m} r(l) G(|km + l|),   r(l) = sum_s w_s w_{s+l}.

gamma_D(0) = 2 AVAR(m tau0) (the Allan variance is half the variance of the difference of
adjacent means, NIST SP 1065 eq. 9), and the expression is the time-domain form of
gamma_D(k) = 2 int S_y(f) |W(f)|^2 cos(2 pi f k m tau0) df. It is exact for the sampled
processes of the model file, term by term, filter included (G_f = G * rho,
``kernels.apply_filter``).

**Likelihood.** D is stationary and Gaussian, so -log L = 1/2 [log det Gamma + D'
Gamma^{-1} D] (+ const) with Gamma Toeplitz. It is evaluated with the Durbin-Levinson
recursion (Brockwell & Davis 1991, *Time Series: Theory and Methods*, sec. 5.2, 8.7): the
one-step prediction errors e_t and their variances v_t give -log L = 1/2 sum_t (log v_t +
e_t^2 / v_t), O(n^2) operations and O(n) memory.
"""

from __future__ import annotations

import math

import numpy as np

from imubench.noisefit.kernels import apply_filter, filter_autocorrelation, gacv_unit

MAX_BLOCKS: int = 2000
"""Block means per record at most: m = ceil(n / MAX_BLOCKS). 3 h at 100 Hz gives m = 540
(5.4 s, Nyquist 0.09 Hz, far above the random walk's band, ~7e-4 Hz). The likelihood
costs O(MAX_BLOCKS^2) per evaluation. Cramer-Rao spread of ln K at the bench
configuration (all terms free): 0.221 at m = 200, 0.226 at m = 400, 0.230 at m = 540,
against 0.217 for the whole record; 0.216 at m = 540 with N known (docs/noise-fit.md)."""


def block_length(n_samples: int) -> int:
    """Samples per block for a record of ``n_samples`` (see :data:`MAX_BLOCKS`)."""
    return max(1, math.ceil(n_samples / MAX_BLOCKS))


def block_increments(y: np.ndarray, m: int) -> np.ndarray:
    """D_i = Y_{i+1} - Y_i of the means Y_i of consecutive m-sample blocks (tail dropped)."""
    n_blocks = y.size // m
    means = y[: n_blocks * m].reshape(n_blocks, m).mean(axis=1)
    return np.diff(means)


def weight_autocorrelation(m: int) -> np.ndarray:
    """r(l), l = -(2m-1)..(2m-1), of the weights w = (-1_m, 1_m)/m (module docstring)."""
    w = np.concatenate([-np.ones(m), np.ones(m)]) / m
    return np.correlate(w, w, mode="full")


def acv_from_gacv(g: np.ndarray, m: int, n_lags: int) -> np.ndarray:
    """gamma_D(k), k = 0..n_lags-1, from G(0..) (needs len(g) >= (n_lags + 1) m + m)."""
    r = weight_autocorrelation(m)
    lags = np.arange(-(2 * m - 1), 2 * m)
    out = np.empty(n_lags)
    chunk = max(1, 2_000_000 // lags.size)
    for start in range(0, n_lags, chunk):
        k = np.arange(start, min(start + chunk, n_lags))
        out[start:start + k.size] = g[np.abs(k[:, None] * m + lags[None, :])] @ r
    return out


def term_acv(term: str, m: int, n_lags: int, rate_hz: float, *, tau_c_s: float = 0.0,
             bandwidth_hz: float = 0.0, filter_order: int = 1) -> np.ndarray:
    """gamma_D of one term at unit amplitude (``output_white`` is white after the filter)."""
    filtered = bandwidth_hz > 0 and term != "output_white"
    rho = (filter_autocorrelation(bandwidth_hz, filter_order, rate_hz) if filtered
           else np.ones(1))
    kmax = (n_lags + 2) * m + rho.size
    base = "white" if term == "output_white" else term
    g = gacv_unit(base, kmax, 1.0 / rate_hz, tau_c_s=tau_c_s)
    g = apply_filter(g, rho, multiplicative=base == "markov")
    return acv_from_gacv(g, m, n_lags)


def toeplitz_nll(acv: np.ndarray, x: np.ndarray) -> np.ndarray:
    """-log L (without n/2 log 2 pi) of x ~ N(0, Toeplitz(acv)), by Durbin-Levinson.

    ``acv`` is one autocovariance (n,) or a batch (P, n) evaluated in one pass (the loop
    over t is shared, which is most of the cost). With v_0 = gamma(0),
    phi_{t,t} = (gamma(t) - sum_j phi_{t-1,j} gamma(t-j)) / v_{t-1},
    phi_{t,j} = phi_{t-1,j} - phi_{t,t} phi_{t-1,t-j}, v_t = v_{t-1} (1 - phi_{t,t}^2),
    e_t = x_t - sum_j phi_{t,j} x_{t-j}: -log L = 1/2 sum_t (log v_t + e_t^2 / v_t).
    +inf where Gamma is not positive definite.
    """
    g = np.atleast_2d(np.asarray(acv, dtype=np.float64))
    n = x.size
    phi = np.zeros((g.shape[0], n))
    v = g[:, 0].copy()
    with np.errstate(divide="ignore", invalid="ignore"):
        total = np.log(v) + x[0] ** 2 / v
        rev_g = g[:, ::-1]
        rev_x = x[::-1]
        for t in range(1, n):
            head = phi[:, : t - 1]
            a = (g[:, t] - np.einsum("ij,ij->i", head, rev_g[:, n - t: n - 1])) / v
            phi[:, : t - 1] = head - a[:, None] * head[:, ::-1]
            phi[:, t - 1] = a
            v = v * (1.0 - a * a)
            e = x[t] - phi[:, :t] @ rev_x[n - t: n]
            total += np.log(v) + e * e / v
    out = 0.5 * total
    out[~np.isfinite(out) | ~(g[:, 0] > 0)] = np.inf
    return out if np.ndim(acv) == 2 else out[:1]


TREND_ONLY = 1e-3
"""Increments ``dx`` whose standard deviation is at most this share of their mean are a
trend alone (a temperature that only drifts; its rounding leaves ~1e-5): no slope is
fitted beside the constant (:func:`imubench.gap.curves.gls_slopes`,
:func:`imubench.noisefit.temperature.fit_temperature_response`)."""


def only_trend(dx: np.ndarray) -> bool:
    """The regressor's increments are a constant (its levels a straight line): its slope
    cannot be told from the trend fitted beside it (:data:`TREND_ONLY`)."""
    return bool(float(np.std(dx)) <= TREND_ONLY * abs(float(np.mean(dx))))


def gls_fit(dys: np.ndarray, x: np.ndarray, chol: tuple[np.ndarray, bool]
            ) -> tuple[np.ndarray, np.ndarray]:
    """Generalized-least-squares coefficients (p, k) of each row of ``dys`` (k, n) on the
    columns of the design ``x`` (n, p), with noise covariance ``chol`` (:func:`scipy.
    linalg.cho_factor` of the model's), and their standard errors (p, k), each row's
    variance factor ``s^2 = e' C^-1 e / (n - p)`` at least 1 (the covariance is the
    model's own scale: noisier data widen the error, quieter data never narrow it below
    the model's); Aitken (1935), Proc. R. Soc. Edinb. 55, 42-48. NaN where the design is
    singular or a coefficient's variance is not positive."""
    from scipy.linalg import cho_solve

    nan = np.full((x.shape[1], len(dys)), np.nan)
    cx = cho_solve(chol, x)
    info = x.T @ cx
    if not (np.all(np.isfinite(info)) and np.linalg.det(info) > 0):
        return nan, nan
    inv = np.linalg.inv(info)
    var = np.diag(inv)
    if not np.all(var > 0):
        return nan, nan
    coef = inv @ (cx.T @ dys.T)  # (p, k)
    e = dys - (x @ coef).T
    s2 = np.einsum("kn,nk->k", e, cho_solve(chol, e.T)) / max(dys.shape[1] - x.shape[1], 1)
    return coef, np.sqrt(np.maximum(s2, 1.0)[None, :] * var[:, None])


__all__ = [
    "MAX_BLOCKS",
    "acv_from_gacv",
    "block_increments",
    "block_length",
    "gls_fit",
    "only_trend",
    "term_acv",
    "toeplitz_nll",
    "weight_autocorrelation",
]
