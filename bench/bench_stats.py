"""Speed benchmark of imubench.stats against allantools 2024.6 on the same data and taus.

Usage: ``.venv/bin/python bench/bench_stats.py [--skip-1e5] [--skip-memory]``.
Prints the machine, date, timings, ratios, numerical agreement with allantools and, for
the O(N) statistics, the effective memory traffic compared with a measured copy bandwidth.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

import imubench.stats as st


def _t(fn: Callable[[], Any], repeat: int = 1) -> tuple[float, Any]:
    """Best wall time of ``repeat`` runs (the machine is shared: the minimum is the least
    disturbed run) and the last result."""
    best = float("inf")
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def copy_bandwidth_gbs() -> float:
    a = np.random.default_rng(0).standard_normal(1 << 24)
    b = np.empty_like(a)
    best = 1e9
    for _ in range(5):
        t0 = time.perf_counter()
        np.copyto(b, a)
        best = min(best, time.perf_counter() - t0)
    return 2 * a.nbytes / best / 1e9


def compare(
    name: str,
    n: int,
    at_fn: Callable[..., Any],
    ours: str,
    y: np.ndarray,
    target: float,
    passes: float | None = None,
    bw: float = 0.0,
) -> None:
    repeat = 3 if n >= 1e5 else 1
    kw = {"alpha": 0, "bias_correction": False}
    t_ours, r = _t(lambda: st.compute(ours, y, 1.0, "freq", "octave", **kw), repeat)
    t_full, _ = _t(lambda: st.compute(ours, y, 1.0, "freq", "octave"), repeat)
    taus = r.m.astype(float)
    t_at, (_, dev, _, _) = _t(lambda: at_fn(y, rate=1.0, data_type="freq", taus=taus), repeat)
    rel = float(np.max(np.abs(r.dev / dev - 1.0)))
    ratio = t_at / t_ours
    line = (
        f"{name:8s} N={n:>8d} ours {t_ours:8.4f} s (with noise ID+EDF+CI {t_full:8.4f} s)  "
        f"allantools {t_at:8.4f} s  speed-up {ratio:7.1f}x / {t_at / t_full:7.1f}x "
        f"(target >= {target:g}x: {'OK' if min(ratio, t_at / t_full) >= target else 'MISS'})"
        f"  max|rel diff| {rel:.1e}"
    )
    if passes:
        ideal = passes * y.nbytes * len(taus) / (bw * 1e9)
        line += f"  ~{ideal / t_ours:.0%} of copy bandwidth"
    print(line, flush=True)


def memory_child(n: int) -> None:
    import tracemalloc

    y = np.random.default_rng(1).standard_normal(n)
    tracemalloc.start()
    st.oadev(y, 1.0, "freq", "octave", alpha=0)
    _, peak = tracemalloc.get_traced_memory()
    print(f"{peak / y.nbytes:.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--skip-1e5", action="store_true")
    ap.add_argument("--skip-memory", action="store_true")
    ap.add_argument("--memory-child", type=int, default=0, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.memory_child:
        memory_child(args.memory_child)
        return
    import allantools as at

    warm = np.random.default_rng(0).standard_normal(400)
    for name in ("oadev", "mdev", "ohdev", "totdev", "mtotdev", "htotdev", "theo1", "theobr"):
        st.compute(name, warm, 1.0, "freq")  # load (or compile, after an edit) the kernels
    st.compute("theobr", np.random.default_rng(0).standard_normal(3000), 1.0, "freq")

    print(f"# imubench.stats benchmark  {datetime.datetime.now().isoformat(timespec='seconds')}")
    print(
        f"# {platform.platform()}  {platform.processor() or platform.machine()}  "
        f"cpus={os.cpu_count()}  python {platform.python_version()}  numpy {np.__version__}  "
        f"allantools {at.__version__ if hasattr(at, '__version__') else '?'}"
    )
    bw = copy_bandwidth_gbs()
    print(f"# measured copy bandwidth {bw:.1f} GB/s  load average {os.getloadavg()[0]:.1f}")
    rng = np.random.default_rng(42)
    y6 = rng.standard_normal(1_000_000)
    # passes over an N-double array per tau: one read of x (the lagged reads hit cache);
    # TOTVAR reads its 3N reflected copy
    for name, fn, p in (
        ("oadev", at.oadev, 1),
        ("mdev", at.mdev, 1),
        ("tdev", at.tdev, 1),
        ("ohdev", at.ohdev, 1),
        ("totdev", at.totdev, 3),
    ):
        compare(name, y6.size, fn, name, y6, 2.0, p, bw)
    y3 = rng.standard_normal(3000)
    for name, fn in (("mtotdev", at.mtotdev), ("htotdev", at.htotdev), ("theo1", at.theo1)):
        compare(name, y3.size, fn, name, y3, 100.0)
    if not args.skip_1e5:
        y5 = rng.standard_normal(100_000)
        for name in ("theo1", "theobr", "theoh", "mtotdev", "ttotdev", "htotdev"):
            # the exact statistics at N = 1e5, default call (noise ID, bias correction, EDF,
            # CI), run once each (slow: about a minute in all); the target is absolute
            t, r = _t(lambda name=name: st.compute(name, y5, 1.0, "freq", "octave"))
            print(
                f"{name:8s} N=  100000 octave ({r.m.size} taus, max m {r.m[-1]}) "
                f"{t:8.2f} s (target < 30 s: {'OK' if t < 30 else 'MISS'})  "
                f"load average {os.getloadavg()[0]:.1f}",
                flush=True,
            )
    if not args.skip_memory:
        out = subprocess.run(
            [sys.executable, __file__, "--memory-child", "10000000"],
            capture_output=True,
            text=True,
            check=True,
        )
        ratio = float(out.stdout.strip())
        print(
            f"oadev    N=10000000 octave peak traced memory {ratio:.2f} x input array "
            f"(target < 4: {'OK' if ratio < 4 else 'MISS'})"
        )


if __name__ == "__main__":
    main()
