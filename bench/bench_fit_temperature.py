"""``imubench fit --fit-temperature``: the response it takes out, and the noise it leaves.

Usage: ``PYTHONPATH=src:drivers:simulator .venv/bin/python bench/bench_fit_temperature.py
[--part generator,dominant,cats] [--seeds 3]``

Both parts go through the fit's public engine on a recording file
(``imubench.noisefit.recording_fit.fit_recording``, a native ``.imbr`` written here), once
as ``imubench fit`` runs by default and once with ``fit_temperature=True``.

**generator**: a numpy generator written here (not the project's simulator): white 0.004
dps/sqrt(Hz) + random walk K (3e-5 or 3e-4 dps/sqrt(s)) + ``c (T - 25)``, c in {0, 1e-3,
3e-3} dps/degC, one hour at 52 Hz, the temperature a 25 +- 4 degC cycle of 900 s, a
20 -> 30 degC warm-up or a 30 -> 20 degC cool-down (time constant 600 s, read with 0.05
degC of noise). Printed per history, K and c: responses taken out, the median |z| of the
taken-out coefficient against the truth and the share within 2 standard errors, and the
long-tau terms of the model (ramp or flicker present; random walk over its truth) by
default and with the response taken out. Nulls (c = 0) must never have one taken out.

**dominant**: the same at 10 Hz with c in {0, 0.01, 0.03} dps/degC: responses that
dominate the record, which the first fit takes for a random walk (the second screen of
``_fit_with_temperature``); the nulls check that screen.

**cats**: the CATS tag's temperature-calibration run (../shared/reference/imu-real/
cats-tag-temperature/, 1 Hz, an MPU-9250-class part nobody tuned this on): three static
orientations x 6 axes, each orientation cut into three segments of 7.7-8.5 h. The response
is fitted on one segment and judged on the two others, which the fit never saw: the share
of their 600 s block means' variance about a straight line that taking the fitted response
out removes (``explained``; negative: the response makes that segment worse).
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from imubench.batch import CHANNELS, Batch
from imubench.noisefit.fit import ChannelFit
from imubench.noisefit.recording_fit import fit_recording
from imubench.recording import open_writer

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_gap_real_temperature import CATS, G  # the CATS tag's folder, g in m/s2

RATE = 52.0
DOMINANT_RATE = 10.0
"""Rate of the ``dominant`` part: responses of 0.01 and 0.03 dps/degC that the first fit
takes for its noise (a random walk of ~0.015 dps/sqrt(s) and no white term)."""
WHITE = 0.004
BLOCK_S = 600


def write_imbr(tmp: Path, channel: str, y: np.ndarray, temp: np.ndarray, rate: float
               ) -> Path:
    """A new native recording in ``tmp`` holding ``y`` on ``channel`` (the others zero)
    and ``temp``."""
    path = tmp / f"r{len(list(tmp.glob('*.imbr')))}.imbr"
    n = len(y)
    values = np.zeros((n, len(CHANNELS)))
    values[:, CHANNELS.index(channel)] = y
    idx = np.arange(n, dtype=np.int64)
    with open_writer(path, {"odr_hz": rate}) as w:
        w.write(Batch(idx, idx / rate, values, temp))
    return path


def fit_both(path: Path, channel: str) -> tuple[ChannelFit, ChannelFit]:
    """(default fit, fit with the temperature response taken out) of ``channel``."""
    return (fit_recording(path, channels=[channel]).fits[channel],
            fit_recording(path, channels=[channel], fit_temperature=True).fits[channel])


def history(kind: str, rng: np.random.Generator, n: int, rate: float) -> np.ndarray:
    t = np.arange(n) / rate
    if kind == "cycle":
        return 25.0 + 4.0 * np.sin(2 * np.pi * t / 900.0)
    rise = 10.0 * (1.0 - np.exp(-t / 600.0))
    base = 20.0 + rise if kind == "warm-up" else 30.0 - rise
    return base + 0.05 * rng.standard_normal(n)


def long_terms(f: ChannelFit) -> str:
    return "+".join(t for t in ("ramp", "flicker", "random_walk") if t in f.present) or "-"


def generator(seeds: int, tmp: Path, rate: float = RATE,
              coeffs: tuple[float, ...] = (0.0, 1e-3, 3e-3)) -> None:
    n = int(3600 * rate)
    print(f"\n## generator (1 h at {rate:g} Hz; white 0.004 dps/sqrt(Hz))")
    print("| history | K dps/sqrt(s) | c dps/degC | taken out | median abs z | within 2 SE "
          "| long-tau terms, default | with --fit-temperature | K fitted / K, default | "
          "with |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for kind in ("cycle", "warm-up", "cool-down"):
        for walk in (3e-5, 3e-4):
            for coeff in coeffs:
                taken, zs, raw_terms, terms, raw_k, k = 0, [], [], [], [], []
                for seed in range(seeds):
                    rng = np.random.default_rng(1000 * seed + int(coeff * 1e4) + int(walk * 1e6))
                    temp = history(kind, rng, n, rate)
                    y = (WHITE * np.sqrt(rate) * rng.standard_normal(n)
                         + np.cumsum(walk / np.sqrt(rate) * rng.standard_normal(n))
                         + coeff * (temp - 25.0))
                    raw, fit = fit_both(write_imbr(tmp, "gx", y, temp, rate), "gx")
                    if fit.temperature is not None:
                        taken += 1
                        zs.append((fit.temperature.temp_coeff - coeff)
                                  / fit.temperature.temp_coeff_se)
                    raw_terms.append(long_terms(raw))
                    terms.append(long_terms(fit))
                    raw_k.append(raw.params.get("random_walk", 0.0) / walk)
                    k.append(fit.params.get("random_walk", 0.0) / walk)
                az = np.abs(zs)
                print(f"| {kind} | {walk:g} | {coeff:g} | {taken}/{seeds} | "
                      f"{np.median(az) if zs else math.nan:.2f} | "
                      f"{(az < 2).sum() if zs else '-'}/{len(zs)} | {', '.join(raw_terms)} | "
                      f"{', '.join(terms)} | {np.median(raw_k):.2f} | {np.median(k):.2f} |",
                      flush=True)


def block_means(v: np.ndarray) -> np.ndarray:
    m = len(v) // BLOCK_S * BLOCK_S
    return v[:m].reshape(-1, BLOCK_S).mean(1)


def about_line(v: np.ndarray) -> float:
    x = np.column_stack([np.ones(len(v)), np.arange(len(v))])
    return float(np.var(v - x @ np.linalg.lstsq(x, v, rcond=None)[0]))


def cats(tmp: Path) -> None:
    npz = CATS / "cats_temperature_calib.npz"
    if not npz.is_file():
        print(f"cats: skipped, no reference data at {npz}")
        return
    z = np.load(npz)
    fs = float(z["fs_hz"])
    rows = [r.split(",") for r in (CATS / "events.csv").read_text().splitlines()[1:]
            if r.startswith("static,")]
    print("\n## cats (fit on one segment, judged on the two others)")
    explained: list[float] = []
    taken = cases = 0
    for o, row in enumerate(rows):
        i0, i1 = int(row[1]), int(row[2])
        n = (i1 - i0) // 3
        temp_all = z["temperature_c"][i0:i1]
        for ch in ("gx", "gy", "gz", "ax", "ay", "az"):
            i = "xyz".index(ch[1])
            y_all = (np.degrees(z["gyro_mrad_s"][i0:i1, i] / 1000.0) if ch[0] == "g"
                     else z["accel_m_s2"][i0:i1, i] / G)
            for seg in range(3):
                sl = slice(seg * n, (seg + 1) * n)
                raw, fit = fit_both(write_imbr(tmp, ch, y_all[sl], temp_all[sl],
                                               fs), ch)
                cases += 1
                tr = fit.temperature
                if tr is None:
                    why = next((x for x in raw.notes if "die temperature" in x), "")
                    print(f"  o{o} {ch} seg{seg}: not taken out; long-tau {long_terms(raw)}"
                          + (f" ({why.split('; ', 1)[-1][:90]}...)" if why else ""))
                    continue
                taken += 1
                out = []
                hz = tr.halves_z if tr.halves_z is not None else math.nan
                for other in (k for k in range(3) if k != seg):
                    so = slice(other * n, (other + 1) * n)
                    yb, tb = block_means(y_all[so]), block_means(temp_all[so])
                    e = 1.0 - about_line(yb - tr.response(tb)) / about_line(yb)
                    explained.append(e)
                    out.append(f"seg{other} {e:+.0%}")
                print(f"  o{o} {ch} seg{seg}: {tr.temp_coeff:+.4g} +- {tr.temp_coeff_se:.2g} "
                      f"(t {tr.t:.1f}, halves z {hz:.1f}, "
                      f"-log L gain {tr.likelihood_gain:.0f}); long-tau {long_terms(raw)} -> "
                      f"{long_terms(fit)}; explained on {', '.join(out)}", flush=True)
    e = np.array(explained)
    print(f"\n  taken out on {taken}/{cases} segments; on the segments not fitted: median "
          f"explained {np.median(e):+.0%}, >= 50 % on {(e >= 0.5).sum()}/{len(e)}, worse "
          f"(< 0) on {(e < 0).sum()}/{len(e)}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="generator,cats")
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args(argv)
    print(f"# bench_fit_temperature {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC "
          f"{platform.node()} cpus={os.cpu_count()} load {os.getloadavg()[0]:.1f} "
          f"part={args.part} seeds={args.seeds}", flush=True)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as d:
        parts = args.part.split(",")
        if "generator" in parts:
            generator(args.seeds, Path(d))
        if "dominant" in parts:
            generator(args.seeds, Path(d), DOMINANT_RATE, (0.0, 0.01, 0.03))
        if "cats" in parts:
            cats(Path(d))
    print(f"\n({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
