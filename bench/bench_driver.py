"""Acceptance measurements of the driver and the simulated chip (issue 6 items 1-3, 5;
issue 5 item 3). Run: ``.venv/bin/python bench/bench_driver.py [--quick]``.

Speed (issue 5 acceptance 3: >= 5e5 sample sets/s through the real driver in virtual
time, 24 h at 104 Hz in < 20 s) is measured with the shipped datasheet model
(``datasheet:lsm6dsl``: white + flicker + random walk + temperature on all six
channels, what ``imubench sim --model`` users run) and, in the same run, two references:
the same path with the quiet sensor (driver + chip cost alone) and the physics alone
(``SensorPhysics.generate`` in FIFO-sized calls). Wall and CPU time are both printed:
on a shared machine the wall time includes other people's load.

Prints one line per measurement; figures go to docs/benchmarks.md by hand.
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np

from imubench.errors import SourceError
from imubench.sources.registry import open_source


def cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def drain(uri: str) -> tuple[object, np.ndarray, float, float]:
    src = open_source(uri)
    t0, c0 = time.perf_counter(), cpu_s()
    idx = []
    with src:
        for b in src:
            idx.append(b.index)
    return src, np.concatenate(idx), time.perf_counter() - t0, cpu_s() - c0


def physics_only(model_path: str, n: int, call: int = 288) -> tuple[float, float]:
    """Wall and CPU seconds of ``SensorPhysics.generate`` in ``call``-sample calls."""
    from lsm6ds_sim.model import load_model
    from lsm6ds_sim.physics import SensorPhysics

    phys = SensorPhysics(
        load_model(model_path), seed=0, duration_hint_s=n / 104.0, noise_block=1 << 14
    )
    t0, c0 = time.perf_counter(), cpu_s()
    done = 0
    while done < n:
        phys.generate(min(call, n - done), 1 / 104.0)
        done += call
    return time.perf_counter() - t0, cpu_s() - c0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="1 h instead of 24 h for speed")
    args = ap.parse_args()
    import imubench.sources.chip  # noqa: F401 - imports outside the timed region

    hours = 1 if args.quick else 24
    model = "datasheet:lsm6dsl"
    target = 5e5
    base = f"sim://lsm6dsl?odr_hz=104&duration_s={hours * 3600}"
    runs = (("quiet sensor (reference)", base), ("datasheet model", f"{base}&model={model}"))
    for label, uri in runs:
        src, idx, wall, cpu = drain(uri)
        print(
            f"speed, {label}: {hours} h at 104 Hz = {len(idx)} sample sets in {wall:.1f} s "
            f"wall, {cpu:.1f} s CPU -> {len(idx) / wall:,.0f} /s wall "
            f"({len(idx) / wall / target:.2f}x target), {len(idx) / cpu:,.0f} /s CPU "
            f"({len(idx) / cpu / target:.2f}x target)"
        )
    wall, cpu = physics_only(model, len(idx))
    print(
        f"speed, physics alone (reference, {model}): {len(idx) / wall:,.0f} /s wall, "
        f"{len(idx) / cpu:,.0f} /s CPU"
    )

    src, idx, wall, _ = drain("sim://lsm6dsl?odr_hz=3330&bus_khz=400&duration_s=60&counting=1")
    payload = 12 * len(idx) / (src.elapsed_s * 400e3 / 9)
    print(
        f"item 1: 3330 Hz 60 s on 400 kHz: {len(idx)} samples (expected {3330 * 60}), "
        f"overruns {src.counters['overruns']}, lost {src.counters['lost_samples']}, "
        f"sample payload {payload:.1%} of the link limit, wire utilisation "
        f"{src.bus_utilization:.1%}, {wall:.1f} s wall"
    )

    try:
        open_source("sim://lsm6dsl?odr_hz=6660&bus_khz=400&duration_s=1")
    except SourceError as exc:
        print(f"item 2: refused: {exc}")

    for extra in ("", "&crystal_ppm=37500"):
        src, idx, wall, _ = drain(
            "sim://lsm6dsl?odr_hz=104&bus_khz=400&nack_rate=1e-3&nack_burst=3&reset_every_s=10"
            f"&overrun_at_s=25&watermark_s=0.25&counting=1&seed=7&duration_s=600{extra}"
        )
        c = src.counters
        print(
            f"item 3{' with crystal error 37500 ppm' if extra else ''}: faults 600 s at 104 Hz: "
            f"delivered {c['samples']} + lost {c['lost_samples']} = "
            f"{c['samples'] + c['lost_samples']} (expected {104 * 600}); gaps {c['gaps']}, "
            f"overruns {c['overruns']}, io_errors {c['io_errors']}, retries {c['retries']}, "
            f"measured ODR {src.measured_odr_hz:.3f} Hz, injected {src.sim.bus.faults.injected}"
        )


if __name__ == "__main__":
    main()
