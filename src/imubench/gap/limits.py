"""Detection limits on the user's own recording (``imubench gap --limits``).

Each effect is injected into the recording itself (its real noise is the background) at
decreasing sizes, :data:`INJECTIONS` times per size with different draws (phase, step
time, noise), and diagnosed with the same model; an injection counts as identified when
the forward selection keeps that effect. The search screens each size with
:data:`INJECTIONS` injections and stops at the first size identified in fewer than
:data:`RATE` of them; when the first size is missed, the larger :data:`UP_FACTORS` are
tried until one is identified. The smallest size that passed the screen is then
confirmed with :data:`CONFIRMATIONS` more injections, and it is the limit only when it
is identified in at least :data:`RATE` of all its injections; otherwise the next larger
size that passed is confirmed in the same way (downwards), or the search goes on upwards.
"90 %" is thus read as 5 of 5 at the limit: 3 of 3 alone is passed by an effect
identified 60 % of the time once in 4.6 (0.6^3 = 0.22; 5 of 5: 0.08). A coarse, bounded
estimate, stated as such in the JSON; and identification need not grow with the size
where a look-alike covers both the effect and the background's own departure (Samsung
S5 gx, second segment: a random walk confirmed 5 of 5 at 0.0068 dps/sqrt(s) was named
``telegraph`` and not kept at twice that, with the background's ~2 s wander).

The injections alternate in sign (:func:`injection_sign`: +, -, +, -, +), so a limit holds for
an added effect of either sign. The recording may already hold the effect below what the
diagnosis keeps, and a deterministic injection adds to it coherently: blind pair Markov
(4 mdps, 30 s) + temperature 1e-3 dps/degC, temperature not kept, gave a limit of
8.0e-4 dps/degC with positive injections only, identified because each injected record
held 1.8e-3 in all; 4e-4 more (1.4e-3 in all) was found once in three. The limit then
said that the recording's own 1e-3 would have been seen. A random effect's sign does not
matter (a random walk's or a sine's negative size is another draw).

Starting sizes come from the recording's own statistics (so the first size is usually
seen) and are multiplied by :data:`FACTORS`:

* sine: amplitude whose Hann-periodogram peak is ~30x the median continuum of the fit
  part, ``sqrt(90 S df)``, ``S`` the median one-sided Welch PSD, ``df = rate / n_fit``;
  at a fifth of the Nyquist frequency;
* ramp: ``R tau / sqrt(2) = 2 ADEV(tau)`` at ``tau = T / 8`` (IEEE 952 C.5);
* random_walk: ``K sqrt(tau / 3) = ADEV(tau)`` at ``tau = T / 8`` (C.4);
* flicker: ``0.664 B`` = the smallest ADEV of the record (C.3);
* temperature: ``c std(T) = ADEV(T / 8)`` (only with a temperature column);
* bias_step: 5 robust sigmas of the increments of the 256 block means the step test
  uses, at a random time in the middle 80 % of the record.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from lsm6ds_sim.model import NoiseModel

from imubench.gap import extras
from imubench.gap.curves import analysis_afs, oavar_at, welch_psd
from imubench.gap.diagnose import diagnose_channel
from imubench.gap.evidence import STEP_BLOCKS, block_means_of
from imubench.gap.parts import RecordTemperature, Series
from imubench.gap.result import GapOptions

FACTORS: tuple[float, ...] = (4.0, 2.0, 1.0, 0.5)
"""Sizes tried downwards, as multiples of the starting size, largest first."""
UP_FACTORS: tuple[float, ...] = (8.0, 16.0, 32.0, 64.0)
"""Sizes tried upwards when the first size is not identified (the starting size comes
from the recording's noise at T/8, which a short fit part may not reach, and a model
that departs from the recording leaves more for an effect to stand out from: on the
Samsung S5 gyros, whose flicker-only models miss a wander of their own, a random walk
was identified 2 times in 3 at 16x, and up to 16x no limit was stated)."""
INJECTIONS = 3
"""Injections per size screened."""
CONFIRMATIONS = 2
"""Injections added at the size that would be the limit (module docstring)."""
RATE = 0.9
"""Share of the injections that must be identified."""
REALISATIONS = 5
"""Realisations per diagnosis of an injection (fewer than the main diagnosis: time)."""
LIMIT_EFFECTS: tuple[str, ...] = ("sine", "ramp", "random_walk", "flicker", "temperature",
                                  "bias_step")
MAIN_KEY = {"sine": "sine_amplitude", "ramp": "ramp", "random_walk": "random_walk",
            "flicker": "flicker", "temperature": "temp_coeff", "bias_step": "step_size"}


def _adev_at(y: np.ndarray, rate_hz: float, tau_s: float) -> float:
    afs = analysis_afs(len(y), rate_hz)
    m = afs[np.argmin(np.abs(afs / rate_hz - tau_s))]
    return float(math.sqrt(oavar_at(y, rate_hz, np.array([m]))[0]))


def start_sizes(series: Series, holdout_fraction: float) -> dict[str, float]:
    """Starting size of each effect from the recording's own noise (module docstring)."""
    y, fs = series.y, series.rate_hz
    n = len(y)
    n_fit = max(64, round(n * (1.0 - holdout_fraction)))
    t_rec = n / fs
    a8 = _adev_at(y, fs, t_rec / 8.0)
    _, p = welch_psd(y, fs, min(n, 4096))
    out = {
        "sine": math.sqrt(90.0 * float(np.median(p[1:])) * fs / n_fit),
        "ramp": 2.0 * math.sqrt(2.0) * a8 / (t_rec / 8.0),
        "random_walk": a8 * math.sqrt(3.0 / (t_rec / 8.0)),
        "flicker": float(np.sqrt(np.min(oavar_at(y, fs, analysis_afs(n, fs))))) / 0.664,
    }
    if series.has_temperature:
        assert series.temp_c is not None
        sd = float(np.nanstd(series.temp_c))
        if sd > 0.01:
            out["temperature"] = a8 / sd
    m = block_means_of(y, max(1, n // STEP_BLOCKS))
    d = np.diff(m[np.isfinite(m)])
    out["bias_step"] = 5.0 * 1.4826 * float(np.median(np.abs(d - np.median(d))))
    return out


def inject(series: Series, effect: str, size: float, rng: np.random.Generator
           ) -> np.ndarray:
    """The recording plus ``effect`` of ``size`` (one draw)."""
    y, fs = series.y, series.rate_hz
    n = len(y)
    t = np.arange(n) / fs
    if effect == "sine":
        f0 = fs / 10.0 * (1.0 + 0.1 * rng.uniform(-1, 1))
        return y + size * np.sin(2 * math.pi * f0 * t + rng.uniform(0, 2 * math.pi))
    if effect == "ramp":
        return y + size * (t - t.mean())
    if effect == "random_walk":
        return y + np.cumsum(size * math.sqrt(1.0 / fs) * rng.standard_normal(n))
    if effect == "flicker":
        freq = np.fft.rfftfreq(n, 1.0 / fs)
        s = np.zeros_like(freq)
        s[1:] = size * size / (math.pi * freq[1:])
        sd = np.sqrt(s * fs * n / 4.0)
        return y + np.fft.irfft(sd * (rng.standard_normal(freq.size)
                                      + 1j * rng.standard_normal(freq.size)), n)
    if effect == "temperature":
        assert series.temp_c is not None
        return y + size * np.nan_to_num(series.temp_c - np.nanmean(series.temp_c))
    if effect == "bias_step":
        t0 = t[-1] * rng.uniform(0.1, 0.9)
        return y + extras.increment("bias_step", {"step_time_s": t0, "step_size": size},
                                    n, fs, 0)
    raise ValueError(f"no injection for {effect!r}")


def injection_sign(i: int) -> float:
    """The sign of injection ``i`` of a size: +1, -1, +1, ... (module docstring)."""
    return 1.0 if i % 2 == 0 else -1.0


def _hits(model: NoiseModel, channel: str, series: Series, opt: GapOptions, effect: str,
          size: float, key: list[int], first: int, count: int) -> int:
    """How many of injections ``first .. first + count - 1`` of ``effect`` at ``size`` the
    diagnosis keeps (injection ``i`` has its own draw and :func:`injection_sign`)."""
    hits = 0
    for i in range(first, first + count):
        rng = np.random.default_rng([*key, i])
        inj = Series(inject(series, effect, injection_sign(i) * size, rng), series.temp_c,
                     series.rate_hz, series.name)
        d = diagnose_channel(model, channel, inj,
                             replace(opt, seed=opt.seed + i, standard_errors=False))
        hits += any(c.effect == effect for c in d.kept)
    return hits


def _identified(entry: dict[str, Any]) -> bool:
    """A size's injections identified in at least :data:`RATE` of them."""
    return bool(entry["identified"] >= math.ceil(RATE * entry["of"] - 1e-9))


def _confirmed(passed: list[tuple[int, dict[str, Any]]], hits: Callable[..., int],
               key: list[int]) -> float | None:
    """The smallest size in ``passed`` (``(j, tried entry)``, largest first) that is also
    identified in :data:`RATE` of its injections with :data:`CONFIRMATIONS` more; the
    entries popped are updated in place. None: none is."""
    while passed:
        j, entry = passed.pop()
        entry["identified"] += hits(entry["size"], [*key, j], INJECTIONS, CONFIRMATIONS)
        entry["of"] += CONFIRMATIONS
        if _identified(entry):
            return float(entry["size"])
    return None


def detection_limits(model: NoiseModel, channel: str, series: Series,
                     options: GapOptions, effects: tuple[str, ...] | None = None
                     ) -> dict[str, Any]:
    """The ``limits`` JSON block of one channel (module docstring)."""
    wanted = [e for e in (effects or LIMIT_EFFECTS) if e in options.effects]
    starts = start_sizes(series, options.holdout_fraction)
    opt = replace(options, realisations=min(REALISATIONS, options.realisations))
    out: dict[str, Any] = {}
    for k, eff in enumerate(wanted):
        if eff not in starts:
            continue
        if eff == "temperature":
            why = RecordTemperature(model[channel], series).note
            if why:  # no injection can be identified (an outside reviewer: 9 spent)
                out[eff] = {"key": MAIN_KEY[eff], "smallest_identified": None, "tried": [],
                            "smallest_tried_identified": False, "not_searched": why}
                continue
        hits = functools.partial(_hits, model, channel, series, opt, eff)
        tried: list[dict[str, Any]] = []
        passed: list[tuple[int, dict[str, Any]]] = []  # (j, its entry), as screened
        smallest: float | None = None
        # downwards from FACTORS[0] while identified; upwards when nothing down there is
        up = False
        for j, factor in enumerate((*FACTORS, *UP_FACTORS)):
            if (j < len(FACTORS)) == up:
                continue
            size = starts[eff] * factor
            entry = {"size": size, "identified": hits(size, [options.seed, 0x11, k, j], 0,
                                                      INJECTIONS), "of": INJECTIONS}
            tried.append(entry)
            if _identified(entry):
                passed.append((j, entry))
                if not up and j < len(FACTORS) - 1:
                    continue  # screen the next smaller size
            elif up:
                continue
            smallest = _confirmed(passed, hits, [options.seed, 0x11, k])
            if smallest is not None:
                break
            up = True
        out[eff] = {"key": MAIN_KEY[eff], "smallest_identified": smallest, "tried": tried,
                    "smallest_tried_identified": bool(
                        smallest is not None and smallest == min(t["size"] for t in tried))}
    return {"rate_required": RATE, "injections_per_size": INJECTIONS,
            "confirmations": CONFIRMATIONS,
            "realisations": opt.realisations, "factors": list(FACTORS),
            "up_factors": list(UP_FACTORS), "note": COARSE, "effects": out}


COARSE = (f"coarse: {INJECTIONS} injections per size screened, {CONFIRMATIONS} more at the "
          f"limit (90 % read as {INJECTIONS + CONFIRMATIONS} of "
          f"{INJECTIONS + CONFIRMATIONS}), sizes a factor 2 apart, stopping at the first "
          "size identified less often than required; a limit may be off by a factor of 2 "
          "either way (two records of the same noise gave limits 1.8-2.4x apart), and where "
          "the smallest size tried was identified it is an upper bound")
"""What the limits are and are not (JSON ``limits.note``, and the text)."""
