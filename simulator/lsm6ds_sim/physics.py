"""Sensor physics of a 6-axis IMU: true input, sensor errors, temperature, noise, output filter.

:class:`SensorPhysics` is what the simulated chip samples: ``generate(n, dt_s)`` returns the
next ``n`` samples of what the sensing elements output *before* the chip's quantisation
and saturation. The signal chain of channel i of a sensor (gyro: u = angular rate in dps;
accel: u = specific force in g), all terms optional (model keys in brackets)::

    dT   = T(t) - temp_ref
    s    = 1 + scale_error + scale_temp_coeff dT + scale_temp_coeff2 dT^2
    x    = u_i + nonlinearity u_i^2 + sum_{j != i} cross_j u_j
    y    = s x + bias + temp_coeff dT + temp_coeff2 dT^2
           + (gyro only) sum_j g_sensitivity_j f_j        f = true specific force (g)
           + noise terms (white, flicker, random_walk, ramp, quantization, markov, sine,
             resonance, outliers; see :mod:`lsm6ds_sim.noise`)
    out  = low-pass(y)   Butterworth of order filter_order, -3 dB at bandwidth_hz
                         (bilinear transform with prewarping, scipy.signal.butter), started
                         in steady state on the first sample; no filter if bandwidth_hz is 0
                         or not below the Nyquist frequency 1/(2 dt_s)
           + white noise of density output_white (after the filter)

The true input is constant between calls: a jig sets it with
:meth:`SensorPhysics.set_rate_dps` and :meth:`SensorPhysics.set_orientation`, and the die
temperature with :meth:`SensorPhysics.set_temperature` (e.g. a
:class:`~lsm6ds_sim.temperature.ChamberTemperature`). With no model the sensor is quiet
(no noise, +1 g on Z, 25 degC).

:func:`simulate` is the pure-numpy offline entry point (same numbers as a
``SensorPhysics`` with the same seed, generated in one call); :func:`quantize` and
:func:`quantize_counts` turn values into the chip's int16 output grid.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from lsm6ds.channels import CHANNELS
from scipy.signal import butter, lfilter, lfilter_zi

from .errors import ModelError
from .model import ChannelModel, NoiseModel
from .noise import (
    FlickerNoise,
    GaussMarkov,
    Outliers,
    Quantization,
    Ramp,
    RandomWalk,
    Resonance,
    Sinusoid,
    TermGenerator,
    WhiteNoise,
    term_rng,
)
from .temperature import TemperatureProfile, as_profile

DEFAULT_DURATION_HINT_S: float = 3.0 * 3600.0
"""Record length the streaming flicker generator is exact for, when nobody says (3 h)."""

INT16_MIN, INT16_MAX = -32768, 32767


@dataclass
class TrueSamples:
    """What the sensing elements output before quantisation and saturation.

    Attributes:
        gyro_dps: (n, 3) float64 angular rate X Y Z in dps.
        accel_g: (n, 3) float64 specific force X Y Z in g.
        temp_c: (n,) float64 die temperature in degC.
    """

    gyro_dps: np.ndarray
    accel_g: np.ndarray
    temp_c: np.ndarray


class ChannelNoise:
    """The sum of the noise terms of one channel (zero-mean terms plus ramp)."""

    def __init__(
        self,
        cm: ChannelModel,
        seed: int,
        channel_index: int,
        flicker_taps: int,
        flicker_length: int | None = None,
    ):
        self.terms: list[TermGenerator] = []
        i = channel_index
        if cm.white > 0:
            self.terms.append(WhiteNoise(cm.white, term_rng(seed, i, "white")))
        if cm.flicker > 0:
            self.terms.append(
                FlickerNoise(
                    cm.flicker, term_rng(seed, i, "flicker"), flicker_taps, flicker_length
                )
            )
        if cm.random_walk > 0:
            self.terms.append(RandomWalk(cm.random_walk, term_rng(seed, i, "random_walk")))
        if cm.ramp != 0:
            self.terms.append(Ramp(cm.ramp))
        if cm.quantization > 0:
            self.terms.append(Quantization(cm.quantization, term_rng(seed, i, "quantization")))
        if cm.markov_sigma > 0:
            self.terms.append(
                GaussMarkov(cm.markov_sigma, cm.markov_tau, term_rng(seed, i, "markov"))
            )
        if cm.sine_amplitude > 0:
            self.terms.append(Sinusoid(cm.sine_amplitude, cm.sine_freq, term_rng(seed, i, "sine")))
        if cm.resonance_height > 0:
            self.terms.append(Resonance(cm.resonance_height, cm.resonance_freq_hz,
                                        cm.resonance_width_hz, term_rng(seed, i, "resonance")))
        if cm.outlier_rate > 0 and cm.outlier_amplitude > 0:
            self.terms.append(
                Outliers(
                    cm.outlier_rate,
                    cm.outlier_amplitude,
                    term_rng(seed, i, "outliers", 0),
                    term_rng(seed, i, "outliers", 1),
                )
            )

    def generate(self, n: int, dt_s: float, t_s: np.ndarray) -> np.ndarray:
        out = np.zeros(n)
        for term in self.terms:
            out += term.generate(n, dt_s, t_s)
        return out

    def prepare(self) -> None:
        for term in self.terms:
            term.prepare()


class _OutputFilter:
    """Streaming Butterworth low-pass with explicit state (scipy lfilter ``zi``)."""

    def __init__(self, bandwidth_hz: float, order: int) -> None:
        self.bandwidth_hz = bandwidth_hz
        self.order = order
        self.dt_s: float | None = None
        self.ba: tuple[np.ndarray, np.ndarray] | None = None
        self.zi: np.ndarray | None = None
        self.last: float | None = None

    def apply(self, y: np.ndarray, dt_s: float) -> np.ndarray:
        if self.bandwidth_hz <= 0 or len(y) == 0:
            return y
        if dt_s != self.dt_s:
            self.dt_s = dt_s
            if self.bandwidth_hz >= 0.5 / dt_s:
                self.ba = None
            else:
                b, a = butter(self.order, self.bandwidth_hz, btype="low", fs=1.0 / dt_s)
                self.ba = (b, a)
                start = y[0] if self.last is None else self.last
                self.zi = lfilter_zi(b, a) * start
        if self.ba is None:
            self.last = float(y[-1])
            return y
        out, self.zi = lfilter(self.ba[0], self.ba[1], y, zi=self.zi)
        self.last = float(out[-1])
        return out


def _gravity_from(
    orientation: np.ndarray | Sequence[float] | Sequence[Sequence[float]],
) -> np.ndarray:
    arr = np.asarray(orientation, dtype=np.float64)
    if arr.shape == (3,):
        return arr.copy()
    if arr.shape == (3, 3):
        if not np.allclose(arr @ arr.T, np.eye(3), atol=1e-9):
            raise ModelError(
                "set_orientation: a 3x3 argument must be a rotation matrix (orthonormal);"
                " pass the sensor-to-world rotation, or a specific-force vector in g"
            )
        return arr.T @ np.array([0.0, 0.0, 1.0])
    raise ModelError(
        f"set_orientation: expected a (3,) specific-force vector in g or a (3, 3) rotation,"
        f" got shape {arr.shape}"
    )


class SensorPhysics:
    """The six sensing channels and the die temperature of one IMU.

    Args:
        model: the noise model (quiet when None).
        seed: seed of every random stream (each channel and term has its own substream).
        temperature: die temperature profile (a profile, a constant degC, a profile string
            for :func:`lsm6ds_sim.temperature.parse_profile`, or None for 25 degC).
        duration_hint_s: record length the flicker generator is exact for (its lowest
            frequency is 1/duration_hint_s; below it the spectrum flattens). Default 3 h.
        channels: generate noise only for these channels (others get the noise-free signal
            chain); default all six. The values of a channel never depend on this choice.
        rate_dps: initial true angular rate (sensor frame).
        gravity_g: initial specific force of a sensor at rest (sensor frame), default +1 g Z.
        noise_block: noise is generated ahead in blocks of at least this many samples
            (values do not depend on it; it only amortises per-call overhead).
    """

    def __init__(
        self,
        model: NoiseModel | None = None,
        seed: int = 0,
        *,
        temperature: TemperatureProfile | float | str | None = None,
        duration_hint_s: float = DEFAULT_DURATION_HINT_S,
        channels: Sequence[str] | None = None,
        rate_dps: Sequence[float] = (0.0, 0.0, 0.0),
        gravity_g: Sequence[float] = (0.0, 0.0, 1.0),
        noise_block: int = 1024,
    ) -> None:
        self.model = model if model is not None else NoiseModel.quiet()
        self.seed = int(seed)
        self.temperature = as_profile(temperature)
        if not duration_hint_s > 0:
            raise ModelError(f"SensorPhysics: duration_hint_s must be > 0, got {duration_hint_s}")
        self.duration_hint_s = float(duration_hint_s)
        wanted = CHANNELS if channels is None else tuple(channels)
        for ch in wanted:
            if ch not in CHANNELS:
                raise ModelError(f"SensorPhysics: unknown channel {ch!r}; use {CHANNELS}")
        self.noisy_channels = wanted
        self._output_white = {
            ch: WhiteNoise(self.model[ch].output_white,
                           term_rng(self.seed, CHANNELS.index(ch), "output_white"))
            for ch in wanted if self.model[ch].output_white > 0
        }
        self._rate = np.zeros(3)
        self._force = np.array([0.0, 0.0, 1.0])
        self.set_rate_dps(rate_dps)
        self.set_orientation(gravity_g)
        self._noise: dict[str, ChannelNoise] | None = None
        self._filters = {
            ch: _OutputFilter(self.model[ch].bandwidth_hz, self.model[ch].filter_order)
            for ch in CHANNELS
        }
        self.samples_generated = 0
        self._t_base_s = 0.0
        self._k_base = 0
        self._dt_s: float | None = None
        self.noise_block = int(noise_block)
        self._const = np.zeros(6)
        self._const_key: tuple[bytes, bytes] | None = None
        self._thermal: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._thermal_key: tuple[bytes, bytes] | None = None
        self._buf = np.empty((0, 0))
        self._buf_pos = 0
        self._buf_dt: float | None = None

    # ----------------------------------------------------------------- jig interface
    def set_rate_dps(self, xyz: Sequence[float] | np.ndarray) -> None:
        """True angular rate (dps) about sensor X Y Z from the next sample on."""
        arr = np.asarray(xyz, dtype=np.float64)
        if arr.shape != (3,):
            raise ModelError(f"set_rate_dps: expected 3 values (dps), got shape {arr.shape}")
        self._rate = arr.copy()

    def set_orientation(
        self, orientation: np.ndarray | Sequence[float] | Sequence[Sequence[float]]
    ) -> None:
        """Attitude of the sensor at rest, from the next sample on.

        Either a (3,) vector: the specific force in the sensor frame in g (what a perfect
        accelerometer reads; (0, 0, 1) flat and face up), or a (3, 3) rotation matrix
        ``R_ws`` taking sensor-frame vectors to a world frame whose Z points up, so the
        specific force is ``R_ws^T (0, 0, 1)`` g.
        """
        self._force = _gravity_from(orientation)

    def set_temperature(self, temperature: TemperatureProfile | float | str) -> None:
        """Die temperature profile from the next sample on (a profile, a constant degC or
        a profile string); profiles are functions of :attr:`time_s`, the simulated time
        of the samples since this physics started."""
        self.temperature = as_profile(temperature)

    @property
    def rate_dps(self) -> np.ndarray:
        return self._rate.copy()

    @property
    def specific_force_g(self) -> np.ndarray:
        return self._force.copy()

    @property
    def time_s(self) -> float:
        """Simulated time (s) of the next sample."""
        if self._dt_s is None:
            return self._t_base_s
        return self._t_base_s + (self.samples_generated - self._k_base) * self._dt_s

    # ----------------------------------------------------------------- generation
    def _take_noise(self, n: int, dt_s: float) -> tuple[list[int], np.ndarray] | None:
        """Noise of the next n samples, served from blocks of at least ``noise_block``:
        the channel columns (indices into :data:`CHANNELS`) that have noise terms and an
        (n, len(columns)) array, or None when no channel has any.

        Each term is a fixed function of the sample index (for a constant dt_s), so
        serving it from look-ahead blocks gives the same values as generating it per call,
        while the per-call cost of many small calls (a FIFO read loop) stays low. When
        dt_s changes, the unused look-ahead is discarded: the continuation is deterministic
        but skips those samples' random draws. Only the noisy channels are held (the gap
        diagnosis realises one channel of six: a (n, 6) buffer of zeros cost it a fifth of
        its time).
        """
        assert self._noise is not None
        noisy = [(CHANNELS.index(ch), cn) for ch, cn in self._noise.items() if cn.terms]
        if not noisy:
            return None
        cols = [i for i, _ in noisy]
        if self._buf_dt != dt_s:
            self._buf = np.empty((0, len(cols)))
            self._buf_pos = 0
            self._buf_dt = dt_s
        if self._buf_pos >= len(self._buf) and n >= self.noise_block:
            # the next block would be exactly these n samples: served without a copy
            return cols, self._noise_block(noisy, self.samples_generated, n, dt_s)
        out = np.empty((n, len(cols)))
        done = 0
        while done < n:
            if self._buf_pos >= len(self._buf):
                k = max(self.noise_block, n - done)
                first = self.samples_generated + done + (len(self._buf) - self._buf_pos)
                self._buf, self._buf_pos = self._noise_block(noisy, first, k, dt_s), 0
            take = min(n - done, len(self._buf) - self._buf_pos)
            out[done : done + take] = self._buf[self._buf_pos : self._buf_pos + take]
            self._buf_pos += take
            done += take
        return cols, out

    def _noise_block(self, noisy: list[tuple[int, ChannelNoise]], first: int, k: int,
                     dt_s: float) -> np.ndarray:
        """(k, len(noisy)) noise of samples ``first ..`` of each noisy channel."""
        t = self._t_base_s + (np.arange(first, first + k) - self._k_base) * dt_s
        block = np.empty((k, len(noisy)))
        for j, (_, cn) in enumerate(noisy):
            block[:, j] = cn.generate(k, dt_s, t)
        return block

    def _times(self, n: int, dt_s: float) -> np.ndarray:
        if self._dt_s != dt_s:
            self._t_base_s = self.time_s
            self._k_base = self.samples_generated
            self._dt_s = dt_s
        k = np.arange(
            self.samples_generated - self._k_base, self.samples_generated - self._k_base + n
        )
        return self._t_base_s + k * dt_s

    def _make_noise(self, dt_s: float) -> None:
        if self._noise is None:
            # a resonance must lie below the Nyquist frequency, known only now
            self.model.check_nyquist(1.0 / dt_s, self.noisy_channels)
            taps = math.ceil(self.duration_hint_s / dt_s)
            # one flicker FFT block for the whole hinted record, with room for the
            # look-ahead and a reader that runs a little past the end
            length = taps + taps // 32 + 2 * self.noise_block
            self._noise = {
                ch: ChannelNoise(self.model[ch], self.seed, CHANNELS.index(ch), taps, length)
                for ch in self.noisy_channels
            }

    def prepare(self, dt_s: float) -> None:
        """Do the slow set-up of samples spaced ``dt_s`` now (the first flicker blocks),
        before a real-time reader starts; draws no sample, changes no output."""
        self._make_noise(dt_s)
        assert self._noise is not None
        for cn in self._noise.values():
            cn.prepare()

    def generate(self, n: int, dt_s: float) -> TrueSamples:
        """The next ``n`` samples spaced ``dt_s`` (s), continuing the previous call.

        Deterministic from the seed; for a constant ``dt_s`` the result of several calls
        equals, bit for bit, one call for the total count.
        """
        if n < 0 or not dt_s > 0 or not math.isfinite(dt_s):
            raise ModelError(f"generate: need n >= 0 and dt_s > 0, got n={n}, dt_s={dt_s}")
        self._make_noise(dt_s)
        t = self._times(n, dt_s)
        temp = self.temperature.at(t)
        noise = self._take_noise(n, dt_s)
        out = np.empty((n, 6))
        out[:] = self._constant_part()
        thermal = self._thermal_coefficients()
        if thermal is not None:  # column by column: only those with a temperature term
            ref, lin, quad = thermal
            for c in np.flatnonzero((lin != 0) | (quad != 0)):
                dT = temp - ref[c]
                out[:, c] += dT * (lin[c] + dT * quad[c])
        if noise is not None:
            cols, values = noise
            for j, col in enumerate(cols):
                out[:, col] += values[:, j]
        for i, ch in enumerate(CHANNELS):
            if self.model[ch].bandwidth_hz > 0:
                out[:, i] = self._filters[ch].apply(out[:, i], dt_s)
        for ch, gen in self._output_white.items():  # model key output_white: after the filter
            out[:, CHANNELS.index(ch)] += gen.generate(n, dt_s, t)
        self.samples_generated += n
        return TrueSamples(gyro_dps=out[:, :3], accel_g=out[:, 3:], temp_c=temp)

    def _thermal_coefficients(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """(6,) temp_ref, linear and quadratic temperature coefficients of each channel at
        the current input, None if all are zero: the output gains
        ``(scale_temp_coeff dT + scale_temp_coeff2 dT^2) x + temp_coeff dT + temp_coeff2 dT^2``
        = ``lin dT + quad dT^2`` with dT = T - temp_ref and x the sensed input."""
        key = (self._rate.tobytes(), self._force.tobytes())
        if self._thermal_key != key:
            ref, lin, quad = np.empty(6), np.zeros(6), np.zeros(6)
            for i, ch in enumerate(CHANNELS):
                cm = self.model[ch]
                ref[i] = cm.temp_ref
                if cm.temp_coeff or cm.temp_coeff2 or cm.scale_temp_coeff or cm.scale_temp_coeff2:
                    x = self._sensed(cm, i % 3, self._rate if i < 3 else self._force)
                    lin[i] = cm.scale_temp_coeff * x + cm.temp_coeff
                    quad[i] = cm.scale_temp_coeff2 * x + cm.temp_coeff2
            any_term = bool(np.any(lin) or np.any(quad))
            self._thermal = (ref, lin, quad) if any_term else None
            self._thermal_key = key
        return self._thermal

    def _constant_part(self) -> np.ndarray:
        """(6,) noise-free output at temp_ref: sensitivity, nonlinearity, cross-axis, bias."""
        key = (self._rate.tobytes(), self._force.tobytes())
        if self._const_key != key:
            vals = np.empty(6)
            for i, ch in enumerate(CHANNELS):
                cm = self.model[ch]
                gyro = i < 3
                u = self._rate if gyro else self._force
                x = self._sensed(cm, i % 3, u)
                y = (1.0 + cm.scale_error) * x + cm.bias
                if gyro:
                    y += cm.g_sensitivity_x * self._force[0] + cm.g_sensitivity_y * self._force[1]
                    y += cm.g_sensitivity_z * self._force[2]
                vals[i] = y
            self._const, self._const_key = vals, key
        return self._const

    @staticmethod
    def _sensed(cm: ChannelModel, axis: int, u: np.ndarray) -> float:
        """u_i + nonlinearity u_i^2 + sum_{j != i} cross_j u_j."""
        cross = (cm.cross_x, cm.cross_y, cm.cross_z)
        x = u[axis] + cm.nonlinearity * u[axis] ** 2
        return float(x + sum(cross[j] * u[j] for j in range(3) if j != axis))


def simulate(
    model: NoiseModel | None,
    n: int,
    rate_hz: float,
    seed: int = 0,
    temperature: TemperatureProfile | float | str | None = None,
    channels: Sequence[str] | None = None,
    *,
    rate_dps: Sequence[float] = (0.0, 0.0, 0.0),
    gravity_g: Sequence[float] = (0.0, 0.0, 1.0),
) -> dict[str, np.ndarray]:
    """Offline simulation of ``n`` samples at ``rate_hz`` (no registers, no quantisation).

    Returns ``{channel: (n,) values}`` for the requested channels (default all six; dps
    and g) plus ``"t_s"`` (sample times) and ``"temp_c"``. Identical to
    ``SensorPhysics(model, seed, temperature=..., duration_hint_s=n / rate_hz)`` generated in
    one call, so flicker is exact Kasdin-Walter over the whole record.
    """
    if not rate_hz > 0:
        raise ModelError(f"simulate: rate_hz must be > 0, got {rate_hz}")
    if n < 1:
        raise ModelError(f"simulate: n must be >= 1, got {n}")
    wanted = CHANNELS if channels is None else tuple(channels)
    phys = SensorPhysics(
        model,
        seed,
        temperature=temperature,
        duration_hint_s=n / rate_hz,
        channels=wanted,
        rate_dps=rate_dps,
        gravity_g=gravity_g,
    )
    dt = 1.0 / rate_hz
    s = phys.generate(n, dt)
    t = np.arange(n) * dt  # the times generate() used (t_base = 0)
    out = {ch: (s.gyro_dps if i < 3 else s.accel_g)[:, i % 3].copy()
           for ch, i in ((c, CHANNELS.index(c)) for c in wanted)}
    out["t_s"] = t
    out["temp_c"] = s.temp_c
    return out


def quantize_counts(values: np.ndarray, lsb: float, fs: float | None = None) -> np.ndarray:
    """Raw int16 counts of ``values``: ``rint(values / lsb)`` saturated.

    Saturation is at the int16 limits (-32768, 32767), as the chip's output registers, or
    at ``+-fs / lsb`` counts when a full scale ``fs`` (same unit as values) is given and
    is tighter. Rounding is to nearest, ties to even (``numpy.rint``).
    """
    if not lsb > 0:
        raise ValueError(f"quantize: lsb must be > 0, got {lsb}")
    lo, hi = float(INT16_MIN), float(INT16_MAX)
    if fs is not None:
        lim = math.floor(fs / lsb + 1e-9)
        lo, hi = max(lo, -lim), min(hi, lim)
    counts = np.rint(np.asarray(values, dtype=np.float64) / lsb)
    return np.clip(np.nan_to_num(counts, nan=0.0), lo, hi).astype(np.int16)


def quantize(values: np.ndarray, lsb: float, fs: float | None = None) -> np.ndarray:
    """``values`` on the LSB grid, saturated (see :func:`quantize_counts`), as float64."""
    return quantize_counts(values, lsb, fs).astype(np.float64) * lsb


__all__ = [
    "DEFAULT_DURATION_HINT_S",
    "ChannelNoise",
    "SensorPhysics",
    "TrueSamples",
    "quantize",
    "quantize_counts",
    "simulate",
]
