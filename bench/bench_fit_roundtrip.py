"""Round trip of the noise fit on an independent generator (issue 14, acceptance 2).

White N + flicker B + random walk K written directly with numpy (``tests/independent_noise.py``:
circulant-embedding flicker, exact interval-mean random walk; not the project's simulator),
default 3 h at 100 Hz, N 0.004 dps/sqrt(Hz), B 0.0015 dps, K 1e-4 dps/sqrt(s), over
--seeds seeds. B is the project's coefficient: one-sided rate PSD B^2/(pi f) at low f,
ADEV floor 0.664 B (``imubench.noisefit.units``). Each record is fitted with ``wls`` and
``whittle`` (``--terms auto`` model selection, or a fixed list); per method and term it
prints the median relative error, the coverage of the 95 % intervals (a term judged absent
counts with its (0, upper limit) interval, and with error 100 %), how often each true term
was dropped, how often a term the truth lacks was reported, and the fit time per channel.
Prints tables; no asserts.

    .venv/bin/python bench/bench_fit_roundtrip.py [--seeds 50] [--hours 3] [--terms auto]
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from imubench.noisefit import fit_channel

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from independent_noise import white_flicker_walk

RATE_HZ = 100.0
TRUTH: dict[str, float] = {"white": 0.004, "flicker": 0.0015, "random_walk": 1e-4}
METHODS = ("wls", "whittle")
TARGET_ERR = {"white": 0.02, "flicker": 0.10, "random_walk": 0.15}
EXTRA = ("quantization", "ramp", "markov_sigma", "sine_amplitude", "bandwidth_hz")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--first-seed", type=int, default=1000)
    ap.add_argument("--hours", type=float, default=3.0)
    ap.add_argument("--terms", default="auto")
    args = ap.parse_args()
    n = round(args.hours * 3600 * RATE_HZ)
    value: dict[str, dict[str, list[float]]] = {m: {k: [] for k in TRUTH} for m in METHODS}
    hit: dict[str, dict[str, list[bool]]] = {m: {k: [] for k in TRUTH} for m in METHODS}
    kept: dict[str, dict[str, list[bool]]] = {m: {k: [] for k in TRUTH} for m in METHODS}
    false: dict[str, list[int]] = {m: [] for m in METHODS}
    times: dict[str, list[float]] = {m: [] for m in METHODS}
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        y = white_flicker_walk(n, RATE_HZ, seed=seed, **TRUTH)
        line = [f"seed {seed}"]
        for method in METHODS:
            t0 = time.perf_counter()
            fit = fit_channel(y, RATE_HZ, method=method, terms=args.terms)
            times[method].append(time.perf_counter() - t0)
            for key, true in TRUTH.items():
                lo, hi = fit.ci.get(key, (math.nan, math.nan))
                value[method][key].append(fit.params[key] / true)
                hit[method][key].append(bool(lo <= true <= hi))
                kept[method][key].append(key in fit.present)
            false[method].append(sum(1 for k in EXTRA if k in fit.present))
            line.append(f"{method} " + " ".join(f"{fit.params[k] / v:.3f}"
                                                for k, v in TRUTH.items()))
        print("  ".join(line), flush=True)

    print(f"\n# round trip, {args.seeds} seeds, {args.hours:g} h at {RATE_HZ:g} Hz, terms "
          f"{args.terms}; {datetime.date.today()}, {platform.machine()}, "
          f"{os.cpu_count()} cores (shared)")
    print("| method | term | median rel. error | target | 95 % coverage | kept | "
          "mean ratio | sd ratio |")
    print("|---|---|---|---|---|---|---|---|")
    for method in METHODS:
        for key in TRUTH:
            v = np.array(value[method][key])
            print(f"| {method} | {key} | {100 * np.median(np.abs(v - 1)):.1f} % | "
                  f"<= {100 * TARGET_ERR[key]:.0f} % | "
                  f"{100 * np.mean(hit[method][key]):.0f} % | "
                  f"{int(np.sum(kept[method][key]))}/{v.size} | {v.mean():.3f} | "
                  f"{v.std(ddof=1):.3f} |")
    print("\n| method | fits with a term the truth lacks | median time / channel (s) |")
    print("|---|---|---|")
    for method in METHODS:
        print(f"| {method} | {sum(1 for c in false[method] if c)}/{len(false[method])} | "
              f"{np.median(times[method]):.2f} |")
    print(f"\ntime ratio wls / whittle (medians): "
          f"{np.median(times['wls']) / np.median(times['whittle']):.2f}")


if __name__ == "__main__":
    main()
