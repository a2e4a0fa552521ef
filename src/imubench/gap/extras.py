"""Effects the gap diagnosis adds to realisations itself (the simulator has no such term,
or places it elsewhere in the sensor chain): bias step, random telegraph noise, a
narrowband resonance, and impulsive outliers after the output filter.

Each is an additive increment of the rate output (unit of the channel, e.g. dps), drawn
from its own random stream per realisation seed, so a candidate's realisations are the
current realisations plus the increment (common random numbers).

* ``bias_step``: ``size * 1[t >= step_time_s]``; deterministic.
* ``sine``: ``sine_amplitude * sin(2 pi sine_freq t + phi)``, phi uniform per seed; an
  increment rather than the simulator's sine term, so a model that already carries a
  line (the ADIS16405 gz fit has 0.42 dps at 20.8 Hz) keeps it when a second one is
  added (with the simulator's single sine term the candidate replaced the model's line).
* ``telegraph``: symmetric random telegraph signal between ``0`` and ``telegraph_step``
  with mean dwell ``telegraph_dwell_s`` in each level (exponential dwell times, switching
  rate ``1 / dwell``). Its autocovariance is ``(step/2)^2 exp(-2 |t| / dwell)``
  (Papoulis & Pillai, Probability, Random Variables and Stochastic Processes, 4th ed.,
  ex. 9-16), so its Allan variance is that of a Gauss-Markov process with
  ``sigma = step / 2`` and ``tau_c = dwell / 2`` (IEEE Std 952-1997 C.6); only the
  amplitude distribution (two levels, excess kurtosis -2) tells it apart.
* ``resonance``: the simulator's resonance term (:class:`lsm6ds_sim.noise.Resonance`,
  model keys of the same names): a damped cosine (the real part of a complex AR(1))
  whose spectrum is a Lorentzian line of centre ``resonance_freq_hz`` and full width at
  half maximum ``resonance_width_hz`` (plus its mirror at -f0), of one-sided PSD
  ``resonance_height`` (unit^2/Hz) at the centre: the shape the evidence's Lorentzian
  fit measures; the variance is about ``height * pi/2 * width``. Realised here, as an
  increment, so that a model that already carries a resonance keeps it when a candidate
  adds another.
* ``outliers``: Bernoulli-Gaussian impulses, probability ``outlier_rate / rate_hz`` per
  sample, amplitude ``N(0, outlier_amplitude^2)``, added AFTER the output filter (where
  a bus glitch or an SPI read error appears in the record; the simulator's outlier term
  sits before the filter and a filtered impulse has a smaller tail).
"""

from __future__ import annotations

import math

import numpy as np
from lsm6ds_sim.noise import Resonance

LOCAL_EFFECTS: tuple[str, ...] = ("bias_step", "sine", "telegraph", "resonance", "outliers")
"""Effects realised here rather than by the simulator."""

_STREAM = {"bias_step": 1, "telegraph": 2, "resonance": 3, "outliers": 4, "sine": 5}


def _rng(seed: int, effect: str) -> np.random.Generator:
    return np.random.default_rng([int(seed), 0x6A9, _STREAM[effect]])


def increment(effect: str, params: dict[str, float], n: int, rate_hz: float, seed: int
              ) -> np.ndarray:
    """The effect's additive increment (n samples at rate_hz) for one realisation seed."""
    if effect == "bias_step":
        t = np.arange(n) / rate_hz
        return np.where(t >= params["step_time_s"], params["step_size"], 0.0)
    rng = _rng(seed, effect)
    if effect == "sine":
        t = np.arange(n) / rate_hz
        return params["sine_amplitude"] * np.sin(2.0 * math.pi * params["sine_freq"] * t
                                                 + rng.uniform(0.0, 2.0 * math.pi))
    if effect == "telegraph":
        return telegraph_signal(rng, n, rate_hz, params["telegraph_step"],
                                params["telegraph_dwell_s"])
    if effect == "resonance":
        return resonance_noise(rng, n, rate_hz, params["resonance_freq_hz"],
                               params["resonance_width_hz"], params["resonance_height"])
    if effect == "outliers":
        p = min(params["outlier_rate"] / rate_hz, 1.0)
        hit = rng.random(n) < p
        out = np.zeros(n)
        out[hit] = rng.normal(0.0, params["outlier_amplitude"], int(hit.sum()))
        return out
    raise ValueError(f"no local increment for effect {effect!r}")


def increments(effect: str, params: dict[str, float], n: int, rate_hz: float,
               seeds: list[int]) -> np.ndarray:
    """(K, n) increments, one per realisation seed."""
    return np.stack([increment(effect, params, n, rate_hz, s) for s in seeds])


def telegraph_signal(rng: np.random.Generator, n: int, rate_hz: float, step: float,
                     dwell_s: float) -> np.ndarray:
    """Two-level signal (0 / step) with exponential dwell times of mean dwell_s."""
    out = np.empty(n)
    i = 0
    level = float(rng.integers(0, 2))
    mean_samples = max(dwell_s * rate_hz, 1.0)
    while i < n:
        k = max(1, round(rng.exponential(mean_samples)))
        out[i:i + k] = level * step
        level = 1.0 - level
        i += k
    return out


def resonance_noise(rng: np.random.Generator, n: int, rate_hz: float, f0_hz: float,
                    width_hz: float, height: float) -> np.ndarray:
    """Narrowband noise of peak one-sided PSD ``height``: the simulator's resonance term
    (:class:`lsm6ds_sim.noise.Resonance`, the one generator of it). A centre the Welch
    excess put at or above 0.49 fs is moved to 0.49 fs (the pole needs f0 < fs/2)."""
    f0 = min(f0_hz, 0.49 * rate_hz)
    width = min(width_hz, 0.49 * rate_hz)
    return Resonance(height, f0, width, rng).generate(n, 1.0 / rate_hz, np.arange(n) / rate_hz)
