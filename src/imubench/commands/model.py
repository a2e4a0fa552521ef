"""``imubench model``: the OADEV a noise model file predicts, per channel.

``imubench model MODEL.toml --rate HZ --taus SPEC [--n N] [--json PATH|-]`` prints (or
writes as ``{"channels": {"gx": {"tau_s": [...], "dev": [...]}}}``) the Allan deviation of
each channel that carries noise, at the taus of SPEC (``octave``, ``decade``, ``all``, an
integer = points per decade, or a comma list of seconds). Keyword SPECs need ``--n`` (the
record length in samples: taus stop at the OADEV limit N/4). With ``--n`` each channel also
gets ``edf`` and the 68.3 % ``ci_low``/``ci_high`` a recording of N samples would show
(Greenhall EDF for the noise type of the model's local slope). The AVAR is exact for
sampled data (closed forms where they exist; the output filter from the model's
autocovariance, i.e. its spectrum): see docs/noise-fit.md.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np
from lsm6ds_sim.model import ChannelModel, NoiseModel, load_model

from imubench.batch import CHANNELS
from imubench.commands import write_json
from imubench.noisefit.errors import FitError
from imubench.noisefit.identify import local_slopes
from imubench.noisefit.model_avar import model_avar_m


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "model",
        help="Allan deviation a noise model file predicts (per channel)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", type=Path, help="noise model file (TOML)")
    p.add_argument("--rate", type=float, required=True, help="sample rate in Hz")
    p.add_argument("--taus", required=True,
                   help="octave | decade | all | N (points per decade) | comma list of tau_s")
    p.add_argument("--n", type=int, default=None,
                   help="record length in samples (needed by keyword taus; adds EDF and CI)")
    p.add_argument("--json", default=None, metavar="PATH|-", help="write JSON here")
    p.set_defaults(func=run)


MAX_FACTOR = 2**24
"""Largest averaging factor (samples) the model's AVAR is computed at: the exact AVAR
sums the autocovariance over 2 m lags (134 MB at this m; 45 h at 104 Hz)."""


def _factors(spec: str, rate_hz: float, n: int | None) -> np.ndarray:
    """Averaging factors of ``--taus``: a list of seconds must hold whole numbers of
    samples at ``rate_hz`` (no tau is moved or dropped without a word), keywords stop at
    N/4; every factor at most :data:`MAX_FACTOR`."""
    from imubench.stats.taus import averaging_factors, parse_taus

    taus = parse_taus(spec)
    if isinstance(taus, list):
        t = np.asarray(taus, dtype=np.float64)
        for tau in t:
            if not (math.isfinite(tau) and tau > 0):
                raise FitError(f"--taus {spec}: tau {tau:g} s is not a positive time")
            m = tau * rate_hz
            if m < 0.5 or abs(m - round(m)) > 1e-6 * max(m, 1.0):
                raise FitError(f"--taus {spec}: tau {tau:g} s is {m:.6g} samples at "
                               f"{rate_hz:g} Hz; give whole multiples of {1 / rate_hz:g} s")
        m = np.unique(np.rint(t * rate_hz).astype(np.int64))
        if n is not None and m.max() > max((n - 1) // 4, 1):
            raise FitError(f"--taus {spec}: tau {m.max() / rate_hz:g} s is beyond N/4 = "
                           f"{max((n - 1) // 4, 1)} samples of a record of --n {n}")
    elif n is None:
        raise FitError(f"--taus {spec}: a keyword or points-per-decade spec (an integer "
                       "is points per decade; write 1.0 for one second) needs --n (record "
                       "length in samples) to know where to stop")
    else:
        m = averaging_factors("oadev", n - 1, taus, 1.0 / rate_hz)
    if m.size and m.max() > MAX_FACTOR:
        raise FitError(f"--taus {spec}: tau {m.max() / rate_hz:g} s is {m.max():.3g} samples "
                       f"at {rate_hz:g} Hz; the largest computed is {MAX_FACTOR} "
                       f"({MAX_FACTOR / rate_hz:.4g} s)")
    return m


def _expected_ci(tau: np.ndarray, avar: np.ndarray, m: np.ndarray, n: int) -> dict[str, Any]:
    from imubench.stats.confidence import confidence_arrays

    slope = local_slopes(tau, np.sqrt(avar)) if tau.size > 1 else np.array([-0.5])
    alpha = np.clip(np.rint(-2.0 * slope - 1.0), -2, 2).astype(int)
    edfs, lo, hi = confidence_arrays("oavar", alpha, m, n, avar, 0.683)
    return {"edf": edfs.tolist(), "ci_low": np.asarray(lo).tolist(),
            "ci_high": np.asarray(hi).tolist(), "alpha": alpha.tolist()}


NOISE_KEYS = ("white", "flicker", "random_walk", "ramp", "quantization", "markov_sigma",
              "sine_amplitude", "outlier_rate", "output_white", "resonance_height")
"""A channel with one of these away from its quiet value carries noise."""


def predict(model: NoiseModel, rate_hz: float, spec: str, n: int | None) -> dict[str, Any]:
    """The ``{"channels": {...}}`` document for every channel that carries noise."""
    if not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise FitError(f"--rate must be > 0 Hz, got {rate_hz}")
    if n is not None and n < 8:
        raise FitError(f"--n must be at least 8 samples, got {n}")
    m = _factors(spec, rate_hz, n)
    if m.size == 0:
        raise FitError(f"--taus {spec}: no averaging time left (need tau >= 1/rate"
                       + (f" and <= N/4 samples with N={n}" if n else "") + ")")
    quiet = ChannelModel()
    noisy = [ch for ch in CHANNELS
             if any(getattr(model[ch], k) != getattr(quiet, k) for k in NOISE_KEYS)]
    if not noisy:
        raise FitError(f"{model.source}: gives no channel any noise; nothing to predict")
    out: dict[str, Any] = {"rate_hz": rate_hz, "channels": {}}
    for ch in noisy:
        cm = model[ch]
        avar = model_avar_m(cm, m, rate_hz)
        tau = m / rate_hz
        entry: dict[str, Any] = {"tau_s": tau.tolist(), "dev": np.sqrt(avar).tolist()}
        if n is not None:
            entry.update(_expected_ci(tau, avar, m, n))
        out["channels"][ch] = entry
    return out


def run(args: argparse.Namespace) -> int:
    doc = predict(load_model(args.model), args.rate, args.taus, args.n)
    if args.json is None:
        for ch, e in doc["channels"].items():
            print(f"# {ch}")
            print(f"{'tau_s':>12} {'dev':>12}")
            for t, d in zip(e["tau_s"], e["dev"], strict=True):
                print(f"{t:>12.5e} {d:>12.5e}")
    else:
        write_json(doc, args.json)
    return 0
