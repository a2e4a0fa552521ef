"""Coverage of the jig's 95 % intervals on simulated boards whose truth is known.

Runs ``imubench jig run`` on ``config/station-sim.toml`` (a simulated LSM6DSL with the
datasheet-typical model) with the DUT's seed set to each of ``--seeds A:B``, and counts
how often each interval holds the truth: the model's ``temp_coeff`` per channel for
``temperature_coefficient.*`` (dps/degC; mg/degC for the accelerometer) and 0 for
``gyro_sensitivity.*`` (the model has no scale error). Prints, per measurement, the
coverage, the mean and spread of z = (value - truth) / (half-width / 1.96) and the mean
half-width. Run: ``.venv/bin/python bench/bench_jig_coverage.py --seeds 1:25``; figures go
to docs/benchmarks.md by hand.

The reference is the nominal confidence itself (95 %): a binomial 95 % range for 24
boards is 21-24 of 24 per channel, 132-141 of 144 over six channels.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
STATION = REPO / "config" / "station-sim.toml"
MODEL = REPO / "simulator" / "lsm6ds_sim" / "datasheet" / "lsm6dsl.toml"


def truths() -> dict[str, float]:
    model = tomllib.loads(MODEL.read_text())["channels"]
    out = {f"gyro_sensitivity.{ch}": 0.0 for ch in ("gx", "gy", "gz")}
    for ch, c in model.items():
        scale = 1e3 if ch.startswith("a") else 1.0  # g -> mg
        out[f"temperature_coefficient.{ch}"] = scale * float(c.get("temp_coeff", 0.0))
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="1:25", help="A:B, seeds A to B-1")
    args = ap.parse_args()
    a, b = (int(x) for x in args.seeds.split(":"))
    truth = truths()
    rows: dict[str, list[tuple[float, float, float]]] = {k: [] for k in truth}
    station_text = STATION.read_text().replace('limits = "limits-lsm6dsl.toml"',
                                               f'limits = "{REPO / "config"}/limits-lsm6dsl.toml"')
    with tempfile.TemporaryDirectory(prefix="bench-jig-cov-") as tmp:
        for seed in range(a, b):
            st = Path(tmp) / f"station_{seed}.toml"
            st.write_text(station_text.replace("seed=1&", f"seed={seed}&"))
            rep = Path(tmp) / f"rep_{seed}"
            proc = subprocess.run([sys.executable, "-m", "imubench.cli", "jig", "run",
                                   "--station", str(st), "--serial", f"COV-{seed}",
                                   "--report", str(rep)], capture_output=True, text=True,
                                  cwd=REPO, env=os.environ)
            found = sorted(rep.rglob("result.json"))  # PASS 0, FAIL 1, INCONCLUSIVE 3
            if not found:
                sys.exit(f"seed {seed}: jig run exited {proc.returncode}\n{proc.stderr[-2000:]}")
            result = json.loads(found[-1].read_text())
            for m in result["measurements"]:
                if m["name"] in rows:
                    rows[m["name"]].append((m["value"], m["ci_low"], m["ci_high"]))
            print(f"seed {seed}: {result['verdict']}", flush=True)
    total = hit = 0
    for name, vals in rows.items():
        v = np.array(vals)
        t = truth[name]
        covered = int(np.sum((v[:, 1] <= t) & (t <= v[:, 2])))
        half = (v[:, 2] - v[:, 1]) / 2.0
        z = (v[:, 0] - t) / (half / 1.96)
        total += len(v)
        hit += covered
        print(f"{name:32s} covered {covered}/{len(v)}  mean z {z.mean():+.2f}  sd z "
              f"{z.std(ddof=1):.2f}  mean half-width {half.mean():.3g}")
    print(f"all: {hit}/{total} ({hit / total:.1%}) against 95 %")


if __name__ == "__main__":
    main()
