"""Blind acceptance of ``imubench gap`` on plain-CSV logger files (issue 15, acceptance 1).

Usage: ``PYTHONPATH=src:drivers:simulator .venv/bin/python bench/bench_gap_blind.py
[--quick] [--set tune,heldout] [--jobs 2] [--cases sine,markov,...] [--keep DIR]
[--pairs [--truth] | --weak-lines | --line-shapes]``

What it measures. An independent generator written here from textbook definitions
(numpy / scipy only; NOT :mod:`lsm6ds_sim`) makes 1 h at 104 Hz of one gyro channel
``gx``: white noise of density 0.004 dps/sqrt(Hz) plus flicker B = 0.0008 dps plus ONE
withheld effect, quantised to the LSM6DSL's 8.75 mdps LSB, with a temperature column that
always varies (two incommensurate sines and a drift of this file's own, random phases,
quantised to the LSM6DSL's 1/256 degC). Each case is written the way a logger writes a
file: a ``t,gx,temp`` header, ``t`` in seconds to 6 decimals, no ``# odr_hz`` or other
metadata line. The truth model minus the withheld effect is written as a noise-model TOML
(white, flicker, temp_ref and the LSB's quantisation noise as ``output_white`` =
LSB / sqrt(12 fs): a rounding error uniform over one LSB, white). The real CLI is then run
as a subprocess, ``python -m imubench gap FILE.csv --model M.toml --channels gx --json
OUT --seed S`` (default holdout fraction 0.5, 10 realisations), and scored:

* **top-1**: the verdict names the withheld effect (the output filter's expected name is
  ``base_model``, the refit of the model's white level and filter);
* **false alarms** on the nulls (no withheld effect; the exact truth model): strict, any
  verdict but ``none``; and named, a verdict that names an unmodelled effect (not
  ``none``, ``base_model`` or ``unexplained``);
* **held-out excess closed** (named right): ``1 - gap_excess_after / gap_excess_before``
  on the held-out half when its systematic part exceeds 0.05 before, else the held-out
  excess chi-squared closed (line, tail, temperature and step effects barely move the
  Allan curve), as in ``bench_gap_acceptance.py``;
* **main-parameter error** (named right): ``|fitted - truth| / truth`` of the effect's main
  key (``imubench.gap.candidates.MAIN_PARAM``; flicker and white are totals).

Generators (textbook definitions): white, N / sqrt(tau0) N(0, 1) per sample; flicker and
the resonance by FFT spectral shaping (one-sided S(f) = B^2 / (pi f), NIST SP 1065
Table 3; a Lorentzian line S(f) = H / (1 + (2 (f - f0) / w)^2) of peak H and FWHM w);
random walk as the running sum of white steps K sqrt(tau0) N(0, 1); ramp R t; Gauss-Markov
as the exact AR(1) recursion (phi = exp(-tau0 / tau_c), IEEE 952 C.6); IEEE 952 C.2
quantization by rounding the integrated angle to the step S = sqrt(12) Q and
differencing, as the file's converter (S / tau0 a whole number of LSBs, no LSB rounding
after it, and no ``output_white`` in that case's model; see :func:`generate`);
Bernoulli-Gaussian outliers; a sine of random phase at a random frequency;
a temperature coefficient on the file's temperature column; a bias step at a random time
in the middle 80 %; a random telegraph signal with exponential dwell times; the output
filter as the zero-phase frequency response |H|^2 = 1 / (1 + (f / f_c)^4) applied in the
FFT domain (the magnitude of an analogue 2nd-order Butterworth; the simulator's filter is a
bilinear IIR, so this row is independent of it too).

Magnitudes: each effect at a CLEAR size and a NEAR-LIMIT size. Near-limit follows the
measured detection limits of docs/gap.md ("Detection limits", the 2026-11-21 run, 1 h at
104 Hz, white 0.004 dps/sqrt(Hz)) where they exist, scaled by at most 1.5 (this base has
more flicker, 0.0008 against 0.0005); for the others the rule is "the size at which the
effect's own detection statistic is ~2x its threshold" from first principles (stated per
effect in :data:`EFFECTS`). The testers' misses of the last sitting are in the set:
random walk 2e-4 (clear) and 1.5e-4, Markov tau_c 30 s, temperature 5e-4 dps/degC.

Seeds: every (effect, magnitude) and null is drawn once per split; the ``tune`` split uses
data seeds 1000+ and diagnosis seed 11, the ``heldout`` split data seeds 2000+ and
diagnosis seed 12, the ``fresh`` split data seeds 3000+ and diagnosis seed 13 (see
:data:`SPLITS`). Tune only on ``tune``; report each separately.

``--quick``: the clear magnitudes and 2 nulls per split.

``--pairs`` (acceptance 3, "two simultaneous effects: both named, held-out gap closed >= 80 %
after both"): each pair of :data:`PAIRS` instead, both effects at their clear magnitudes
drawn in turn into one record (the same generator and model file). Right = both effects
in ``kept`` and the held-out gap closed by at least 80 % (the closure defined above).

``--truth`` (with ``--pairs``): the same CLI run a second time on each record with the
generator's truth as the model (the base plus both effects at their drawn values, as model
keys; a bias step, which has none, taken out of the data instead; a telegraph pair has no
truth model): the held-out excess the truth leaves, on the same yardstick, gives the
closure the truth itself reaches on that record (``truth_closed``). A random effect's
held-out realisation can sit far from its expected Allan curve (a random walk's at 200-400
s has a few degrees of freedom on a 30 min half), so on some records no model, the truth
included, closes 80 %: the acceptance figure is printed as measured, and beside it how
many of its misses the truth misses too.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

RATE = 104.0
DURATION_S = 3600.0
WHITE = 0.004
"""dps/sqrt(Hz)."""
FLICKER = 0.0008
"""dps (bias instability coefficient B)."""
LSB = 0.00875
"""dps per LSB (LSM6DSL at 250 dps full scale)."""
TEMP_LSB = 1.0 / 256.0
TEMP_REF = 25.0
ROOT = Path(__file__).resolve().parents[1]

EFFECTS: dict[str, list[dict[str, float]]] = {
    # clear, near-limit (limits: docs/gap.md 5e-4 dps/degC on +-4 degC, t 5.2-6.5)
    "temperature": [{"temp_coeff": 1e-3}, {"temp_coeff": 5e-4}],
    # limit 0.0015 dps at 3.3 Hz (line t 6-10); frequency drawn in 2-20 Hz
    "sine": [{"sine_amplitude": 0.003}, {"sine_amplitude": 0.0018}],
    # limit 1.5e-4 (z 4.1 independent); the testers' clear miss 2e-4
    "random_walk": [{"random_walk": 3e-4}, {"random_walk": 2e-4}],
    # ADDED flicker (total sqrt(0.0008^2 + B^2)); limit 0.0011 total on 0.0005
    "flicker": [{"flicker": 0.0025}, {"flicker": 0.0015}],
    # limit 5e-6 dps/s (trend t 5.9-6.9)
    "ramp": [{"ramp": 2e-5}, {"ramp": 8e-6}],
    # the testers' tau_c 30 s; limit sigma 0.0012 at tau_c 5 s
    "markov": [{"markov_sigma": 0.004, "markov_tau": 30.0},
               {"markov_sigma": 0.0018, "markov_tau": 5.0}],
    # IEEE 952 angle quantization Q (deg): 3 Q^2 / tau0^2 against N^2 / tau0 at tau0 is
    # 11 % (clear) and 2 % (near: ~2x the family-wise z at the shortest taus). Drawn
    # since 2026-12-04 as S / tau0 = 4 and 1 LSB (_angle_quantizer): Q 9.72e-5 and
    # 2.43e-5, the ADEV at tau0 1.088 and 1.006 times the model's (1.093, 1.009 planned)
    "quantization": [{"quantization": 1e-4}, {"quantization": 3e-5}],
    # Gaussian impulses; tail test at 5 robust sigmas (~0.2 dps): near, 0.05/s of
    # N(0, 0.15^2): ~16 beyond 5 sigma in the fit part against ~0 expected
    "outliers": [{"outlier_rate": 0.1, "outlier_amplitude": 0.5},
                 {"outlier_rate": 0.05, "outlier_amplitude": 0.15}],
    # output low-pass, 2nd order (expected verdict base_model); near: 40 Hz of 52 Nyquist
    "filter": [{"bandwidth_hz": 15.0}, {"bandwidth_hz": 40.0}],
    # step test: 5 robust sigmas of 256 block-mean increments (~0.008 dps here)
    "bias_step": [{"step_size": 0.03}, {"step_size": 0.015}],
    # same Allan curve as Markov sigma = step / 2, tau_c = dwell / 2
    "telegraph": [{"telegraph_step": 0.008, "telegraph_dwell_s": 20.0},
                  {"telegraph_step": 0.004, "telegraph_dwell_s": 10.0}],
    # Lorentzian line of peak H (dps^2/Hz one-sided) over a continuum 2 N^2 = 3.2e-5,
    # FWHM 1 Hz at 5-25 Hz: clear 10x, near 3x the continuum
    "resonance": [{"resonance_height": 3.2e-4, "resonance_width_hz": 1.0},
                  {"resonance_height": 1.0e-4, "resonance_width_hz": 1.0}],
}
LINE_SHAPES = {"resonance_bandpass": "bandpass", "resonance_mechanical": "mechanical"}
"""A resonance drawn with another line shape than the Lorentzian (``--line-shapes``, added
on 2026-12-06 when the simulator's resonance became a Lorentzian line, so that the
diagnosis is not judged on its own line shape alone), at the magnitudes of the Lorentzian
resonance of :data:`EFFECTS`, peak H at f0 and FWHM 1 Hz, f0 in 5-25 Hz (Q 5-25):

* ``bandpass``: a second-order band-pass, ``H (f f0 / Q)^2 / ((f0^2 - f^2)^2 + (f f0 /
  Q)^2)``: zero at 0 Hz, wings falling as 1/f^2 above the centre;
* ``mechanical``: a mass-spring-damper driven by white noise, ``H (f0^2 / Q)^2 / ((f0^2 -
  f^2)^2 + (f f0 / Q)^2)``: a floor at 0 Hz, wings falling as 1/f^4 above.

Scored apart, never mixed into the fixed set's figures; seeds past the others'."""
EXPECTED = {"filter": "base_model", "resonance_bandpass": "resonance",
            "resonance_mechanical": "resonance"}
"""Verdict expected for a withheld effect whose name differs from the truth's."""
MAIN = {"temperature": "temp_coeff", "sine": "sine_amplitude", "random_walk": "random_walk",
        "flicker": "flicker", "ramp": "ramp", "markov": "markov_sigma",
        "quantization": "quantization", "outliers": "outlier_rate",
        "filter": "bandwidth_hz", "bias_step": "step_size", "telegraph": "telegraph_step",
        "resonance": "resonance_freq_hz", "resonance_bandpass": "resonance_freq_hz",
        "resonance_mechanical": "resonance_freq_hz"}
N_NULL = 4
PAIRS = ("temperature+sine", "ramp+sine", "bias_step+temperature", "random_walk+sine",
         "flicker+ramp", "markov+temperature", "outliers+random_walk", "telegraph+ramp",
         "resonance+bias_step", "quantization+temperature", "filter+sine")
"""Two withheld effects at once (``--pairs``), each at its clear magnitude; fixed before
the first run: the issue's temperature + sine, and every other effect once beside a
deterministic or a random one."""
MORE_PAIRS = ("temperature+ramp", "flicker+random_walk", "telegraph+temperature",
              "temperature+random_walk")
"""Pairs an outside blind test (its own generator) kept wrong on 2026-12-03 (the first
three) and 2026-12-04 (temperature + random walk, 2 of 6 with both kept), added after
:data:`PAIRS` had been run for weeks (``--pairs --more-pairs``): scored apart, never
mixed into the fixed set's figures. The seeds continue past :data:`PAIRS`'."""
WEAK_LINES = (0.0012, 0.0009)
"""Sine amplitudes (dps) below the near-limit one of :data:`EFFECTS` (0.0018), 3 records
each per split (``--weak-lines``), added on 2026-12-06 with the held-out line test
(``imubench.gap.line_across``) after an outside reviewer's 1.5 mdps line at 52 Hz was
missed: scored apart, never mixed into the fixed set's figures; seeds past the others'.
The peak of 1.2 mdps on a 30 min fit part is ~11x the continuum, of 0.9 mdps ~6x."""
PAIR_CLOSURE = 0.8
"""Acceptance 3: the held-out gap closed by at least this share after both effects."""
SPLITS = {"tune": (1000, 11), "heldout": (2000, 12), "fresh": (3000, 13)}
"""Split: (first data seed, diagnosis seed). ``fresh`` was added on 2026-11-27 after two
held-out misses had been studied case by case (temperature clear, Markov clear): it is
the split nobody has looked into; run it, do not tune on it."""


# ------------------------------------------------------------------ generator
def spectral(rng: np.random.Generator, n: int, fs: float, s_one: np.ndarray) -> np.ndarray:
    """Gaussian series of one-sided PSD ``s_one`` (on rfftfreq(n, 1/fs)) by FFT shaping:
    E|X_k|^2 = S(f_k) fs n / 2 for 0 < f_k < fs/2."""
    sd = np.sqrt(s_one * fs * n / 4.0)
    x = sd * (rng.standard_normal(sd.size) + 1j * rng.standard_normal(sd.size))
    x[0] = 0.0
    return np.fft.irfft(x, n)


def temperature(rng: np.random.Generator, n: int, fs: float) -> np.ndarray:
    """Always varying: two incommensurate sines (periods 23-31 min and 6-9 min) and a drift
    of 0.5-2 degC/h, random phases, quantised to 1/256 degC."""
    t = np.arange(n) / fs
    p1, p2 = rng.uniform(1380, 1860), rng.uniform(360, 540)
    temp = (26.0 + 3.0 * np.sin(2 * math.pi * t / p1 + rng.uniform(0, 2 * math.pi))
            + 1.2 * np.sin(2 * math.pi * t / p2 + rng.uniform(0, 2 * math.pi))
            + rng.uniform(0.5, 2.0) * t / 3600.0)
    return np.round(temp / TEMP_LSB) * TEMP_LSB


def generate(rng: np.random.Generator, effects: list[tuple[str, dict[str, float]]], n: int,
             fs: float, temp: np.ndarray) -> tuple[np.ndarray, dict[str, float]]:
    """(gx in dps quantised to LSB, truth values of the effects' parameters): the base
    (white + flicker) and each effect in turn, drawn from ``rng`` in that order, except
    that the angle quantizer (``quantization``) is applied after every other effect, as a
    sensor's converter is the last stage of its chain, and is then the converter itself
    (:func:`_angle_quantizer`: no rounding to the LSB after it).

    Until 2026-12-04 (a) a pair applied its effects in the order of its name, so
    ``quantization+temperature`` added the temperature response to an already quantised
    rate (multiples of S / tau0 = 4.12 LSB at Q = 1e-4 deg) and the LSB rounding then
    erased it where it was small: the mean output moved by 1 % of a 1e-3 dps/degC response
    at +-1 degC, 7 % at +-2 degC, 73 % at +-4 degC and 131 % at +6 degC, a cubic-like
    response the tool read as a linear one 9-27 % low with a curvature (and, once, a random
    walk beside it); (b) the LSB rounding after a step of 4.12 LSB mapped most of its
    levels to 4 LSB: a gain of 0.970 on the whole series (its PSD at 0.5-3 Hz 0.941 of the
    same white noise rounded alone, 6 seeds), so the truth model's white level was 3 %
    too high for the data (the tool kept a ``base_model`` refit, white 0.00396, beside the
    quantization and a temperature response once (a) was fixed) and the quantization's
    Allan excess at tau0 fell to 0.65 of 3 Q^2 / tau0^2. The seeds are unchanged (the
    temperature response draws no random number)."""
    tau0 = 1.0 / fs
    f = np.fft.rfftfreq(n, tau0)
    fl = np.zeros_like(f)
    fl[1:] = 1.0 / (math.pi * f[1:])
    y = WHITE / math.sqrt(tau0) * rng.standard_normal(n) + spectral(rng, n, fs,
                                                                   FLICKER**2 * fl)
    truth: dict[str, float] = {}
    for effect, p in effects:
        if effect != "quantization":
            y = _add(rng, effect, p, y, fs, fl, temp, truth)
    quantizer = dict(effects).get("quantization")
    if quantizer is None:
        return np.round(y / LSB) * LSB, truth
    truth.update(quantizer)
    y, truth["quantization"] = _angle_quantizer(rng, y, fs, quantizer["quantization"])
    return y, truth


def _angle_quantizer(rng: np.random.Generator, y: np.ndarray, fs: float, q: float
                     ) -> tuple[np.ndarray, float]:
    """(rate samples, the quantization coefficient Q in deg) of a converter that
    quantises the integrated angle (IEEE 952 C.2): the angle is rounded to a step S and
    the rate sample is the difference of consecutive quantised angles over tau0, so its
    values are multiples of S / tau0, the output's LSB. S / tau0 is the nearest whole
    number (at least 1) of :data:`LSB` to ``sqrt(12) q / tau0``: a sensor whose rate LSB is
    k x 8.75 mdps (Q = 1e-4 deg: k = 4, the LSM6DSL's 35 mdps at +-1000 dps; 3e-5: k = 1),
    so that the file's values are LSB multiples as every other case's, and Q = S / sqrt(12)
    is the truth. No other rounding follows: this converter's quantization is all the
    file's quantization noise (:func:`model_toml` leaves out the LSB's ``output_white``
    for these cases)."""
    tau0 = 1.0 / fs
    k = max(1, round(math.sqrt(12.0) * q / tau0 / LSB))
    step = k * LSB * tau0
    angle = np.cumsum(y) * tau0 + rng.uniform(0, step)
    levels = np.round(angle / step)
    counts = np.diff(np.concatenate([[levels[0] - round(y[0] * tau0 / step)], levels]))
    return counts * (k * LSB), step / math.sqrt(12.0)


def _add(rng: np.random.Generator, effect: str, p: dict[str, float], y: np.ndarray,
         fs: float, fl: np.ndarray, temp: np.ndarray, truth: dict[str, float]) -> np.ndarray:
    """``y`` with one effect added (or applied: quantization, filter); its truth values
    into ``truth``."""
    n, tau0 = len(y), 1.0 / fs
    t = np.arange(n) * tau0
    f = np.fft.rfftfreq(n, tau0)
    y = y.copy()
    truth.update(p)
    if effect == "temperature":
        y += p["temp_coeff"] * (temp - TEMP_REF)
    elif effect == "sine":
        fr = float(rng.uniform(2.0, 20.0))
        truth["sine_freq"] = fr
        y += p["sine_amplitude"] * np.sin(2 * math.pi * fr * t + rng.uniform(0, 2 * math.pi))
    elif effect == "random_walk":
        y += np.cumsum(p["random_walk"] * math.sqrt(tau0) * rng.standard_normal(n))
    elif effect == "flicker":
        y += spectral(rng, n, fs, p["flicker"] ** 2 * fl)
        truth["flicker"] = math.hypot(FLICKER, p["flicker"])
    elif effect == "ramp":
        y += p["ramp"] * t
    elif effect == "markov":
        phi = math.exp(-tau0 / p["markov_tau"])
        x = np.empty(n)
        acc = p["markov_sigma"] * rng.standard_normal()
        w = p["markov_sigma"] * math.sqrt(1.0 - phi * phi) * rng.standard_normal(n)
        for i in range(n):  # AR(1), written out
            acc = phi * acc + w[i]
            x[i] = acc
        y += x
    elif effect == "outliers":
        hit = rng.random(n) < p["outlier_rate"] * tau0
        y[hit] += p["outlier_amplitude"] * rng.standard_normal(int(hit.sum()))
    elif effect == "filter":
        h2 = 1.0 / (1.0 + (f / p["bandwidth_hz"]) ** 4)
        y = np.fft.irfft(np.fft.rfft(y) * np.sqrt(h2), n)
    elif effect == "bias_step":
        t_step = float(rng.uniform(0.1, 0.9)) * DURATION_S
        truth["step_time_s"] = t_step
        y += np.where(t >= t_step, p["step_size"], 0.0)
    elif effect == "telegraph":
        out = np.zeros(n)
        level, i = float(rng.integers(0, 2)), 0
        while i < n:
            k = int(rng.exponential(p["telegraph_dwell_s"] * fs)) + 1
            out[i:i + k] = level * p["telegraph_step"]
            level = 1.0 - level
            i += k
        y += out
    elif effect == "resonance" or effect in LINE_SHAPES:
        f0 = float(rng.uniform(5.0, 25.0))
        truth["resonance_freq_hz"] = f0
        y += spectral(rng, n, fs, line_shape(LINE_SHAPES.get(effect, "lorentzian"), f, f0,
                                             p["resonance_width_hz"], p["resonance_height"]))
    elif effect != "none":
        raise ValueError(effect)
    return y


def line_shape(kind: str, f: np.ndarray, f0: float, width: float, height: float
               ) -> np.ndarray:
    """One-sided PSD of a resonance of peak ``height`` near ``f0`` and FWHM ``width``:
    the Lorentzian of :data:`EFFECTS` or a shape of :data:`LINE_SHAPES`."""
    if kind == "lorentzian":
        return height / (1.0 + (2.0 * (f - f0) / width) ** 2)
    q = f0 / width
    den = (f0**2 - f**2) ** 2 + (f * f0 / q) ** 2
    num = (f * f0 / q) ** 2 if kind == "bandpass" else np.full_like(f, (f0**2 / q) ** 2)
    return height * num / den


def model_toml(lsb_rounding: bool = True) -> str:
    """The truth model minus the withheld effect: the same for every case but those with
    the angle quantizer, whose output is not rounded to the LSB after it
    (``lsb_rounding`` False: no ``output_white``)."""
    ow = (f"output_white = {LSB / math.sqrt(12.0 * RATE):.8g}\n" if lsb_rounding else "")
    return (f"[meta]\nname = \"blind truth minus the withheld effect\"\n\n"
            f"[channels.gx]\nwhite = {WHITE}\nflicker = {FLICKER}\n"
            f"{ow}temp_ref = {TEMP_REF}\n")


def write_csv(path: Path, y: np.ndarray, temp: np.ndarray, fs: float) -> None:
    t = np.arange(len(y)) / fs
    with path.open("w") as fh:
        fh.write("t,gx,temp\n")
        np.savetxt(fh, np.column_stack([t, y, temp]), fmt=("%.6f", "%.5f", "%.4f"),
                   delimiter=",")


# ------------------------------------------------------------------ cases
@dataclass
class Case:
    split: str
    effect: str
    size: str
    data_seed: int
    diag_seed: int
    params: dict[str, float] = field(default_factory=dict)
    truth: dict[str, float] = field(default_factory=dict)
    verdict: str = ""
    kept: list[str] = field(default_factory=list)
    closed: float = float("nan")
    param_error: float = float("nan")
    param_z: list[float] = field(default_factory=list)
    """Each named effect's main-parameter error in its standard errors (``params_se``)."""
    truth_closed: float = float("nan")
    """``--truth``: the held-out excess closed by the generator's truth model."""
    seconds: float = 0.0
    detail: str = ""
    error: str = ""

    @property
    def names(self) -> list[str]:
        """The withheld effects (two for a pair ``a+b``)."""
        return self.effect.split("+")

    @property
    def effects(self) -> list[tuple[str, dict[str, float]]]:
        """Each withheld effect with its own parameters (the keys of :data:`EFFECTS`)."""
        if self.effect == "none":
            return [("none", {})]
        return [(e, {k: v for k, v in self.params.items()
                     if k in EFFECTS["resonance" if e in LINE_SHAPES else e][0]})
                for e in self.names]

    @property
    def expected(self) -> str:
        return "+".join(EXPECTED.get(e, e) for e in self.names)

    @property
    def named(self) -> bool:
        """Single effect: the verdict names it; pair: both are kept."""
        if len(self.names) == 1:
            return self.verdict == self.expected
        return all(EXPECTED.get(e, e) in self.kept for e in self.names)

    @property
    def right(self) -> bool:
        """Single effect: named; pair (acceptance 3): both kept and the held-out gap
        closed by at least 80 %."""
        if len(self.names) == 1:
            return self.named
        return self.named and self.closed >= PAIR_CLOSURE


TRUTH_KEYS = ("temp_coeff", "sine_amplitude", "sine_freq", "random_walk", "flicker", "ramp",
              "markov_sigma", "markov_tau", "quantization", "outlier_rate",
              "outlier_amplitude", "bandwidth_hz", "resonance_freq_hz", "resonance_width_hz",
              "resonance_height")
"""Truth values that are noise-model keys of the same meaning (``flicker`` the total)."""


def truth_model(c: Case) -> str | None:
    """The generator's truth for ``c`` as a noise-model TOML (None: an effect without
    model keys other than a bias step, which :func:`run_case` takes out of the data)."""
    if any(e in ("telegraph", *LINE_SHAPES) for e in c.names):
        return None
    keys = {"white": WHITE, "flicker": FLICKER}
    if "quantization" not in c.names:
        keys["output_white"] = LSB / math.sqrt(12.0 * RATE)
    keys.update({k: v for k, v in c.truth.items() if k in TRUTH_KEYS})
    if "filter" in c.names:
        keys["filter_order"] = 2  # |H|^2 = 1 / (1 + (f / f_c)^4): 2nd-order Butterworth
    body = "".join(f"{k} = {v!r}\n" for k, v in keys.items())
    return (f"[meta]\nname = \"blind truth\"\n\n[channels.gx]\n{body}"
            f"temp_ref = {TEMP_REF}\n")


def _gap(csv: Path, model: Path, out: Path, seed: int) -> subprocess.CompletedProcess[str]:
    """``imubench gap`` on ``csv`` as a subprocess, its JSON to ``out``."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(str(ROOT / d) for d in ("src", "drivers", "simulator"))
    cmd = [sys.executable, "-m", "imubench", "gap", str(csv), "--model", str(model),
           "--channels", "gx", "--json", str(out), "--seed", str(seed), "--progress", "off"]
    return subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)


def run_case(c: Case, work: Path, truth: bool = False) -> Case:
    n = int(DURATION_S * RATE)
    rng = np.random.default_rng(c.data_seed)
    temp = temperature(rng, n, RATE)
    y, c.truth = generate(rng, c.effects, n, RATE, temp)
    stem = f"{c.split}_{c.effect}_{c.size}_{c.data_seed}"
    csv, out = work / f"{stem}.csv", work / f"{stem}.json"
    write_csv(csv, y, temp, RATE)
    model = work / "model.toml"
    if "quantization" in c.names:
        model = work / f"{stem}.toml"
        model.write_text(model_toml(lsb_rounding=False))
    t0 = time.perf_counter()
    p = _gap(csv, model, out, c.diag_seed)
    c.seconds = time.perf_counter() - t0
    if p.returncode != 0:
        c.error = (p.stderr.strip().splitlines() or ["?"])[-1]
        c.verdict = "ERROR"
        return c
    d = json.loads(out.read_text())["channels"]["gx"]
    c.verdict = d["verdict"]
    c.kept = [k["effect"] for k in d["kept"]]
    h = d["holdout"] or {}
    if c.named and c.effect != "none":
        if (h.get("gap_excess_before") or 0.0) > 0.05:
            c.closed = 1.0 - (h["gap_excess_after"] or 0.0) / h["gap_excess_before"]
        elif h.get("chi2_closed") is not None:
            c.closed = h["chi2_closed"]
        errors = []
        for e in c.names:
            key = MAIN[e]
            win = next((k for k in d["kept"] if k["effect"] == EXPECTED.get(e, e)), None)
            if win is not None and key in win["params"] and c.truth.get(key):
                # a curved temperature fit is judged by its slope at the record's mean (a
                # linear truth's is the same everywhere), a line as recorded (injected at
                # the output)
                got = (win.get("temp_slope_at_mean", win["params"][key])
                       if key == "temp_coeff"
                       else win.get(f"{key}_at_output", win["params"][key]))
                errors.append(abs(abs(got) - abs(c.truth[key])) / abs(c.truth[key]))
                se = (win.get("params_se") or {}).get(key)
                if se and not (key == "temp_coeff" and win["params"].get("temp_coeff2")):
                    # a line as recorded: its SE scaled as the amplitude is
                    se *= abs(got / win["params"][key])
                    c.param_z.append((abs(got) - abs(c.truth[key])) / se)
        if errors:  # a pair: the worse of the two
            c.param_error = max(errors)
    top = [(e["effect"], e.get("rejected_because", "")[:60]) for e in d["effects"][:3]]
    c.detail = (f"reason={d['reason']!r} gap {d['gap_before']:.3f}->{d['gap_after']:.3f} "
                f"excess {d['gap_excess_before']:.3f}; held-out "
                f"{h.get('gap_before', math.nan):.3f}->{h.get('gap_after', math.nan):.3f} "
                f"excess {h.get('gap_excess_before') or 0:.3f}->"
                f"{h.get('gap_excess_after') or 0:.3f} null {h.get('gap_null', math.nan):.3f}; "
                f"global {d['global']['chi2_smooth']:.1f}/{d['global']['threshold_smooth']:.1f}"
                f" temp_z {d['temperature_slope_z']:.1f} top {top}")
    if truth and (h.get("gap_excess_before") or 0.0) > 0.05:
        c.truth_closed = _truth_closed(c, y, temp, work / stem, h["gap_excess_before"])
    if d.get("look_alike"):  # another effect the fit part does not tell apart
        la = d["look_alike"]
        c.detail += (f" look_alike {la['effect']} by "
                     f"{la['score'] - la['score_verdict']:.2f}, held-out drops "
                     f"{la['holdout_chi2_drop']} / {la['holdout_chi2_drop_verdict']}")
    return c


def _truth_closed(c: Case, y: np.ndarray, temp: np.ndarray, stem: Path,
                  excess_before: float) -> float:
    """The held-out excess closed by the truth model (:func:`truth_model`) on ``c``'s
    record (NaN without one)."""
    text = truth_model(c)
    if text is None:
        return math.nan
    model, csv = stem.with_suffix(".truth.toml"), stem.with_suffix(".truth.csv")
    model.write_text(text)
    if "step_time_s" in c.truth:  # no model key: the true step out of the data, exactly
        t = np.arange(len(y)) / RATE
        y = y - np.where(t >= c.truth["step_time_s"], c.truth["step_size"], 0.0)
    write_csv(csv, y, temp, RATE)
    out = stem.with_suffix(".truth.json")
    p = _gap(csv, model, out, c.diag_seed)
    if p.returncode != 0:
        raise RuntimeError(f"truth run of {stem.name}: "
                           f"{(p.stderr.strip().splitlines() or ['?'])[-1]}")
    after = json.loads(out.read_text())["channels"]["gx"]["holdout"]["gap_excess_before"]
    return 1.0 - (after or 0.0) / excess_before


def show(c: Case) -> None:
    ok = "OK " if c.right else "BAD"
    zs = " ".join(f"{z:+.1f}" for z in c.param_z)
    print(f"  {c.split:7s} {c.effect:12s} {c.size:5s} verdict={c.verdict:12s} kept={c.kept} "
          f"closed={c.closed:5.2f} "
          + (f"truth_closed={c.truth_closed:5.2f} " if math.isfinite(c.truth_closed) else "")
          + f"perr={c.param_error:5.2f} z=[{zs}] {ok} "
          f"({c.seconds:.0f} s) "
          f"{c.error or c.detail} {c.params}", flush=True)


def pair_cases(split: str, only: tuple[str, ...], more: bool = False) -> list[Case]:
    """Acceptance 3: each pair of :data:`PAIRS` (or of :data:`MORE_PAIRS`) at both effects'
    clear magnitudes."""
    base, diag_seed = SPLITS[split]
    out = []
    first = len(PAIRS) if more else 0
    for i, pair in enumerate(MORE_PAIRS if more else PAIRS, start=first):
        if only and pair not in only:
            continue
        params: dict[str, float] = {}
        for e in pair.split("+"):
            params.update(EFFECTS[e][0])
        out.append(Case(split, pair, "clear", base + 700 + i, diag_seed, params))
    return out


def weak_line_cases(split: str) -> list[Case]:
    """The sines of :data:`WEAK_LINES`, three records each."""
    base, diag_seed = SPLITS[split]
    return [Case(split, "sine", f"w{a * 1e4:.0f}", base + 800 + 10 * i + j, diag_seed,
                 {"sine_amplitude": a})
            for i, a in enumerate(WEAK_LINES) for j in range(3)]


def line_shape_cases(split: str) -> list[Case]:
    """Each shape of :data:`LINE_SHAPES` at the resonance's clear and near magnitudes, two
    records each."""
    base, diag_seed = SPLITS[split]
    return [Case(split, shape, ("clear", "near")[j], base + 900 + 10 * i + 2 * j + k,
                 diag_seed, dict(EFFECTS["resonance"][j]))
            for i, shape in enumerate(LINE_SHAPES) for j in range(2) for k in range(2)]


def make_cases(split: str, quick: bool, only: tuple[str, ...]) -> list[Case]:
    base, diag_seed = SPLITS[split]
    out = []
    for i, (eff, mags) in enumerate(EFFECTS.items()):
        if only and eff not in only:
            continue
        for j, p in enumerate(mags[:1] if quick else mags):
            out.append(Case(split, eff, ("clear", "near")[j], base + 10 * i + j, diag_seed,
                            dict(p)))
    if not only or "none" in only:
        for k in range(2 if quick else N_NULL):
            out.append(Case(split, "none", f"n{k}", base + 500 + k, diag_seed))
    return out


def summarise(name: str, cs: list[Case]) -> None:
    eff = [c for c in cs if c.effect != "none"]
    nul = [c for c in cs if c.effect == "none"]
    print(f"\n## {name}")
    if eff:
        single = [c for c in eff if len(c.names) == 1]
        cols = sorted({c.verdict for c in single} | {c.expected for c in single})
        print(f"{'truth':13s}" + "".join(f"{x[:10]:>11s}" for x in cols))
        for e in EFFECTS:
            row = Counter(c.verdict for c in single if c.effect == e)
            if row:
                print(f"{e:13s}" + "".join(f"{row.get(x, 0):11d}" for x in cols))
        pairs = [c for c in eff if len(c.names) == 2]
        if pairs:
            print(f"  pairs: both kept {sum(c.named for c in pairs)}/{len(pairs)}; both kept "
                  f"and held-out gap closed >= {PAIR_CLOSURE:.0%} (acceptance 3) "
                  f"{sum(c.right for c in pairs)}/{len(pairs)}")
            truth = [c for c in pairs if math.isfinite(c.truth_closed)]
            if truth:
                low = [c for c in truth if c.truth_closed < PAIR_CLOSURE]
                print(f"  pairs with a truth model: the truth itself closes < "
                      f"{PAIR_CLOSURE:.0%} on {len(low)}/{len(truth)} ("
                      + ", ".join(f"{c.effect} {c.truth_closed:.2f}, tool {c.closed:.2f}"
                                  for c in low)
                      + f"); misses where the truth reaches {PAIR_CLOSURE:.0%}: "
                      f"{sum(not c.right and c.truth_closed >= PAIR_CLOSURE for c in truth)}")
        for size in ("clear", "near", *(f"w{a * 1e4:.0f}" for a in WEAK_LINES)):
            sub = [c for c in eff if c.size == size]
            if sub:
                print(f"  top-1 {size}: {sum(c.right for c in sub)}/{len(sub)}")
        closed = [c.closed for c in eff if c.right and math.isfinite(c.closed)]
        perr = [c.param_error for c in eff if c.right and math.isfinite(c.param_error)]
        print(f"  top-1 {sum(c.right for c in eff)}/{len(eff)} "
              f"({np.mean([c.right for c in eff]):.0%}); median held-out excess closed "
              f"{np.median(closed) if closed else math.nan:.0%} (n={len(closed)}); median "
              f"main-parameter error {np.median(perr) if perr else math.nan:.0%} "
              f"(n={len(perr)}); misses: "
              + ", ".join(f"{c.effect}/{c.size}->{c.verdict}"
                          + (f" kept {'+'.join(c.kept)} closed {c.closed:.2f}"
                             if len(c.names) == 2 else "")
                          for c in eff if not c.right))
        zs = np.abs([z for c in eff for z in c.param_z])
        if zs.size:
            print(f"  main-parameter error in standard errors (params_se): within 1 SE "
                  f"{np.sum(zs <= 1)}/{zs.size}, within 2 SE {np.sum(zs <= 2)}/{zs.size} "
                  f"(68 % and 95 % if the SE is right); median |z| {np.median(zs):.2f} "
                  f"(0.67); largest: " + ", ".join(
                      f"{c.effect}/{c.size} {z:+.1f}" for c in eff for z in c.param_z
                      if abs(z) > 2))
    if nul:
        strict = sum(c.verdict != "none" for c in nul)
        named = sum(c.verdict not in ("none", "base_model", "unexplained") for c in nul)
        print(f"  nulls: false alarms {strict}/{len(nul)} (any verdict but none); named an "
              f"unmodelled effect {named}/{len(nul)}; verdicts "
              f"{dict(Counter(c.verdict for c in nul))}")
    secs = [c.seconds for c in cs]
    if secs:
        print(f"  CLI wall time per case: median {np.median(secs):.0f} s, max {max(secs):.0f} s")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="clear magnitudes, 2 nulls per split")
    ap.add_argument("--set", default="tune,heldout", help="splits: tune,heldout")
    ap.add_argument("--cases", default="", help="comma list of effects (and/or none)")
    ap.add_argument("--jobs", type=int, default=1, help="CLI subprocesses at once")
    ap.add_argument("--keep", default=None, help="write the CSV/TOML/JSON here (kept)")
    ap.add_argument("--pairs", action="store_true",
                    help="acceptance 3: two withheld effects at once (PAIRS) instead")
    ap.add_argument("--more-pairs", action="store_true",
                    help="with --pairs: the pairs of MORE_PAIRS instead of PAIRS")
    ap.add_argument("--truth", action="store_true",
                    help="with --pairs: also run the truth model on each record")
    ap.add_argument("--weak-lines", action="store_true",
                    help="sines below the near-limit size (WEAK_LINES) instead")
    ap.add_argument("--line-shapes", action="store_true",
                    help="resonances of other line shapes (LINE_SHAPES) instead")
    args = ap.parse_args(argv)
    print(f"# bench_gap_blind {datetime.datetime.now():%Y-%m-%d %H:%M} {platform.node()} "
          f"{platform.machine()} cpus={os.cpu_count()} python {sys.version.split()[0]} "
          f"quick={args.quick} jobs={args.jobs}")
    only = tuple(c for c in args.cases.split(",") if c)
    with tempfile.TemporaryDirectory(prefix="gapblind-") as tmp:
        work = Path(args.keep) if args.keep else Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        (work / "model.toml").write_text(model_toml())
        results: dict[str, list[Case]] = {}
        for split in args.set.split(","):
            cases = (pair_cases(split, only, args.more_pairs) if args.pairs
                     else weak_line_cases(split) if args.weak_lines
                     else line_shape_cases(split) if args.line_shapes
                     else make_cases(split, args.quick, only))
            print(f"\n# split {split}: {len(cases)} cases")
            with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as ex:
                done = []
                for c in ex.map(lambda c: run_case(c, work, args.truth), cases):
                    show(c)
                    done.append(c)
                    if not args.keep:
                        for suffix in (".csv", ".json", ".truth.csv", ".truth.json",
                                       ".truth.toml"):
                            stem = f"{c.split}_{c.effect}_{c.size}_{c.data_seed}"
                            (work / f"{stem}{suffix}").unlink(missing_ok=True)
            results[split] = done
    for split, cs in results.items():
        summarise(f"split {split}", cs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
