"""The temperature candidate of ``imubench gap`` on a real sensor's own temperature.

Usage: ``PYTHONPATH=src:drivers:simulator .venv/bin/python bench/bench_gap_real_temperature.py
[--axes gx,gy,gz,ax,ay,az] [--orientations 0,1,2] [--model-less-temperature]``

Data: the CATS tag's temperature-calibration run
(``../shared/reference/imu-real/cats-tag-temperature/``, 1 Hz, 74.5 h, an MPU-9250-class
part nobody tuned the diagnosis on; gyro mrad/s converted to dps, accelerometer m/s2 to
g), its three static orientations (events.csv, gravity on -z, -x, -y; 23-26 h each), each
cut into three equal segments of 7.7-8.5 h. The temperature cycles between 5 and 24 degC,
often in one half of a segment only (a warm-up or a cool-down that starts or ends
mid-segment).

Per orientation and axis: the model is the noise fit of segment 0 (``imubench fit``'s
engine, ``terms="auto"``, no temperature term; with ``--model-less-temperature`` fitted to
segment 0 less the least-squares response to its temperature, as an engineer who has
calibrated the response would); segments 1 and 2 are diagnosed with their REAL
temperature column (``diagnose_channel``, default options: holdout 0.5, 10 realisations,
seed 7), as a user would run ``imubench gap`` on them.

References, from methods the diagnosis does not use: the least-squares slope of the
segment's 600 s block means on the block temperatures and its Pearson r; the same on the
OTHER test segment (out of sample: data the diagnosis of this segment never saw). A
segment holds a clear response when |r| >= R_CLEAR on it, none when |r| < R_NONE (the rest
are not scored). Printed: per case, the verdict, the kept effects and a kept
temperature's coefficient +- its standard error and where it was fitted
(``fitted_on``); summary: clear responses named ``temperature`` (kept), responses named
where there is none, and the median |fitted / reference - 1| against this segment's and the
other segment's slope, over all segments and over those without a handling event
(events.csv lists a 49 s "short disturbance" at 38.4 h, inside segment 1 of orientation 1:
a transient outside the candidate list, which the outliers candidate fits first and the
held-out check refuses).
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
from typing import NamedTuple

import numpy as np

from imubench.gap import GapOptions, Series, diagnose_channel

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_gap_acceptance import fitted_model  # the model recipe of the acceptance benches

CATS = Path(__file__).resolve().parents[1].parent / "shared" / "reference" / "imu-real" / \
    "cats-tag-temperature"
G = 9.80665
SEGMENTS = 3
BLOCK_S = 600
R_CLEAR = 0.9
"""|r| of the 600 s block means with temperature above which a segment holds a response."""
R_NONE = 0.5
"""|r| below which it holds none."""
SEED = 7


class Case(NamedTuple):
    """One diagnosed segment: its class by |r| (``clear``, ``none`` or ``-``), whether a
    temperature response was kept, its coefficient, the block slopes of this and of the
    other test segment, and whether a handling event lies inside."""

    cls: str
    named: bool
    coeff: float
    slope: float
    slope_other: float
    handled: bool


def events(kind: str) -> list[tuple[int, int, str]]:
    """(first row, end row, note) of each event of ``kind`` (``static``, ``handling``) in
    events.csv."""
    rows = (CATS / "events.csv").read_text().splitlines()[1:]
    return [(int(r.split(",")[1]), int(r.split(",")[2]), r.split(",", 5)[5])
            for r in rows if r.startswith(kind + ",")]


def block_ols(y: np.ndarray, temp: np.ndarray) -> tuple[float, float]:
    """Least-squares slope (unit/degC) of BLOCK_S block means on the block temperatures,
    and their Pearson r."""
    m = len(y) // BLOCK_S * BLOCK_S
    yb = y[:m].reshape(-1, BLOCK_S).mean(1)
    tb = temp[:m].reshape(-1, BLOCK_S).mean(1)
    if np.ptp(tb) < 1e-6:
        return math.nan, 0.0
    return float(np.polyfit(tb, yb, 1)[0]), float(np.corrcoef(tb, yb)[0, 1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--axes", default="gx,gy,gz,ax,ay,az")
    ap.add_argument("--orientations", default="0,1,2", help="static segments of events.csv")
    ap.add_argument("--model-less-temperature", action="store_true",
                    help="fit the model to segment 0 less its least-squares temperature "
                         "response")
    args = ap.parse_args(argv)
    npz = CATS / "cats_temperature_calib.npz"
    if not npz.is_file():
        print(f"skipped: no reference data at {npz}", file=sys.stderr)
        return 0
    z = np.load(npz)
    fs = float(z["fs_hz"])
    print(f"# bench_gap_real_temperature {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} "
          f"UTC {platform.node()} cpus={os.cpu_count()} load {os.getloadavg()[0]:.1f} "
          f"axes={args.axes} orientations={args.orientations} "
          f"model_less_temperature={args.model_less_temperature}", flush=True)
    t_all = time.perf_counter()
    rows: list[Case] = []
    for o in (int(x) for x in args.orientations.split(",")):
        i0, i1, note = events("static")[o]
        temp_all = z["temperature_c"][i0:i1]
        n = (i1 - i0) // SEGMENTS
        temps = [temp_all[k * n:(k + 1) * n] for k in range(SEGMENTS)]
        print(f"\n## orientation {o}: rows {i0}-{i1} ({note}); segments of {n / 3600:.1f} h; "
              "temperature per segment (fit half / held-out half spans, degC): " + "; ".join(
                  f"{k}: {np.ptp(t[:n // 2]):.1f} / {np.ptp(t[n // 2:]):.1f}"
                  for k, t in enumerate(temps)), flush=True)
        for ch in args.axes.split(","):
            i = "xyz".index(ch[1])
            y_all = (np.degrees(z["gyro_mrad_s"][i0:i1, i] / 1000.0) if ch[0] == "g"
                     else z["accel_m_s2"][i0:i1, i] / G)
            ys = [y_all[k * n:(k + 1) * n] for k in range(SEGMENTS)]
            y0 = ys[0]
            if args.model_less_temperature:
                y0 = y0 - np.polyval(np.polyfit(temps[0], y0, 1), temps[0])
            model = fitted_model(y0, fs, ch)
            for seg, other in ((1, 2), (2, 1)):
                handled = any(i0 + seg * n < h1 and h0 < i0 + (seg + 1) * n
                              for h0, h1, _ in events("handling"))
                slope, r = block_ols(ys[seg], temps[seg])
                slope_o, r_o = block_ols(ys[other], temps[other])
                t0 = time.perf_counter()
                d = diagnose_channel(model, ch, Series(ys[seg], temps[seg], fs,
                                                       f"cats{o}:{ch}:{seg}"),
                                     GapOptions(seed=SEED))
                out = d.to_dict()
                k = next((x for x in out["kept"] if x["effect"] == "temperature"), None)
                coeff = k["params"]["temp_coeff"] if k else math.nan
                se = (k.get("params_se") or {}).get("temp_coeff") if k else None
                cls = "clear" if abs(r) >= R_CLEAR else "none" if abs(r) < R_NONE else "-"
                rows.append(Case(cls, k is not None, coeff, slope, slope_o, handled))
                fitted = (f"temperature {coeff:.3g} +- {se if se is not None else math.nan:.2g} "
                          f"({k.get('fitted_on')})" if k else "no temperature")
                inside = " (handling inside)" if handled else ""
                print(f"  o{o} {ch} seg{seg}{inside}: r {r:+.2f} ({cls:5s}) slope "
                      f"{slope:+.3g}, other segment {slope_o:+.3g} (r {r_o:+.2f}); "
                      f"verdict {out['verdict']}, kept "
                      f"{[x['effect'] for x in out['kept']]}; {fitted} "
                      f"({time.perf_counter() - t0:.0f} s)", flush=True)
    print(f"\n## summary ({time.perf_counter() - t_all:.0f} s)")
    for label, subset in (("all segments", rows),
                          ("without a handling event", [x for x in rows if not x.handled])):
        clear = [x for x in subset if x.cls == "clear"]
        none = [x for x in subset if x.cls == "none"]
        named = [x for x in clear if x.named]
        err = [abs(x.coeff / x.slope - 1.0) for x in named]
        err_o = [abs(x.coeff / x.slope_other - 1.0) for x in named
                 if math.isfinite(x.slope_other) and x.slope_other * x.coeff > 0]
        print(f"  {label}: clear responses (|r| >= {R_CLEAR}) named temperature "
              f"{len(named)}/{len(clear)}; no response (|r| < {R_NONE}) named temperature "
              f"{sum(x.named for x in none)}/{len(none)}; median |fitted / slope - 1| "
              f"{np.median(err) if err else math.nan:.1%} against this segment's block "
              f"slope, {np.median(err_o) if err_o else math.nan:.1%} against the other "
              f"segment's (n = {len(err_o)} of the same sign)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
