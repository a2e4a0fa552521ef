"""Streaming generators of the IEEE Std 952 noise terms of one inertial channel.

Every generator produces the *rate-like* sample sequence ``y_k`` (dps or g) of one term,
spaced ``dt_s``, and keeps just enough state to continue it:

* deterministic from its seed (each term of each channel has its own
  ``numpy.random.SeedSequence(seed, spawn_key=(channel, term))`` stream, so switching one
  term on or off never changes the others);
* seamless: ``generate(n1)`` then ``generate(n2)`` returns bit for bit what
  ``generate(n1 + n2)`` returns (random numbers are drawn in the same order, cumulative
  sums and recursions carry their state explicitly, flicker is computed in fixed internal
  blocks independent of the caller's chunking);
* vectorised: every call is a few numpy operations on the whole chunk.

Allan variance of each term (y = rate data at sample interval tau0, tau = m tau0; IEEE Std
952-1997 Annex C, El-Sheimy, Hou & Niu 2008, IEEE TIM 57(1) Table 1):

==================  ===========================  =========================================
term                parameter                    AVAR sigma^2(tau)
==================  ===========================  =========================================
white               N  unit/sqrt(Hz)             N^2 / tau
flicker             B  unit                      (2 ln2 / pi) B^2   (ADEV 0.664 B)
random walk         K  unit/sqrt(s)              K^2 tau / 3
ramp                R  unit/s                    R^2 tau^2 / 2
quantization        Q  unit s                    3 Q^2 / tau^2
Gauss-Markov        sigma, tau_c                 (q tau_c)^2/tau [1 - tau_c/(2 tau)
                                                 (3 - 4 e^{-tau/tau_c} + e^{-2 tau/tau_c})],
                                                 q = sigma sqrt(2 / tau_c)
sinusoid            A (peak), f0                 A^2 sin^4(pi f0 tau) / (pi f0 tau)^2
resonance           height h, f0, width w        2 int S(f) sin^4(pi f tau)/(pi f tau)^2 df,
                                                 S = h x resonance_shape; in closed form at
                                                 the complex pole: imubench.noisefit.
                                                 kernels.resonance_avar
outliers            rate lambda, std s           impulses: white-like, lambda s^2 tau0 / tau
==================  ===========================  =========================================

The analytic functions are :func:`avar_white` ... :func:`avar_sine`.
"""

from __future__ import annotations

import abc
import functools
import math
import threading

import numpy as np
import scipy.fft
from scipy.signal import lfilter

from .errors import ModelError

TERM_IDS: dict[str, int] = {
    "white": 0,
    "flicker": 1,
    "random_walk": 2,
    "ramp": 3,
    "quantization": 4,
    "markov": 5,
    "sine": 6,
    "outliers": 7,
    "output_white": 8,
    "resonance": 9,
}
"""Stable index of each term in the seed's spawn key (never renumber: seeds would change)."""

FLICKER_MAX_TAPS: int = 1 << 22
"""Cap on the flicker filter length (4.2 M samples: 11.2 h at 104 Hz)."""

FLICKER_MAX_BLOCK_RATIO: int = 3
"""Largest overlap-save block, in filter lengths: a block of ``nfft = taps - 1 + block``
FFT points yields ``block`` samples, so long streams cost 4/3 FFT points per sample at
the cap, and a record of ``taps`` samples is served by one block of ``2 taps``."""


@functools.lru_cache(maxsize=4)
def _kasdin_walter_spectrum(taps: int, nfft: int) -> np.ndarray:
    """rfft (complex64, read-only) of the Kasdin-Walter alpha = 1 impulse response
    ``h_0 = 1, h_k = h_{k-1} (k - 1/2) / k`` (k < taps), zero-padded to ``nfft``; shared by
    every channel with the same length (it holds no random state)."""
    k = np.arange(1, taps, dtype=np.float64)
    h = np.concatenate([[1.0], np.cumprod((k - 0.5) / k)])
    spectrum = scipy.fft.rfft(h, nfft).astype(np.complex64)
    spectrum.flags.writeable = False
    return spectrum


def term_rng(seed: int, channel_index: int, term: str, sub: int = 0) -> np.random.Generator:
    """The independent random stream of one term of one channel."""
    ss = np.random.SeedSequence(int(seed), spawn_key=(channel_index, TERM_IDS[term], sub))
    return np.random.Generator(np.random.PCG64(ss))


class TermGenerator(abc.ABC):
    """One noise term of one channel, generated in seamless chunks."""

    @abc.abstractmethod
    def generate(self, n: int, dt_s: float, t_s: np.ndarray) -> np.ndarray:
        """The next ``n`` samples (float64), spaced ``dt_s``; ``t_s`` their times (s)."""

    def prepare(self) -> None:  # noqa: B027 - most terms have nothing to prepare
        """Do the slow set-up now (before a real-time stream), without drawing samples."""


class WhiteNoise(TermGenerator):
    """Angle/velocity random walk: white rate noise of density ``N`` (unit/sqrt(Hz)).

    ``y_k = N / sqrt(tau0) z_k``, ``z_k ~ N(0, 1)`` iid: the mean of m samples has variance
    N^2/(m tau0), so AVAR(tau) = N^2/tau exactly at every m (IEEE 952 C.1). Its one-sided
    PSD is 2 N^2 (unit^2/Hz) on (0, 1/(2 tau0)).
    """

    def __init__(self, density: float, rng: np.random.Generator) -> None:
        self.density = float(density)
        self.rng = rng

    def generate(self, n: int, dt_s: float, t_s: np.ndarray) -> np.ndarray:
        return self.rng.standard_normal(n) * (self.density / math.sqrt(dt_s))


class FlickerNoise(TermGenerator):
    """Bias instability: flicker (1/f) rate noise of coefficient ``B`` (unit).

    Kasdin & Walter (1992), "Discrete simulation of power law noise", Proc. IEEE FCS,
    eq. for alpha = 1: ``y = B (1 - z^-1)^(-1/2) w`` with ``w ~ N(0, 1)``, realised as the
    FIR filter ``h_0 = 1, h_k = h_{k-1} (k - 1/2) / k`` applied to white noise started at
    rest (zero past), as Kasdin-Walter do. Its two-sided PSD is
    ``B^2 tau0 / (2 sin(pi f tau0))``, i.e. one-sided ``S_y(f) = h_-1 / f`` with
    ``h_-1 = B^2 / pi`` for f << 1/tau0, hence AVAR = 2 ln2 h_-1 = (2 ln2 / pi) B^2
    (NIST SP 1065 Table 3; IEEE 952 C.3 with S = B^2 / (2 pi f)). The level does not depend
    on tau0.

    The filter is exact (not a few-octave approximation) for the first ``taps`` samples:
    the 1/f spectrum holds from 1/(taps tau0) to Nyquist. Beyond ``taps`` samples the
    impulse response is truncated at ``taps`` and the spectrum flattens below
    1/(taps tau0). ``taps`` comes from the caller's record length (``simulate``) or
    duration hint (``SensorPhysics(duration_hint_s=...)``), capped at
    :data:`FLICKER_MAX_TAPS`.

    Streaming: FFT overlap-save in fixed internal blocks of ``block = nfft - taps + 1``
    samples (``block`` about the expected record length ``length_hint``, between ``taps``
    and :data:`FLICKER_MAX_BLOCK_RATIO` x ``taps``) carrying the last
    ``taps - 1`` white samples; outputs are served from the current block, so the result
    never depends on how callers chunk their requests. The white samples are drawn in
    float64 (the same stream as ever); the convolution runs in single precision
    (float32 / complex64 FFTs, 3-4x faster than double): its rounding error is about
    1e-6 of the output's rms, a white floor 120 dB below the term, far below an int16
    LSB (tested against the direct FIR sum).

    A block is a few seconds of FFTs at high rates, so :meth:`prepare` computes the first
    one ahead and, once half of a block has been served, the next one is computed in a
    background thread (numpy and scipy.fft release the GIL): a real-time reader of the
    simulated chip is never stalled by it. Blocks are still computed one at a time, in
    order, from the same random stream, so the output does not change.
    """

    def __init__(
        self,
        coefficient: float,
        rng: np.random.Generator,
        taps: int,
        length_hint: int | None = None,
    ) -> None:
        self.coefficient = float(coefficient)
        self.rng = rng
        self.taps = max(2, min(int(taps), FLICKER_MAX_TAPS))
        L = self.taps
        want = L if length_hint is None else int(length_hint)
        want = min(max(want, L), FLICKER_MAX_BLOCK_RATIO * L)
        self.nfft = scipy.fft.next_fast_len(max(L - 1 + want, 1 << 12), real=True)
        self.block = self.nfft - L + 1
        self.H = _kasdin_walter_spectrum(L, self.nfft)
        self.history = np.zeros(L - 1, dtype=np.float32)
        self.buffer = np.empty(0, dtype=np.float32)
        self.pos = 0
        self._ahead: tuple[threading.Thread, list[tuple[np.ndarray, np.ndarray]]] | None = None

    def _compute(self, history: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The block following ``history``: (output samples, the next history)."""
        w = self.rng.standard_normal(self.block)
        x = np.empty(self.nfft, dtype=np.float32)
        x[: self.taps - 1] = history
        x[self.taps - 1 :] = w
        y = scipy.fft.irfft(scipy.fft.rfft(x) * self.H, self.nfft)
        buffer = y[self.taps - 1 :]
        buffer *= np.float32(self.coefficient)
        return buffer, x[len(x) - (self.taps - 1) :].copy()

    def _prefetch(self) -> None:
        """Start computing the block after the current one in a background thread."""
        result: list[tuple[np.ndarray, np.ndarray]] = []
        history = self.history
        thread = threading.Thread(target=lambda: result.append(self._compute(history)),
                                  name="flicker-block", daemon=True)
        thread.start()
        self._ahead = (thread, result)

    def _next_block(self) -> None:
        if self._ahead is not None:
            thread, result = self._ahead
            thread.join()
            self._ahead = None
            self.buffer, self.history = result[0]
        else:
            self.buffer, self.history = self._compute(self.history)
        self.pos = 0

    def prepare(self) -> None:
        if self.pos >= len(self.buffer) and self._ahead is None:
            self._next_block()

    def generate(self, n: int, dt_s: float, t_s: np.ndarray) -> np.ndarray:
        out = np.empty(n)
        done = 0
        while done < n:
            if self._ahead is None and self.pos > len(self.buffer) // 2:
                self._prefetch()
            if self.pos >= len(self.buffer):
                self._next_block()
            take = min(n - done, len(self.buffer) - self.pos)
            out[done : done + take] = self.buffer[self.pos : self.pos + take]
            self.pos += take
            done += take
        return out


class RandomWalk(TermGenerator):
    """Rate random walk of coefficient ``K`` (unit/sqrt(s)), generated exactly.

    The true rate is a Wiener process ``W`` with ``E[dW^2] = K^2 dt``; each sample is the
    mean of ``W`` over its interval (an integrating sensor), drawn jointly and exactly with
    the next end value: ``W_{k+1} = W_k + K sqrt(tau0) z1``,
    ``y_k = W_k + K sqrt(tau0) (z1/2 + z2/(2 sqrt 3))`` (the Brownian integral over
    [0, tau0] has variance tau0^3/3 and covariance tau0^2/2 with the end value). Means of
    m samples are then exact interval means, so AVAR(tau) = K^2 tau / 3 at every m
    (IEEE 952 C.4), with no discretisation term. W_0 = 0.
    """

    def __init__(self, coefficient: float, rng: np.random.Generator) -> None:
        self.coefficient = float(coefficient)
        self.rng = rng
        self.level = 0.0

    def generate(self, n: int, dt_s: float, t_s: np.ndarray) -> np.ndarray:
        z = self.rng.standard_normal((n, 2))
        s = self.coefficient * math.sqrt(dt_s)
        steps = s * z[:, 0]
        ends = np.cumsum(np.concatenate([[self.level], steps]))
        starts = ends[:-1]
        self.level = float(ends[-1])
        return starts + s * (0.5 * z[:, 0] + z[:, 1] / (2.0 * math.sqrt(3.0)))


class Ramp(TermGenerator):
    """Rate ramp ``R`` (unit/s): ``y_k = R t_k`` (deterministic; AVAR R^2 tau^2/2, C.5)."""

    def __init__(self, slope: float) -> None:
        self.slope = float(slope)

    def generate(self, n: int, dt_s: float, t_s: np.ndarray) -> np.ndarray:
        return self.slope * t_s


class Quantization(TermGenerator):
    """Angle (velocity) quantization noise of coefficient ``Q`` (unit s).

    The integrated output (angle) carries an independent quantization error ``e_k``
    uniform on an interval of width ``S = sqrt(12) Q`` (variance Q^2; IEEE 952 C.2:
    Q = S / sqrt(12) for a quantum S), and the rate sample is the angle difference over
    the sample interval: ``y_k = (e_k - e_{k-1}) / tau0``. The mean of m samples is
    ``(e_{j+m} - e_j) / tau`` and the Allan variance is
    ``1/2 E[(e_{2m} - 2 e_m + e_0)^2] / tau^2 = 3 Q^2 / tau^2`` exactly for every m >= 1.
    """

    def __init__(self, coefficient: float, rng: np.random.Generator) -> None:
        self.coefficient = float(coefficient)
        self.rng = rng
        self.half_width = math.sqrt(3.0) * self.coefficient
        self.previous = self.rng.uniform(-self.half_width, self.half_width)

    def generate(self, n: int, dt_s: float, t_s: np.ndarray) -> np.ndarray:
        e = self.rng.uniform(-self.half_width, self.half_width, n)
        prev = np.concatenate([[self.previous], e[:-1]])
        if n:
            self.previous = float(e[-1])
        return (e - prev) / dt_s


class GaussMarkov(TermGenerator):
    """First-order Gauss-Markov (Ornstein-Uhlenbeck) rate of std ``sigma``, time ``tau_c``.

    Exact discretisation at the sample instants (AR(1)): ``x_k = phi x_{k-1} +
    sigma sqrt(1 - phi^2) z_k``, ``phi = exp(-tau0/tau_c)``, started in the stationary
    distribution. The analytic AVAR above (IEEE 952 C.6) is that of the continuous process;
    the sampled process differs from it by O(tau0/tau_c) at the smallest taus. Its ADEV
    peaks near tau = 1.89 tau_c at 0.437 q sqrt(tau_c), q = sigma sqrt(2/tau_c).
    """

    def __init__(self, sigma: float, tau_c_s: float, rng: np.random.Generator) -> None:
        self.sigma = float(sigma)
        self.tau_c_s = float(tau_c_s)
        self.rng = rng
        self.state = self.sigma * float(self.rng.standard_normal())

    def generate(self, n: int, dt_s: float, t_s: np.ndarray) -> np.ndarray:
        phi = math.exp(-dt_s / self.tau_c_s)
        w = self.rng.standard_normal(n) * (
            self.sigma * math.sqrt(-math.expm1(-2 * dt_s / self.tau_c_s))
        )
        y, _ = lfilter([1.0], [1.0, -phi], w, zi=[phi * self.state])
        if n:
            self.state = float(y[-1])
        return y


class Sinusoid(TermGenerator):
    """``A sin(2 pi f0 t + phi0)``, phi0 uniform from the seed (AVAR in the module table)."""

    def __init__(self, amplitude: float, freq_hz: float, rng: np.random.Generator) -> None:
        self.amplitude = float(amplitude)
        self.freq_hz = float(freq_hz)
        self.phase0 = float(rng.uniform(0.0, 2.0 * math.pi))

    def generate(self, n: int, dt_s: float, t_s: np.ndarray) -> np.ndarray:
        cycles = np.mod(self.freq_hz * t_s, 1.0)
        return self.amplitude * np.sin(2.0 * math.pi * cycles + self.phase0)


def resonance_pole(f0_hz: float, width_hz: float, rate_hz: float) -> complex:
    """Pole ``p = r exp(i w0)`` of the resonance's complex AR(1), ``w0 = 2 pi f0/fs``.

    The line ``1 / |1 - p e^{-i w}|^2 = 1 / (1 - 2 r cos(w - w0) + r^2)`` is a Lorentzian
    near ``w0`` (its discrete, periodic form). Its half-power points lie at ``cos(dw) =
    1 - (1 - r)^2 / (2 r)``; with ``dw = pi width / fs`` (points ``width_hz`` apart) that is
    ``r^2 - 2 (2 - cos dw) r + 1 = 0``, so ``r = c - sqrt(c^2 - 1)``, ``c = 2 - cos dw``
    (the root below 1).

    Raises:
        ModelError: f0_hz not in (0, fs/2), or width_hz not in (0, fs/2) (the Nyquist
            frequency is only known here, at simulation time).
    """
    nyquist = 0.5 * rate_hz
    if not 0.0 < f0_hz < nyquist:
        raise ModelError(f"resonance_freq_hz = {f0_hz:g} Hz must lie between 0 and the "
                         f"Nyquist frequency {nyquist:g} Hz of the {rate_hz:g} Hz output")
    if not 0.0 < width_hz < nyquist:
        raise ModelError(f"resonance_width_hz = {width_hz:g} Hz must lie between 0 and the "
                         f"Nyquist frequency {nyquist:g} Hz of the {rate_hz:g} Hz output")
    c = 2.0 - math.cos(math.pi * width_hz / rate_hz)
    r = c - math.sqrt(c * c - 1.0)
    return complex(r * math.cos(2.0 * math.pi * f0_hz / rate_hz),
                   r * math.sin(2.0 * math.pi * f0_hz / rate_hz))


def _line_pair(f_hz: np.ndarray, pole: complex, rate_hz: float) -> np.ndarray:
    """``1/|1 - p e^{-iw}|^2 + 1/|1 - conj(p) e^{-iw}|^2`` at ``w = 2 pi f/fs``."""
    r, w0 = abs(pole), float(np.angle(pole))
    w = 2.0 * np.pi * np.asarray(f_hz, dtype=float) / rate_hz
    return (1.0 / (1.0 - 2.0 * r * np.cos(w - w0) + r * r)
            + 1.0 / (1.0 - 2.0 * r * np.cos(w + w0) + r * r))


def resonance_shape(f_hz: np.ndarray, f0_hz: float, width_hz: float, rate_hz: float
                    ) -> np.ndarray:
    """One-sided PSD of the resonance of unit height at ``f_hz``: exactly 1 at f0_hz.

    The PSD of :class:`Resonance`'s output is the line of :func:`resonance_pole` at +f0
    plus its mirror at -f0 (the real part of a complex process), normalised here to 1 at
    the centre; the mirror adds ``(1 - r)^2 / (1 - 2 r cos 2 w0 + r^2)`` there (< 1 % for
    a width under a fifth of the centre frequency).
    """
    pole, s2 = resonance_drive(f0_hz, width_hz, rate_hz)
    return _line_pair(f_hz, pole, rate_hz) * (s2 / rate_hz)


def resonance_drive(f0_hz: float, width_hz: float, rate_hz: float) -> tuple[complex, float]:
    """(pole p, s^2) of :class:`Resonance` at unit height (1 unit^2/Hz at f0_hz).

    ``s^2`` is the variance of each part of the complex drive: the one-sided PSD of the
    real part is ``s^2 / fs`` times the line pair of :func:`resonance_shape`, so ``s^2 =
    fs / pair(f0)``; the output's variance is ``s^2 / (1 - |p|^2)``.
    """
    pole = resonance_pole(f0_hz, width_hz, rate_hz)
    return pole, rate_hz / float(_line_pair(np.array([f0_hz]), pole, rate_hz)[0])


class Resonance(TermGenerator):
    """Narrowband noise of autocovariance ``var r^|k| cos(w0 k)``: a damped cosine.

    The real part of the complex AR(1) ``z_k = p z_{k-1} + e_k`` with the pole ``p = r
    e^{i w0}`` of :func:`resonance_pole` and ``e_k`` circular complex white noise (real
    and imaginary parts independent, each of variance ``s^2``): the classical random-phase
    oscillator whose coherence decays as ``exp(-pi width t)``. Its autocovariance is
    ``s^2 r^|k| cos(w0 k) / (1 - r^2)`` and its spectrum a pair of Lorentzian lines at
    +-f0 of full width at half maximum ``resonance_width_hz`` (Papoulis & Pillai,
    Probability, Random Variables and Stochastic Processes, 4th ed.: the spectrum of
    ``exp(-a|tau|) cos(w0 tau)``; here in discrete time, :func:`resonance_shape`).

    ``s^2`` is set so that the one-sided PSD at ``resonance_freq_hz`` is the height ``h``
    = ``resonance_height`` (unit^2/Hz): the one-sided PSD is ``s^2 / fs`` times the line
    pair of :func:`resonance_shape`. The variance is about ``h pi/2 width`` (a Lorentzian
    line's area). The state starts in its stationary distribution (each part of ``z``
    N(0, s^2 / (1 - r^2))), so the first samples are not a transient; a change of the
    sample interval recomputes the pole and draws a new stationary state.
    """

    def __init__(self, height: float, f0_hz: float, width_hz: float,
                 rng: np.random.Generator) -> None:
        self.height = float(height)
        self.f0_hz = float(f0_hz)
        self.width_hz = float(width_hz)
        self.rng = rng
        self.dt_s: float | None = None
        self.pole = 0j
        self.std = 0.0
        self.z = 0j

    def _design(self, dt_s: float) -> None:
        self.pole, s2 = resonance_drive(self.f0_hz, self.width_hz, 1.0 / dt_s)
        self.dt_s, self.std = dt_s, math.sqrt(self.height * s2)
        re, im = self.rng.standard_normal(2) * (self.std / math.sqrt(1.0 - abs(self.pole) ** 2))
        self.z = complex(re, im)

    def generate(self, n: int, dt_s: float, t_s: np.ndarray) -> np.ndarray:
        if dt_s != self.dt_s:
            self._design(dt_s)
        e = self.rng.standard_normal(2 * n).view(np.complex128) * self.std
        z, _ = lfilter([1.0], [1.0, -self.pole], e, zi=[self.pole * self.z])
        if n:
            self.z = complex(z[-1])
        return np.ascontiguousarray(z.real)


class Outliers(TermGenerator):
    """Poisson impulses: ``k ~ Poisson(rate tau0)`` per sample, each impulse N(0, s^2).

    A sample hit by k impulses gets ``s sqrt(k) z`` (the sum of k normal amplitudes).
    Counts and amplitudes use separate streams so chunking never reorders draws.
    """

    def __init__(
        self,
        rate_hz: float,
        amplitude: float,
        rng_count: np.random.Generator,
        rng_amplitude: np.random.Generator,
    ) -> None:
        self.rate_hz = float(rate_hz)
        self.amplitude = float(amplitude)
        self.rng_count = rng_count
        self.rng_amplitude = rng_amplitude

    def generate(self, n: int, dt_s: float, t_s: np.ndarray) -> np.ndarray:
        k = self.rng_count.poisson(self.rate_hz * dt_s, n)
        out = np.zeros(n)
        hit = np.nonzero(k)[0]
        if len(hit):
            z = self.rng_amplitude.standard_normal(len(hit))
            out[hit] = self.amplitude * np.sqrt(k[hit]) * z
        return out


# --------------------------------------------------------------------- analytic AVAR
def avar_white(tau_s: np.ndarray, N: float) -> np.ndarray:
    """N^2 / tau (IEEE 952 C.1)."""
    return N**2 / np.asarray(tau_s, dtype=float)


def avar_flicker(tau_s: np.ndarray, B: float) -> np.ndarray:
    """(2 ln2 / pi) B^2 (IEEE 952 C.3, for tau >> 1/f_high)."""
    return np.full(np.shape(tau_s), 2.0 * math.log(2.0) / math.pi * B**2)


def avar_random_walk(tau_s: np.ndarray, K: float) -> np.ndarray:
    """K^2 tau / 3 (IEEE 952 C.4)."""
    return K**2 * np.asarray(tau_s, dtype=float) / 3.0


def avar_ramp(tau_s: np.ndarray, R: float) -> np.ndarray:
    """R^2 tau^2 / 2 (IEEE 952 C.5)."""
    return R**2 * np.asarray(tau_s, dtype=float) ** 2 / 2.0


def avar_quantization(tau_s: np.ndarray, Q: float) -> np.ndarray:
    """3 Q^2 / tau^2 (IEEE 952 C.2)."""
    return 3.0 * Q**2 / np.asarray(tau_s, dtype=float) ** 2


def avar_markov(tau_s: np.ndarray, sigma: float, tau_c_s: float) -> np.ndarray:
    """(q tau_c)^2/tau [1 - tau_c/(2 tau)(3 - 4 e^{-tau/tau_c} + e^{-2 tau/tau_c})] (C.6).

    q = sigma sqrt(2 / tau_c) is the driving white-noise amplitude.
    """
    tau = np.asarray(tau_s, dtype=float)
    q = sigma * math.sqrt(2.0 / tau_c_s)
    x = tau / tau_c_s
    return (q * tau_c_s) ** 2 / tau * _markov_bracket(x)


MARKOV_SERIES_X = 0.01
"""Below this tau / tau_c the bracket of C.6 is summed as its Taylor series."""


def _markov_bracket(x: np.ndarray) -> np.ndarray:
    """``1 - (3 - 4 e^-x + e^-2x) / (2 x)`` of IEEE 952 C.6. As written it loses every
    digit for small x (the bracket is ~x^2 / 3: at tau / tau_c = 1e-5, the shortest tau of
    a 104 Hz record beside a 1000 s tau_c, it was 60 % off, and below it negative), so
    for x < :data:`MARKOV_SERIES_X` it is summed as the series ``sum_{k>=3} (-1)^k (4 -
    2^k) x^(k-1) / (2 k!)`` = x^2/3 - x^3/4 + 7 x^4/60 - ... (terms to k = 12: the next
    is below 1e-16 of the first there)."""
    x = np.asarray(x, dtype=float)
    small = x < MARKOV_SERIES_X
    xs = np.where(small, x, 0.0)
    series = np.zeros_like(xs)
    for k in range(12, 2, -1):  # smallest terms first
        series += (-1) ** k * (4.0 - 2.0**k) / (2.0 * math.factorial(k)) * xs ** (k - 1)
    xd = np.where(small, 1.0, x)
    direct = 1.0 - (3.0 - 4.0 * np.exp(-xd) + np.exp(-2.0 * xd)) / (2.0 * xd)
    return np.where(small, series, direct)


def avar_sine(tau_s: np.ndarray, A: float, f0_hz: float) -> np.ndarray:
    """A^2 sin^4(pi f0 tau) / (pi f0 tau)^2 (IEEE 952 C.7, continuous-time averages)."""
    x = math.pi * f0_hz * np.asarray(tau_s, dtype=float)
    return A**2 * np.sin(x) ** 4 / x**2


def avar_sine_sampled(tau_s: np.ndarray, A: float, f0_hz: float, tau0_s: float) -> np.ndarray:
    """Same for means of m = tau/tau0 samples: A^2 sin^4(pi f0 tau) / (m sin(pi f0 tau0))^2.

    Derived like C.7 with the discrete Dirichlet kernel in place of the sinc; tends to
    :func:`avar_sine` as tau0 -> 0.
    """
    tau = np.asarray(tau_s, dtype=float)
    m = np.round(tau / tau0_s)
    return A**2 * np.sin(math.pi * f0_hz * tau) ** 4 / (m * math.sin(math.pi * f0_hz * tau0_s)) ** 2


def markov_adev_peak(sigma: float, tau_c_s: float) -> tuple[float, float]:
    """(tau_s, adev) of the Gauss-Markov ADEV maximum: about (1.89 tau_c, 0.437 q sqrt(tau_c)).

    Located numerically on :func:`avar_markov` (x = tau/tau_c maximises
    (1 - (3 - 4e^-x + e^-2x)/(2x))/x at x = 1.8926).
    """
    from scipy.optimize import minimize_scalar

    res = minimize_scalar(
        lambda x: -avar_markov(np.array([x * tau_c_s]), sigma, tau_c_s)[0],
        bounds=(0.5, 5.0),
        method="bounded",
        options={"xatol": 1e-9},
    )
    return float(res.x * tau_c_s), float(math.sqrt(-res.fun))


__all__ = [
    "FLICKER_MAX_TAPS",
    "TERM_IDS",
    "FlickerNoise",
    "GaussMarkov",
    "Outliers",
    "Quantization",
    "Ramp",
    "RandomWalk",
    "Resonance",
    "Sinusoid",
    "TermGenerator",
    "WhiteNoise",
    "avar_flicker",
    "avar_markov",
    "avar_quantization",
    "avar_ramp",
    "avar_random_walk",
    "avar_sine",
    "avar_sine_sampled",
    "avar_white",
    "markov_adev_peak",
    "resonance_drive",
    "resonance_pole",
    "resonance_shape",
    "term_rng",
]
