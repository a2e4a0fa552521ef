"""Acceptance figures of the noise fit (issue 7, items 1-3). Prints tables; no asserts.

Round trip: simulate() records (default 3 h at 100 Hz) with known terms over --seeds
seeds; fit with ``wls`` (auto model selection) and ``tangent``; report per parameter the
coverage of the 95 % intervals, the median relative error, and how often each absent term
is reported absent. Real data: fit ADIS16405 replicate 1 (../shared/reference/imu-real),
predict the OADEV of replicates 2 and 3, compare with replicate 1's raw OADEV as predictor.

    .venv/bin/python bench/bench_fit.py [--seeds 50] [--hours 3] [--part all|sim|real]
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import time
from pathlib import Path

import numpy as np
from lsm6ds_sim.model import NoiseModel
from lsm6ds_sim.physics import simulate

from imubench.noisefit import fit_channel
from imubench.noisefit.fit import BASE_TERMS
from imubench.noisefit.kernels import AMPLITUDE_KEY
from imubench.stats import oadev

RATE = 100.0
SCENARIOS: dict[str, dict[str, float]] = {
    "white+flicker+rw": {"white": 0.004, "flicker": 0.002, "random_walk": 2e-4},
    "gauss-markov": {"white": 0.004, "markov_sigma": 0.01, "markov_tau": 5.0},
    "ramp": {"white": 0.004, "flicker": 0.002, "ramp": 1e-5},
    "sinusoid": {"white": 0.004, "sine_amplitude": 0.01, "sine_freq": 0.5},
}
ALL_TERMS = {AMPLITUDE_KEY[t] for t in BASE_TERMS} | {"markov_sigma", "sine_amplitude",
                                                      "bandwidth_hz", "resonance_height"}
REFERENCE = Path(__file__).resolve().parents[2] / "shared" / "reference" / "imu-real"


def round_trip(name: str, truth: dict[str, float], seeds: int, n: int) -> None:
    model = NoiseModel.single_term("gx", **truth)
    stats: dict[str, dict[str, list[float]]] = {"wls": {}, "tangent": {}}
    absent_ok: dict[str, list[bool]] = {k: [] for k in ALL_TERMS if k not in truth}
    t_fit = []
    for seed in range(1, seeds + 1):
        y = simulate(model, n, RATE, seed, channels=["gx"])["gx"]
        t0 = time.perf_counter()
        f = fit_channel(y, RATE)
        t_fit.append(time.perf_counter() - t0)
        for key, v in truth.items():
            lo, hi = f.ci.get(key, (math.nan, math.nan))
            stats["wls"].setdefault(key + ":cover", []).append(float(lo <= v <= hi))
            stats["wls"].setdefault(key + ":err", []).append(abs(f.params[key] / v - 1.0))
        for key in absent_ok:
            absent_ok[key].append(key not in f.present)
        if any(k in truth for k in ("white", "flicker", "random_walk")):
            t = fit_channel(y, RATE, method="tangent")
            for key in ("white", "flicker", "random_walk"):
                if key in truth:
                    lo, hi = t.ci[key]
                    stats["tangent"].setdefault(key + ":cover", []).append(
                        float(lo <= truth[key] <= hi))
                    stats["tangent"].setdefault(key + ":err", []).append(
                        abs(t.params[key] / truth[key] - 1.0))
    print(f"\n### {name}: {truth}  ({seeds} seeds, {n / RATE / 3600:.2f} h at {RATE:g} Hz; "
          f"fit {np.median(t_fit):.1f} s median)")
    print("| parameter | wls coverage 95% | wls median rel. err | tangent coverage | "
          "tangent median rel. err |")
    print("|---|---|---|---|---|")
    for key in truth:
        w_c = np.mean(stats["wls"][key + ":cover"])
        w_e = np.median(stats["wls"][key + ":err"])
        if key + ":cover" in stats["tangent"]:
            t_c = f"{100 * np.mean(stats['tangent'][key + ':cover']):.0f} %"
            t_e = f"{100 * np.median(stats['tangent'][key + ':err']):.1f} %"
        else:
            t_c = t_e = "-"
        print(f"| {key} | {100 * w_c:.0f} % | {100 * w_e:.1f} % | {t_c} | {t_e} |")
    print("absent terms reported absent: " + ", ".join(
        f"{k} {100 * np.mean(v):.0f} %" for k, v in sorted(absent_ok.items())))


def _adis(rep: int) -> dict[str, np.ndarray]:
    d = np.load(REFERENCE / "adis16405" / f"adis16405_rep{rep}.npz")
    g = d["gyro_counts"].astype(float) * float(d["gyro_lsb_dps"])
    a = d["accel_counts"].astype(float) * float(d["accel_lsb_g"])
    chans = dict(zip(("gx", "gy", "gz"), g.T, strict=True))
    chans.update(zip(("ax", "ay", "az"), a.T, strict=True))
    return chans


def real_data() -> None:
    if not (REFERENCE / "adis16405").is_dir():
        print("ADIS16405 reference data not found; skipped")
        return
    reps = {r: _adis(r) for r in (1, 2, 3)}
    n = reps[1]["gx"].size
    print(f"\n### ADIS16405: fit replicate 1, predict replicates 2 and 3 "
          f"(octave taus up to T/10 = {n / RATE / 10:.0f} s)")
    print("| axis | terms (rep1 fit) | rep | RMS ln(meas/model) | RMS ln(meas/rep1 raw) | "
          "ratio | pass (<= 1.1) |")
    print("|---|---|---|---|---|---|---|")
    passed = total = 0
    for ch in ("gx", "gy", "gz", "ax", "ay", "az"):
        t0 = time.perf_counter()
        f = fit_channel(reps[1][ch], RATE, channel=ch)
        dt = time.perf_counter() - t0
        r1 = oadev(reps[1][ch], RATE, "freq", "octave")
        keep = r1.tau_s <= n / RATE / 10
        tau = r1.tau_s[keep]
        pred = np.sqrt(f.model_avar(tau))
        terms = ",".join(k for k in f.present if k != "filter_order")
        for rep in (2, 3):
            meas = oadev(reps[rep][ch], RATE, "freq", list(tau)).dev
            e_model = float(np.sqrt(np.mean(np.log(meas / pred) ** 2)))
            e_raw = float(np.sqrt(np.mean(np.log(meas / r1.dev[keep]) ** 2)))
            ok = e_model <= 1.1 * e_raw
            passed += ok
            total += 1
            print(f"| {ch} | {terms} ({dt:.0f} s) | {rep} | {e_model:.4f} | {e_raw:.4f} | "
                  f"{e_model / e_raw:.2f} | {'yes' if ok else 'NO'} |")
    print(f"passed {passed}/{total} = {100 * passed / total:.0f} % (acceptance: >= 80 %)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--hours", type=float, default=3.0)
    ap.add_argument("--part", choices=("all", "sim", "real"), default="all")
    ap.add_argument("--scenario", default=None, help="one scenario name only")
    args = ap.parse_args()
    print(f"# bench_fit  {platform.node()} {platform.processor() or platform.machine()} "
          f"cpus={os.cpu_count()}  {time.strftime('%Y-%m-%d')}")
    n = round(args.hours * 3600 * RATE)
    if args.part in ("all", "real"):
        real_data()
    if args.part in ("all", "sim"):
        for name, truth in SCENARIOS.items():
            if args.scenario is None or args.scenario == name:
                round_trip(name, truth, args.seeds, n)


if __name__ == "__main__":
    main()
