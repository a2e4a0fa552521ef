"""Benchmark of the streaming Allan engine (issue 4, acceptance 2-4 and the bounded mode).

Usage::

    .venv/bin/python bench/bench_streaming.py [--quick] [--skip-rt] [--skip-rss]
        [--edf-seeds K] [--exact-1e9] [--only SECTIONS] [--malloc default|pad|trim]

Sections, all printed in one run (machine and date first):

(a) OADEV at the octave averaging factors given to ``allantools.realtime.oadev_realtime``,
    both fed the same 1e6 rate samples (``--quick``: 1e5): time per sample and ratio.
(b) samples/s/channel for OADEV + MVAR + OHVAR together, octave taus up to m = 2^20, in
    the daemon's chunk sizes (it reads up to 65536 samples per ring-buffer read; 4096 is a
    typical FIFO-sized batch), int16 and float input, 1 and 6 channels, bounded and exact;
    with the copy bandwidth of this machine expressed as "passes over the data".
(c) resident memory (RSS) at checkpoints while feeding 1e8 samples x 6 channels in the
    default bounded configuration (6.66 kHz, max_tau_s = 1e5; ``--quick``: 1e7).
(d) snapshot() time for 6 channels x 40 taus with noise identification and CIs.
(e) EDF lost by the bounded mode: Monte Carlo over seeds of the variance of the bounded
    and exact estimators at large m (white FM, random-walk FM), EDF = 2 var^2 / Var(est),
    next to Greenhall's EDF for the strided estimator.
(f) ``--exact-1e9``: 1e9 int16 samples, snapshot vs an independent exact integer reference
    (terms from int64 cumulative sums in blocks, squares summed in Python integers).
(g) cost of gaps: 6 float channels at 6660 Hz, all eight statistics, 100 taus per decade up
    to 3600 s, exact memory (a daemon configuration that overran): CPU time per chunk of
    65536 rows before any gap, for a chunk of gap rows (what an overrun consumer feeds
    for the samples it lost), and for real chunks after a gap, as ratios to the first.

CPU time (``time.process_time``) is reported next to wall time: the machine is shared.
"""

from __future__ import annotations

import argparse
import ctypes
import datetime
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from imubench.stats.confidence import strided_edf
from imubench.stats.edf import edf
from imubench.stats.streaming import StreamingAllan

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_stats import copy_bandwidth_gbs  # reuse the batch bench's bandwidth probe

RATE_HZ = 6660.0


def load_average() -> str:
    """1, 5 and 15 minute load averages (other jobs on this shared machine)."""
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def rss_mb() -> float:
    """Resident set size of this process (MB, from /proc/self/statm)."""
    with open("/proc/self/statm") as fh:
        pages = int(fh.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 1e6


def feed(eng: StreamingAllan, y: np.ndarray, chunk: int) -> tuple[float, float]:
    """Feed y in chunks; returns (wall s, CPU s)."""
    w0, c0 = time.perf_counter(), time.process_time()
    for i in range(0, y.shape[0], chunk):
        eng.update(y[i:i + chunk])
    return time.perf_counter() - w0, time.process_time() - c0


# -- (a) ---------------------------------------------------------------------------------
def bench_realtime(n: int) -> None:
    from allantools.realtime import oadev_realtime

    y = np.random.default_rng(1).normal(size=n)
    afs = [int(a) for a in 2 ** np.arange(int(np.log2(n // 4)) + 1)]
    rt = oadev_realtime(afs=afs, tau0=1.0)
    c0 = time.process_time()
    for v in y:
        rt.add_frequency(v)
    t_rt = time.process_time() - c0
    print(f"(a) OADEV, {len(afs)} octave AFs 1..{afs[-1]}, {n:.0e} samples (CPU time); "
          f"allantools oadev_realtime {t_rt / n * 1e6:.2f} us/sample; load average "
          f"{load_average()}")
    for chunk in (4096, 65536):  # load the compiled kernels (every array layout the
        for alpha in (None, 0):  # timed runs meet) and scipy before timing
            warm = StreamingAllan(1.0, taus=[float(a) for a in afs], stats=("oadev",),
                                  max_tau_s=float(afs[-1]), alpha=alpha)
            feed(warm, y[:n // 5], chunk)
            warm.snapshot()
    for chunk in (1, 4096, 65536):
        for alpha in (None, 0):
            if chunk == 1 and n > 100_000:
                continue  # one update() per sample: shown at --quick size only
            eng = StreamingAllan(1.0, taus=[float(a) for a in afs], stats=("oadev",),
                                 max_tau_s=float(afs[-1]), alpha=alpha)
            _, t_ours = feed(eng, y, chunk)
            dev = eng.snapshot()["oadev"].dev  # type: ignore[index]
            agree = float(np.max(np.abs(dev / np.asarray(rt.devs())[: dev.size] - 1)))
            what = "noise ID + CIs" if alpha is None else "alpha fixed   "
            print(f"    imubench chunks of {chunk:5d}, {what}: {t_ours / n * 1e6:7.4f} "
                  f"us/sample, ratio {t_rt / t_ours:6.0f}x (target >= 300x); "
                  f"max |dev rel diff| {agree:.1e}")


# -- (b) ---------------------------------------------------------------------------------
def bench_throughput(quick: bool) -> None:
    bw = copy_bandwidth_gbs()
    pass_rate = bw * 1e9 / 2 / 8  # float64 values/s for one read+write pass
    print(f"(b) OADEV+MVAR+OHVAR, octave m up to 2^20, rate {RATE_HZ} Hz, noise ID on; copy "
          f"bandwidth {bw:.1f} GB/s = {pass_rate:.2e} float64 values/s per read+write pass; "
          f"load average {load_average()}")
    print("    memory  ch  input  chunk   rows   M samples/s/channel (CPU)  (wall)  passes")
    rng = np.random.default_rng(2)
    rows_1 = 1 << (21 if quick else 23)
    for memory in ("bounded", "exact"):
        for nch in (1, 6):
            rows = rows_1 // (1 if nch == 1 else 4)
            if memory == "exact" and rows < 4 << 20:
                rows = 4 << 20 if not quick else rows  # every m active after 3 m_max samples
            for kind in ("int16", "float"):
                base = rng.normal(size=(rows, nch)) * 20
                y = base.astype(np.int16) if kind == "int16" else base
                for chunk in (4096, 65536):
                    eng = StreamingAllan(RATE_HZ, stats=("oadev", "mdev", "ohdev"),
                                         max_tau_s=2**20 / RATE_HZ, memory=memory)
                    warm = min(rows // 2, 3 << 20)
                    feed(eng, y[:warm], chunk)
                    wall, cpu = feed(eng, y[warm:], chunk)
                    per_ch = (rows - warm) / cpu
                    print(f"    {memory:7s} {nch:3d}  {kind:6s} {chunk:6d} {rows:8d}"
                          f"   {per_ch / 1e6:8.2f}                 "
                          f"{(rows - warm) / wall / 1e6:7.2f}  {pass_rate / (per_ch * nch):6.0f}")


# -- (c) ---------------------------------------------------------------------------------
def bench_rss(total: int) -> None:
    chunk = 65536
    pool = (np.random.default_rng(3).normal(size=(1 << 21, 6)) * 20).astype(np.int16)
    rss0 = rss_mb()
    # the compiled kernels (numba and LLVM, loaded once per process) are not the engine's
    tiny = StreamingAllan(RATE_HZ, stats=("oadev", "mdev", "ohdev"), max_tau_s=1.0,
                          memory="bounded")
    tiny.update(pool[:chunk + 1000])
    tiny.snapshot()
    del tiny
    eng = StreamingAllan(RATE_HZ, stats=("oadev", "mdev", "ohdev"), max_tau_s=1e5,
                         memory="bounded")
    base = rss_mb()
    print(f"(c) bounded, 6 ch int16 at {RATE_HZ} Hz, max_tau_s=1e5, OADEV+MVAR+OHVAR, "
          f"{total:.0e} samples/channel, chunks of {chunk}; RSS before {base:.1f} MB, of "
          f"which {base - rss0:.1f} MB for loading the compiled kernels (once per process)")
    marks = set(int(total * k / 10) // chunk for k in range(1, 11))
    fed = 0
    c0 = time.process_time()
    rss = []
    offsets = np.random.default_rng(4).integers(0, pool.shape[0] - chunk, total // chunk + 1)
    for k in range(total // chunk):
        o = int(offsets[k])
        eng.update(pool[o:o + chunk])
        fed += chunk
        if k + 1 in marks:
            rss.append(rss_mb())
            print(f"    {fed:.3e} samples  RSS {rss[-1]:7.1f} MB  state "
                  f"{len(eng.save_state()) / 1e6:5.2f} MB  CPU {time.process_time() - c0:6.0f} s")
    after = rss[1:]
    print(f"    after warm-up (10 %): RSS {min(after):.1f}..{max(after):.1f} MB, spread "
          f"{(max(after) / min(after) - 1) * 100:.1f} % (goal < 10 %); engine share "
          f"{max(after) - base:.1f} MB over the process before it (goal < 64 MB)")


# -- (d) ---------------------------------------------------------------------------------
def bench_snapshot() -> None:
    y = (np.random.default_rng(5).normal(size=(400_000, 6)) * 20).astype(np.int16)
    for stats in (("oadev",), ("oadev", "mdev", "ohdev")):
        for memory in ("exact", "bounded"):
            eng = StreamingAllan(RATE_HZ, taus=10, stats=stats, max_tau_s=1e5,
                                 memory=memory)
            eng.update(y)
            eng.snapshot()  # first call imports scipy's chi2
            times = []
            for _ in range(10):
                t0 = time.perf_counter()
                snap = eng.snapshot()
                times.append(time.perf_counter() - t0)
            ntau = len(snap[0]["oadev"])  # type: ignore[index]
            print(f"(d) snapshot 6 ch x {ntau} taus x {len(stats)} stat(s) ({memory}), alpha + "
                  f"EDF + CI: median {np.median(times) * 1e3:.1f} ms, min "
                  f"{min(times) * 1e3:.1f} ms (goal < 20 ms)")


# -- (e) ---------------------------------------------------------------------------------
def bench_edf_loss(seeds: int, overlap: int) -> None:
    m = 4096
    n = 24 * m
    stats = ("oadev", "mdev", "ohdev")
    print(f"(e) EDF loss of bounded (overlap {overlap}, stride {m // overlap}) vs exact at "
          f"m={m}, N={n}, {seeds} seeds; loss = 1 - Var(exact)/Var(bounded):")
    for kind, alpha in (("white FM", 0), ("random-walk FM", -2)):
        est = {st: ([], []) for st in stats}
        for seed in range(seeds):
            w = np.random.default_rng(1000 + seed).normal(size=n)
            y = w if alpha == 0 else np.cumsum(w)
            ex = StreamingAllan(1.0, taus=[m], stats=stats, alpha=alpha)
            bd = StreamingAllan(1.0, taus=[m], stats=stats, alpha=alpha, memory="bounded",
                                overlap=overlap)
            ex.update(y)
            bd.update(y)
            se, sb = ex.snapshot(), bd.snapshot()
            for st in stats:
                est[st][0].append(se[st].var[0])  # type: ignore[index]
                est[st][1].append(sb[st].var[0])  # type: ignore[index]
        for st in stats:
            e, b = (np.array(v) for v in est[st])
            loss = 1 - np.var(e, ddof=1) / np.var(b, ddof=1)
            boot = []
            rng = np.random.default_rng(7)
            for _ in range(400):
                i = rng.integers(0, seeds, seeds)
                boot.append(1 - np.var(e[i], ddof=1) / np.var(b[i], ddof=1))
            edf_mc = 2 * np.mean(b) ** 2 / np.var(b, ddof=1)
            g_full = edf(st, alpha, m, n + 1)
            g_b = strided_edf(st, alpha, m, n + 1, m // overlap)
            b5, b95 = (np.percentile(boot, q) * 100 for q in (5, 95))
            print(f"    {kind:15s} {st:6s} MC loss {loss * 100:6.2f} % "
                  f"(bootstrap 90 %: {b5:6.2f}..{b95:5.2f} %)"
                  f"  EDF MC {edf_mc:6.1f}  Greenhall full {g_full:6.1f} strided {g_b:6.1f} "
                  f"(loss {(1 - g_b / g_full) * 100:5.2f} %)")


# -- (f) ---------------------------------------------------------------------------------
def _exact_sq_sum(v: np.ndarray) -> int:
    """Exact sum of squares of int64 values |v| < 2^40, in Python integers."""
    hi, lo = np.divmod(v, 1 << 20)
    return (int(np.sum(hi * hi)) << 40) + (int(np.sum(2 * hi * lo)) << 20) + int(np.sum(lo * lo))


def bench_exact_1e9(total: int) -> None:
    ms = (1, 16, 1024, 65536)
    block = 1 << 22
    eng = StreamingAllan(RATE_HZ, taus=[m / RATE_HZ for m in ms],
                         stats=("oadev", "mdev", "ohdev"), max_tau_s=ms[-1] / RATE_HZ, alpha=0)
    sums = {(st, m): 0 for st in ("oadev", "mdev", "ohdev") for m in ms}
    counts = dict.fromkeys(sums, 0)
    keep = 4 * ms[-1]
    hist = np.zeros(0, np.int64)  # X history (phase = cumulative counts, X_0 = 0)
    x_last = 0
    x0_pending = True
    c0 = time.process_time()
    for b in range(-(-total // block)):
        size = min(block, total - b * block)  # the last block may be short: exactly `total`
        y = np.random.default_rng([11, b]).integers(-40, 41, size).astype(np.int16) + np.int16(900)
        eng.update(y)
        x = x_last + np.cumsum(y.astype(np.int64))
        x_last = int(x[-1])
        if x0_pending:
            x = np.concatenate([[0], x])
            x0_pending = False
        full = np.concatenate([hist, x])
        new0 = hist.size  # first index of `full` that is a new phase point
        for m in ms:
            i = np.arange(max(new0, 2 * m), full.size)
            d = full[i] - 2 * full[i - m] + full[i - 2 * m]
            sums[("oadev", m)] += _exact_sq_sum(d)
            counts[("oadev", m)] += d.size
            i3 = i[i >= 3 * m]
            h = full[i3] - 3 * full[i3 - m] + 3 * full[i3 - 2 * m] - full[i3 - 3 * m]
            sums[("ohdev", m)] += _exact_sq_sum(h)
            counts[("ohdev", m)] += h.size
            # MVAR term ending at phase point j: sum of the m second differences ending there
            lo = max(new0, 3 * m - 1)
            j = np.arange(lo - m + 1, full.size)
            dd = full[j] - 2 * full[j - m] + full[j - 2 * m]
            cs = np.concatenate([[0], np.cumsum(dd)])
            e = cs[m:] - cs[:-m]
            sums[("mdev", m)] += _exact_sq_sum(e)
            counts[("mdev", m)] += e.size
        hist = full[-keep:]
    n_fed = total
    snap = eng.snapshot()
    worst = 0.0
    print(f"(f) exactness after {n_fed:.3e} int16 samples ({time.process_time() - c0:.0f} s CPU):")
    for (st, m), s in sums.items():
        norm = {"oadev": 2 * m * m, "mdev": 2 * m**4, "ohdev": 6 * m * m}[st]
        ref = s / (norm * counts[(st, m)])
        r = snap[st]  # type: ignore[index]
        k = int(np.nonzero(r.m == m)[0][0])
        rel = abs(r.var[k] / ref - 1)
        worst = max(worst, rel)
        assert r.n[k] == counts[(st, m)], (st, m, r.n[k], counts[(st, m)])
        print(f"    {st:6s} m={m:6d}  n={counts[(st, m)]}  var {r.var[k]:.15e}  ref {ref:.15e}  "
              f"rel {rel:.1e}")
    print(f"    worst relative difference {worst:.1e} (goal <= 1e-12)")


# -- (g) ---------------------------------------------------------------------------------
GAP_STATS = ("adev", "oadev", "mdev", "tdev", "hdev", "ohdev", "stdev", "ostdev")


def bench_gaps(quick: bool) -> None:
    rate, chunk = 6660.0, 1 << 16
    eng = StreamingAllan(rate, taus=100, stats=GAP_STATS, max_tau_s=3600.0, memory="exact")
    rng = np.random.default_rng(6)
    gap = np.full((chunk, 6), np.nan)

    def cpu(y: np.ndarray) -> float:
        c0 = time.process_time()
        eng.update(y)
        return time.process_time() - c0

    for _ in range(6):  # warm-up: the kernels, the history buffers (grown to hold 3 m)
        cpu(rng.normal(size=(chunk, 6)))
    reps = 2 if quick else 5
    before = float(np.median([cpu(rng.normal(size=(chunk, 6))) for _ in range(reps)]))
    first_gap = cpu(gap)
    first_after = cpu(rng.normal(size=(chunk, 6)))
    gaps = float(np.median([cpu(gap) for _ in range(reps)]))
    cpu(rng.normal(size=(chunk, 6)))  # the chunk right after a gap (its edge)
    after = float(np.median([cpu(rng.normal(size=(chunk, 6))) for _ in range(reps)]))
    print(f"(g) gaps: 6 ch float, {len(GAP_STATS)} statistics, {len(eng.ms)} averaging "
          f"factors (100/decade to 3600 s), exact, {rate:g} Hz; CPU s per {chunk}-row chunk "
          f"({chunk / rate:.1f} s of data): before any gap {before:.2f}; first gap chunk "
          f"{first_gap:.2f} ({first_gap / before:.1f}x, starts the gap history); the "
          f"chunk after it {first_after:.2f} ({first_after / before:.1f}x); gap chunks "
          f"{gaps:.2f} ({gaps / before:.2f}x); real chunks later {after:.2f} "
          f"({after / before:.2f}x)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="shorter runs (a: 1e5, c: 1e7)")
    ap.add_argument("--skip-rt", action="store_true", help="skip (a), allantools realtime")
    ap.add_argument("--skip-rss", action="store_true", help="skip (c), the 1e8-sample RSS run")
    ap.add_argument("--edf-seeds", type=int, default=300, help="Monte Carlo seeds for (e)")
    ap.add_argument("--overlaps", default="64",
                    help="bounded-mode overlap factors for (e), comma separated")
    ap.add_argument("--exact-1e9", action="store_true", help="run (f) (minutes)")
    ap.add_argument("--only", default="abcdefg", help="sections to run, e.g. 'bd'")
    ap.add_argument("--malloc", choices=("default", "pad", "trim"), default="default",
                    help="glibc allocator setting to run under: 'pad' keeps freed heap "
                    "memory (M_TOP_PAD 256 MB, M_TRIM_THRESHOLD 512 MB); 'trim' is the worst "
                    "case, every allocation >= 128 kB mapped afresh and the heap top "
                    "returned to the OS at every free (M_MMAP_THRESHOLD 128 kB, "
                    "M_TRIM_THRESHOLD 0, M_TOP_PAD 0). The engine should not care.")
    args = ap.parse_args()
    libc = ctypes.CDLL("libc.so.6")
    if args.malloc == "pad":
        libc.mallopt(-2, 256 << 20)  # M_TOP_PAD
        libc.mallopt(-1, 512 << 20)  # M_TRIM_THRESHOLD
    elif args.malloc == "trim":
        libc.mallopt(-3, 128 << 10)  # M_MMAP_THRESHOLD (fixed: no dynamic raise)
        libc.mallopt(-1, 0)  # M_TRIM_THRESHOLD
        libc.mallopt(-2, 0)  # M_TOP_PAD
    print(f"{datetime.date.today()} {platform.node()} {platform.processor() or platform.machine()}"
          f", {os.cpu_count()} cores, Python {platform.python_version()}, numpy "
          f"{np.__version__}; machine shared with other jobs (wall times are noisy); "
          f"allocator: {args.malloc}; load average {load_average()}")
    if "a" in args.only and not args.skip_rt:
        bench_realtime(100_000 if args.quick else 1_000_000)
    if "b" in args.only:
        bench_throughput(args.quick)
    if "c" in args.only and not args.skip_rss:
        bench_rss(10_000_000 if args.quick else 100_000_000)
    if "d" in args.only:
        bench_snapshot()
    if "e" in args.only:
        for overlap in (int(v) for v in args.overlaps.split(",")):
            bench_edf_loss(args.edf_seeds, overlap)
    if "g" in args.only:
        bench_gaps(args.quick)
    if "f" in args.only and args.exact_1e9:
        bench_exact_1e9(1_000_000_000)


if __name__ == "__main__":
    main()
