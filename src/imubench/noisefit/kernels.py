"""Exact Allan variance of sampled noise terms, through an optional output filter.

Every noise term of the model file (``docs/noise-model.md``) is described here by its
*generalized autocovariance* ``G(k)`` at sample lag k (for stationary terms the
autocovariance; for terms with stationary increments, minus the structure function
``D(k) = 1/2 E[(y_{i+k} - y_i)^2]``, which gives the same Allan variance because the
Allan weights sum to zero). For the m-sample Allan variance (tau = m tau0)::

    AVAR(m) = 1/2 E[(ybar_2 - ybar_1)^2]
            = (1/m^2) [ sum_{|k|<m} (m - |k|) G(k)  -  sum_{k=1}^{2m-1} (m - |k - m|) G(k) ]

(the time-domain form of AVAR = 2 int S_y(f) sin^4(pi f tau) / (pi f tau)^2 df for
sampled data: IEEE Std 952-1997 Annex C; NIST SP 1065 section 3.1; Percival & Guttorp
1994). ``G`` of each term, with unit-free lag k and tau0 = 1/rate (s):

================  ==========================================  ===========================
term              G(k) (k >= 0, G(-k) = G(k))                 AVAR (no filter)
================  ==========================================  ===========================
white N           N^2/tau0 [k = 0]                            N^2/tau  (exact)
flicker B         -(2 B^2/pi) sum_{j<k} 1/(2j+1)              -> (2 ln2/pi) B^2
random walk K     -K^2 tau0 (k - 1/3) / 2 for k >= 1, 0 at 0  K^2 tau/3  (exact)
ramp R            -(R tau0 k)^2 / 2                           R^2 tau^2/2  (exact)
quantization Q    2 Q^2/tau0^2 [k=0], -Q^2/tau0^2 [|k|=1]     3 Q^2/tau^2  (exact)
Gauss-Markov      sigma^2 phi^k, phi = exp(-tau0/tau_c)       -> IEEE 952 C.6
sine A, f0        A^2/2 cos(2 pi f0 tau0 k)                   A^2 sin^4/(m sin(pi f0 tau0))^2
outliers l, s     l tau0 s^2 [k = 0]                          l s^2 tau0/tau
================  ==========================================  ===========================

Flicker: the Kasdin-Walter discrete 1/f process of the simulator has the two-sided PSD
B^2 / (2 |sin(pi nu)|) in normalised frequency nu, so D(k) = B^2 int_0^1/2 (1 - cos 2 pi nu
k)/sin(pi nu) dnu, and D(k+1) - D(k) = 2 B^2 int_0^1/2 sin((2k+1) pi nu) dnu = 2 B^2 /
((2k + 1) pi): the sum above, exact for the sampled process. Random walk: the simulator's
sample is the interval mean of a Wiener rate, Var(ybar_{i+k} - ybar_i) = K^2 tau0 (k - 1/3).

``output_white`` (model key) is white noise added after the output filter: N^2/tau.

Resonance (model keys ``resonance_freq_hz``, ``resonance_width_hz``, ``resonance_height``):
narrowband noise of one-sided PSD ``h L(f)``, a pair of Lorentzian lines at +-f0 of value 1
at f0 (the simulator's damped-cosine process, :func:`lsm6ds_sim.noise.resonance_shape`);
its AVAR is linear in the height h itself (:data:`HEIGHT_TERMS`) and the Gauss-Markov
closed form at its complex pole (:func:`resonance_avar`).

Output filter (model keys ``bandwidth_hz``, ``filter_order``): the Butterworth low-pass of
the simulator (scipy.signal.butter, bilinear with prewarping) with impulse response h and
rho(j) = sum_i h_i h_{i+j}; the filtered term has G_f = G * rho (a convolution), which is
the discrete-time version of multiplying the spectrum by |H(f)|^2.

Spectra (for the estimator covariance of :mod:`imubench.noisefit.covariance`), two-sided,
variance per unit normalised frequency nu in (-1/2, 1/2): white N^2/tau0; flicker
B^2/(2|sin pi nu|); random walk c (1/(2 sin^2 pi nu) - 1/3) with c = K^2 tau0/2;
quantization 4 Q^2 sin^2(pi nu)/tau0^2; Gauss-Markov sigma^2 (1 - phi^2)/|1 - phi
e^{-2 pi i nu}|^2; outliers l tau0 s^2; all times |H|^2.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache

import numpy as np
from lsm6ds_sim.noise import resonance_drive, resonance_shape
from scipy.signal import butter, fftconvolve, lfilter

LINEAR_TERMS: tuple[str, ...] = (
    "white", "flicker", "random_walk", "ramp", "quantization", "markov", "sine",
    "output_white",
)
"""Terms whose AVAR is linear in one squared amplitude (markov/sine given their time/freq)."""

AMPLITUDE_KEY: dict[str, str] = {
    "white": "white",
    "flicker": "flicker",
    "random_walk": "random_walk",
    "ramp": "ramp",
    "quantization": "quantization",
    "markov": "markov_sigma",
    "sine": "sine_amplitude",
    "output_white": "output_white",
    "resonance": "resonance_height",
}
"""Model-file key of each term's amplitude (AVAR is proportional to its square, except
for :data:`HEIGHT_TERMS`, where it is proportional to the key's value)."""

HEIGHT_TERMS: frozenset[str] = frozenset({"resonance"})
"""Terms whose linear coefficient is the model key's value itself (the resonance's peak
PSD height, unit^2/Hz), not its square."""


def key_value(term: str, coefficient: float) -> float:
    """The model key's value of ``term`` from its linear AVAR coefficient: the square root
    of it (a squared amplitude), or the coefficient itself for :data:`HEIGHT_TERMS`;
    a negative coefficient counts as 0."""
    c = max(float(coefficient), 0.0)
    return c if term in HEIGHT_TERMS else math.sqrt(c)


def _lags(kmax: int) -> np.ndarray:
    return np.arange(kmax + 1, dtype=np.float64)


def gacv_unit(term: str, kmax: int, tau0_s: float, *, tau_c_s: float = 0.0,
              f0_hz: float = 0.0) -> np.ndarray:
    """G(k), k = 0..kmax, of ``term`` with unit amplitude (see the module table)."""
    k = _lags(kmax)
    g = np.zeros(kmax + 1)
    if term == "white":
        g[0] = 1.0 / tau0_s
    elif term == "flicker":
        steps = 2.0 / (math.pi * (2.0 * k[:-1] + 1.0))
        g[1:] = -np.cumsum(steps)
    elif term == "random_walk":
        g[1:] = -0.5 * tau0_s * (k[1:] - 1.0 / 3.0)
    elif term == "ramp":
        g = -0.5 * (tau0_s * k) ** 2
    elif term == "quantization":
        g[0] = 2.0 / tau0_s**2
        if kmax >= 1:
            g[1] = -1.0 / tau0_s**2
    elif term == "markov":
        if not tau_c_s > 0:
            raise ValueError("markov term needs tau_c_s > 0")
        g = np.exp(-k * tau0_s / tau_c_s)
    elif term == "sine":
        g = 0.5 * np.cos(2.0 * math.pi * f0_hz * tau0_s * k)
    elif term == "outliers":
        g[0] = tau0_s
    else:
        raise ValueError(f"unknown term {term!r}")
    return g


@lru_cache(maxsize=64)
def filter_autocorrelation(bandwidth_hz: float, order: int, rate_hz: float) -> np.ndarray:
    """rho(j), j = 0..J, of the simulator's output low-pass (sum_j rho(j) over all j = 1).

    The impulse response is followed until its tail energy is below 1e-14 of the total.
    Returns ``[1.0]`` when there is no filter (bandwidth 0 or not below Nyquist).
    """
    if bandwidth_hz <= 0 or bandwidth_hz >= 0.5 * rate_hz:
        return np.ones(1)
    b, a = butter(int(order), bandwidth_hz, btype="low", fs=rate_hz)
    n = 256
    while True:
        imp = np.zeros(n)
        imp[0] = 1.0
        h = lfilter(b, a, imp)
        e = np.cumsum(h[::-1] ** 2)[::-1]
        if e[-min(n // 4, 64)] < 1e-14 * e[0] or n > (1 << 22):
            break
        n *= 4
    keep = int(np.nonzero(e > 1e-16 * e[0])[0][-1]) + 1
    h = h[:keep]
    rho = fftconvolve(h, h[::-1], mode="full")[keep - 1:]  # = np.correlate(h, h), O(n log n)
    return rho


def apply_filter(g: np.ndarray, rho: np.ndarray, *, multiplicative: bool = False) -> np.ndarray:
    """G_f(k) = sum_j rho(|j|) G(|k - j|) for k = 0..len(g)-1-J (J = len(rho)-1).

    The convolution is computed exactly up to lag K1 = 8 J + 64. Beyond it G_f - G is a
    constant for G linear or quadratic in k (random walk, ramp; white and quantization are
    0 there) and G_f / G a constant for G geometric (Gauss-Markov): ``multiplicative``
    picks the ratio form; flicker's log-like G takes the offset form with an error of
    order (J/k)^2 of its local curvature, negligible in the AVAR.
    """
    if rho.size == 1:
        return g
    j = rho.size - 1
    n_out = g.size - j
    k1 = min(8 * j + 64, n_out - 1)
    full_rho = np.concatenate([rho[:0:-1], rho])
    sym = np.concatenate([g[j:0:-1], g[: k1 + j + 1]])  # G(-J..k1+J) using symmetry
    head = fftconvolve(sym, full_rho, mode="valid")  # k = 0..k1
    out = g[:n_out].copy()
    out[: k1 + 1] = head
    if k1 + 1 < n_out:
        if multiplicative:
            # G geometric (G(k) = phi^k, k >= 0): G_f(k) = s phi^(k-J) for k >= J exactly,
            # s = sum_l rho(|l|) phi^(J-l), l = -J..J (every power <= 1: no overflow). The
            # ratio head[-1] / G(k1) instead divides the convolution's round-off by a G(k1)
            # that can be ~1e-90, which gave a Markov column ~1e60 too large and a
            # chi-squared that jumped with 1-ulp changes of the data.
            out[k1 + 1:] = _geometric_tail_sum(g, rho) * g[k1 + 1 - j: n_out - j]
        else:
            out[k1 + 1:] += head[-1] - g[k1]
    return out


def _geometric_tail_sum(g: np.ndarray, rho: np.ndarray) -> float:
    """s = sum_{l=-J..J} rho(|l|) phi^(J-l) for a geometric G (G(k) = G(1)^k, G(0) = 1).

    Then G_f(k) = s G(k - J) for every k >= J: the filtered Gauss-Markov autocovariance
    beyond the filter's length, exact and without dividing by a vanishing G(k).
    """
    j = rho.size - 1
    full_rho = np.concatenate([rho[:0:-1], rho])  # rho(|l|), l = -J..J
    powers = g[: 2 * j + 1][::-1] if g.size > 2 * j else (
        float(g[1]) ** np.arange(2 * j, -1, -1, dtype=np.float64))
    return float(full_rho @ powers)


def _prefix_sums(g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(p0, p1): p0[n] = sum_{k=1}^{n} G(k), p1[n] = sum_{k=1}^{n} k G(k)."""
    k = np.arange(g.size, dtype=np.float64)
    return (np.concatenate([[0.0], np.cumsum(g[1:])]),
            np.concatenate([[0.0], np.cumsum(k[1:] * g[1:])]))


def _sum_variance(g0: float, p0: np.ndarray, p1: np.ndarray, h: np.ndarray) -> np.ndarray:
    """V(h) = h G(0) + 2 sum_{l=1}^{h-1} (h - l) G(l) for integer h >= 1."""
    hf = h.astype(np.float64)
    return hf * g0 + 2.0 * (hf * p0[h - 1] - p1[h - 1])


def sum_variance(g: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Variance (unit^2) of a sum of ``h`` consecutive samples, from G(0..max h - 1):
    the structure function of the integrated series (0 at h = 0)."""
    h = np.asarray(h, dtype=np.int64)
    if h.size and g.size < int(h.max()):
        raise ValueError("G must extend to lag max(h) - 1")
    p0, p1 = _prefix_sums(g)
    return np.where(h > 0, _sum_variance(float(g[0]), p0, p1, np.maximum(h, 1)), 0.0)


def avar_from_gacv(g: np.ndarray, m: np.ndarray) -> np.ndarray:
    """AVAR(m) from G(0..2 max(m)) by the module formula (prefix sums, O(1) per m)."""
    m = np.asarray(m, dtype=np.int64)
    if m.size == 0:
        return np.zeros(0)
    if g.size < 2 * int(m.max()):
        raise ValueError("G must extend to lag 2 max(m) - 1")
    p0, p1 = _prefix_sums(g)
    mf = m.astype(np.float64)
    s1 = _sum_variance(g[0], p0, p1, m)
    s2 = p1[m] + 2.0 * mf * (p0[2 * m - 1] - p0[m]) - (p1[2 * m - 1] - p1[m])
    return (s1 - s2) / mf**2


def term_avar(term: str, m: Sequence[int] | np.ndarray, rate_hz: float, *,
              tau_c_s: float = 0.0, f0_hz: float = 0.0, bandwidth_hz: float = 0.0,
              filter_order: int = 1, width_hz: float = 0.0) -> np.ndarray:
    """AVAR at averaging factors ``m`` of ``term`` with unit amplitude, filter included
    (``f0_hz``: the sine's or the resonance's frequency; ``width_hz``: the resonance's
    -3 dB width)."""
    m = np.asarray(m, dtype=np.int64)
    tau0 = 1.0 / rate_hz
    if term == "resonance":
        return resonance_avar(m, rate_hz, f0_hz, width_hz, bandwidth_hz, filter_order)
    if term == "output_white":  # white noise added after the filter: N^2/tau exactly
        return rate_hz / m.astype(np.float64)
    rho = filter_autocorrelation(float(bandwidth_hz), int(filter_order), float(rate_hz))
    kmax = 2 * int(m.max()) + rho.size
    if term == "markov" and rho.size == 1:
        return _markov_closed(m, math.exp(-tau0 / tau_c_s))
    if term == "sine":  # a sinusoid only changes amplitude (and phase) in a linear filter
        gain = float(filter_gain2(np.array([f0_hz * tau0]), bandwidth_hz, filter_order,
                                  rate_hz)[0])
        return gain * _sine_closed(m, f0_hz * tau0)
    if rho.size == 1:
        return avar_from_gacv(_gacv_cached(term, kmax, tau0, tau_c_s, f0_hz), m)
    return _filtered_avar(term, m, rate_hz, rho, tau_c_s=tau_c_s, f0_hz=f0_hz)


def _filtered_avar(term: str, m: np.ndarray, rate_hz: float, rho: np.ndarray, *,
                   tau_c_s: float, f0_hz: float) -> np.ndarray:
    """AVAR of a filtered term without the O(max m) filtered autocovariance.

    :func:`apply_filter` gives G_f = r G + c + d with d(k) = 0 for k > K1 (r = 1, c the
    offset for the additive form; c = 0, r the ratio for the multiplicative one). The
    AVAR is linear in G and zero for a constant G (the Allan weights sum to zero), so
    AVAR_f(m) = r AVAR_G(m) + AVAR_d(m): the unfiltered AVAR (cached) plus that of a
    sequence of K1 + 1 lags. Equal to ``avar_from_gacv(apply_filter(G, rho), m)``.
    """
    j = rho.size - 1
    k1 = 8 * j + 64
    kmax = 2 * int(m.max()) + rho.size
    if k1 + j + 1 >= kmax - j:  # short records: the direct form is as cheap
        g = _gacv_cached(term, kmax, 1.0 / rate_hz, tau_c_s, f0_hz)
        return avar_from_gacv(apply_filter(g, rho, multiplicative=term == "markov"), m)
    g = gacv_unit(term, k1 + j + 2, 1.0 / rate_hz, tau_c_s=tau_c_s, f0_hz=f0_hz)
    head = apply_filter(g, rho, multiplicative=term == "markov")[: k1 + 1]
    if term == "markov":
        if (g[1] / g[0]) ** (k1 - j) < MARKOV_TAIL_NEGLIGIBLE:
            # G_f(k) = s phi^(k - J) for k >= J with s <= sum |rho|
            # (:func:`_geometric_tail_sum`): beyond k1 it is below round-off of the head,
            # which is the whole autocovariance. Written as r G + d, r = s / phi^J is huge
            # and G_f the difference of two huge terms: tau_c 0.345 s beside an order-2
            # 0.2 Hz filter at 10 Hz (J ~ 300 lags, phi^J ~ 1e-38) gave AVARs of -2, 8, 4,
            # -8 and a chi2 that jumped by 9 between tau_c values one rounding apart
            # (Samsung S5 gy, a crash of the profile search)
            return _avar_short(head, m)
        # G_f(k) = r G(k) for k >= J with r = sum_l rho(|l|) phi^(-l) (see apply_filter);
        # from rho and phi, not head[-1] / G(k1) (round-off over a tiny G(k1)). Here
        # phi^J >= MARKOV_TAIL_NEGLIGIBLE^(1/7) (K1 - J = 7 J + 64): r is finite
        r, c = _geometric_tail_sum(g, rho) / g[j], 0.0
    else:
        r, c = 1.0, head[-1] - g[k1]
    d = head - r * g[: k1 + 1] - c
    base = _unfiltered_avar(term, m.tobytes(), rate_hz, tau_c_s, f0_hz)
    return r * base + _avar_short(d, m)


@lru_cache(maxsize=256)
def _unfiltered_avar(term: str, m_bytes: bytes, rate_hz: float, tau_c_s: float,
                     f0_hz: float) -> np.ndarray:
    m = np.frombuffer(m_bytes, dtype=np.int64)
    out = term_avar(term, m, rate_hz, tau_c_s=tau_c_s, f0_hz=f0_hz)
    out.flags.writeable = False
    return out


def _avar_short(d: np.ndarray, m: np.ndarray) -> np.ndarray:
    """:func:`avar_from_gacv` for G = d on lags 0..L and 0 beyond (prefix sums clipped)."""
    last = d.size - 1
    k = np.arange(d.size, dtype=np.float64)
    p0 = np.concatenate([[0.0], np.cumsum(d[1:])])
    p1 = np.concatenate([[0.0], np.cumsum(k[1:] * d[1:])])
    mf = m.astype(np.float64)

    def at(p: np.ndarray, idx: np.ndarray) -> np.ndarray:
        return p[np.minimum(idx, last)]

    s1 = mf * d[0] + 2.0 * (mf * at(p0, m - 1) - at(p1, m - 1))
    s2 = (at(p1, m) + 2.0 * mf * (at(p0, 2 * m - 1) - at(p0, m))
          - (at(p1, 2 * m - 1) - at(p1, m)))
    return (s1 - s2) / mf**2


MARKOV_TAIL_NEGLIGIBLE: float = 1e-17
"""phi^(K1 - J) below which a filtered Gauss-Markov autocovariance beyond the head
(lags 0..K1) is below the head's round-off and is left out (:func:`_filtered_avar`)."""
RESONANCE_TAIL: float = 1e-6
"""Least ``r^J`` (the resonance's decay over the output filter's length J) for which the
filtered resonance's autocovariance beyond lag J is taken in closed form; below it the
filtered autocovariance is summed directly up to its negligible lags."""


def _resonance_filtered(f0_hz: float, width_hz: float, bandwidth_hz: float,
                        filter_order: int, rate_hz: float
                        ) -> tuple[complex, float, complex | None, np.ndarray]:
    """(pole p, var, C, d) of the resonance of unit height through the output low-pass.

    The simulator's resonance (:class:`lsm6ds_sim.noise.Resonance`) is the real part of a
    complex AR(1) of pole ``p`` (:func:`lsm6ds_sim.noise.resonance_pole`): autocovariance
    ``G(k) = var Re(p^|k|)`` with ``var = s^2 / (1 - |p|^2)`` for unit height
    (:func:`lsm6ds_sim.noise.resonance_drive`). Through the output low-pass, ``G_f(k) =
    sum_l rho(|l|) G(k - l)`` (l = -J..J) equals ``var Re(C p^k)`` for k >= J with ``C =
    sum_l rho(|l|) p^-l``, so ``G_f(k) = var (Re(C p^k) + d(k))`` with ``d`` zero beyond
    lag J (no filter: C = 1, d = [0]). Where ``|p|^J`` < :data:`RESONANCE_TAIL` (C would
    be large and cancel), the resonance dies out within a few filter lengths: C is None
    and ``d`` is G_f / var itself up to the lag where ``|p|^k`` < 1e-20 (0 beyond).
    """
    pole, s2 = resonance_drive(f0_hz, width_hz, rate_hz)
    r = abs(pole)
    var = s2 / (1.0 - r * r)
    rho = filter_autocorrelation(float(bandwidth_hz), int(filter_order), float(rate_hz))
    j = rho.size - 1
    if j == 0:
        return pole, var, 1.0 + 0j, np.zeros(1)
    full_rho = np.concatenate([rho[:0:-1], rho])  # rho(|l|), l = -J..J
    closed = r**j >= RESONANCE_TAIL
    last = j if closed else j + math.ceil(math.log(1e-20) / math.log(r))
    lags = np.arange(-j, last + j + 1)
    head = np.convolve((pole ** np.abs(lags)).real, full_rho, mode="valid")  # 0..last
    if not closed:
        return pole, var, None, head
    c = complex(np.sum(full_rho * pole ** -np.arange(-j, j + 1)))
    return pole, var, c, head - (c * pole ** np.arange(j + 1)).real


def resonance_avar(m: Sequence[int] | np.ndarray, rate_hz: float, f0_hz: float,
                   width_hz: float, bandwidth_hz: float = 0.0, filter_order: int = 1
                   ) -> np.ndarray:
    """AVAR at averaging factors ``m`` of the resonance of unit height (1 unit^2/Hz).

    With G_f from :func:`_resonance_filtered`: the module's G(k) formula is linear in G, so
    the AVAR is ``var (Re(C A(p)) + A_d)``, ``A(phi)`` the Gauss-Markov closed form
    (:func:`_markov_closed`) at the complex ``phi = p`` and ``A_d`` that of the short
    sequence d (:func:`_avar_short`): exact, O(1) per m.
    """
    m = np.asarray(m, dtype=np.int64)
    pole, var, c, d = _resonance_filtered(f0_hz, width_hz, bandwidth_hz, filter_order,
                                          rate_hz)
    tail = 0.0 if c is None else (c * _markov_closed(m, pole)).real
    return var * (tail + _avar_short(d, m))


def resonance_gacv(kmax: int, rate_hz: float, f0_hz: float, width_hz: float,
                   bandwidth_hz: float = 0.0, filter_order: int = 1) -> np.ndarray:
    """G_f(k), k = 0..kmax, of the resonance of unit height through the output low-pass
    (:func:`_resonance_filtered`)."""
    pole, var, c, d = _resonance_filtered(f0_hz, width_hz, bandwidth_hz, filter_order,
                                          rate_hz)
    g = np.zeros(kmax + 1) if c is None else (c * pole ** np.arange(kmax + 1.0)).real
    n = min(d.size, kmax + 1)
    g[:n] += d[:n]
    return var * g


def resonance_psd(f_hz: np.ndarray, height: float, f0_hz: float, width_hz: float,
                  rate_hz: float) -> np.ndarray:
    """Two-sided PSD (unit^2/Hz) of the resonance at ``f_hz``, before the output filter:
    ``height L(f) / 2`` (height is the one-sided PSD at the centre f0)."""
    return 0.5 * height * resonance_shape(f_hz, f0_hz, width_hz, rate_hz)


def _sine_closed(m: np.ndarray, nu0: float) -> np.ndarray:
    """Unit-amplitude sampled sine: sin^4(pi nu0 m) / (m sin(pi nu0))^2, nu0 = f0 tau0.

    The module formula summed in closed form (equals lsm6ds_sim.noise.avar_sine_sampled).
    """
    mf = m.astype(np.float64)
    den = (mf * math.sin(math.pi * nu0)) ** 2
    if den.min() == 0.0:
        return np.zeros(m.size)
    return np.sin(math.pi * nu0 * mf) ** 4 / den


def _markov_closed(m: np.ndarray, phi: complex) -> np.ndarray:
    """The module formula summed in closed form for G(k) = phi^k (unit variance AR(1)).

    Complex ``phi`` gives a complex result, the AVAR of the complex G (the resonance's).

    sum_{k=1}^{m-1} (m-k) phi^k = phi (m (1-phi) - (1-phi^m)) / (1-phi)^2 and
    sum_{k=1}^{2m-1} (m-|k-m|) phi^k = phi (1-phi^m)^2 / (1-phi)^2.
    """
    mf = m.astype(np.float64)
    pm = phi**mf
    q = (1.0 - phi) ** 2
    s1 = mf + 2.0 * phi * (mf * (1.0 - phi) - (1.0 - pm)) / q
    s2 = phi * (1.0 - pm) ** 2 / q
    return (s1 - s2) / mf**2


@lru_cache(maxsize=32)
def _gacv_cached(term: str, kmax: int, tau0_s: float, tau_c_s: float, f0_hz: float
                 ) -> np.ndarray:
    g = gacv_unit(term, kmax, tau0_s, tau_c_s=tau_c_s, f0_hz=f0_hz)
    g.flags.writeable = False
    return g


def averaging_factors(tau_s: Sequence[float] | np.ndarray, rate_hz: float) -> np.ndarray:
    """m = round(tau_s * rate_hz), at least 1."""
    return np.maximum(np.rint(np.asarray(tau_s, dtype=float) * rate_hz), 1).astype(np.int64)


def term_spectrum(term: str, nu: np.ndarray, tau0_s: float, *, tau_c_s: float = 0.0) -> np.ndarray:
    """Two-sided PSD (unit amplitude) per unit normalised frequency nu (module docstring).

    ``ramp`` and ``sine`` are deterministic: 0 here (the covariance model leaves them out).
    At nu = 0 the walk-like spectra are set to 0 (the Allan filters vanish there).
    """
    s = np.abs(np.sin(np.pi * nu))
    out = np.zeros_like(nu, dtype=np.float64)
    nz = s > 0
    if term == "white":
        out[:] = 1.0 / tau0_s
    elif term == "flicker":
        out[nz] = 1.0 / (2.0 * s[nz])
    elif term == "random_walk":
        out[nz] = 0.5 * tau0_s * (1.0 / (2.0 * s[nz] ** 2) - 1.0 / 3.0)
    elif term == "quantization":
        out = 4.0 * s**2 / tau0_s**2
    elif term == "markov":
        phi = math.exp(-tau0_s / tau_c_s)
        out = (1.0 - phi**2) / np.abs(1.0 - phi * np.exp(-2j * np.pi * nu)) ** 2
    elif term == "outliers":
        out[:] = tau0_s
    elif term in ("ramp", "sine"):
        pass
    else:
        raise ValueError(f"unknown term {term!r}")
    return out


def filter_gain2(nu: np.ndarray, bandwidth_hz: float, order: int, rate_hz: float) -> np.ndarray:
    """|H(e^{2 pi i nu})|^2 of the output low-pass (1 when there is none)."""
    if bandwidth_hz <= 0 or bandwidth_hz >= 0.5 * rate_hz:
        return np.ones_like(nu, dtype=np.float64)
    b, a = butter(int(order), bandwidth_hz, btype="low", fs=rate_hz)
    z = np.exp(-2j * np.pi * nu)
    num = np.polyval(b[::-1], z)
    den = np.polyval(a[::-1], z)
    return np.abs(num / den) ** 2


__all__ = [
    "AMPLITUDE_KEY",
    "HEIGHT_TERMS",
    "LINEAR_TERMS",
    "apply_filter",
    "avar_from_gacv",
    "averaging_factors",
    "filter_autocorrelation",
    "filter_gain2",
    "gacv_unit",
    "key_value",
    "resonance_avar",
    "resonance_gacv",
    "resonance_psd",
    "sum_variance",
    "term_avar",
    "term_spectrum",
]
