"""Configuration fuzz: damaged configurations through the loader, counted.

    python bench/bench_config_fuzz.py [--n 20000] [--cli 40] [--seed 1]

Random truncations, byte and bit flips, duplicated lines and value type swaps of three
valid configurations (tests/config_damage.py). Each must be accepted or refused with one
line per problem naming the file (never a traceback, never longer than 20 s); ``--cli``
of them also go through ``imubench run --check`` in a subprocess (exit 0 or 2, no
traceback). Prints counts per damage kind and the load-time distribution; exit status 1
if any configuration was handled badly. Figures: docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import os
import platform
import random
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from config_damage import base_configs, damaged, load_outcome  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20000, help="damaged configs loaded in-process")
    ap.add_argument("--cli", type=int, default=40, help="of them also through the CLI")
    ap.add_argument("--seed", type=int, default=1, help="random seed")
    args = ap.parse_args()
    for name in [k for k in os.environ if k.upper().startswith("IMUBENCH_")]:
        del os.environ[name]
    rng = random.Random(args.seed)
    by_kind: Counter[tuple[str, str]] = Counter()
    times: list[float] = []
    bad: list[str] = []
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        os.chdir(tmp)
        texts = base_configs(tmp)
        cli_every = max(1, args.n // max(args.cli, 1)) if args.cli else 0
        t_start = time.perf_counter()
        for i in range(args.n):
            kind, data = damaged(texts, rng)
            p = tmp / f"d{i % 64}.toml"
            p.write_bytes(data)
            out = load_outcome(p)
            by_kind[(kind, out.verdict)] += 1
            times.append(out.seconds)
            if out.verdict == "bad":
                bad.append(f"{kind}: {out.detail[:2000]}")
                (tmp.parent / f"imubench-fuzz-bad-{len(bad)}.toml").write_bytes(data)
            if cli_every and i % cli_every == 0:
                proc = subprocess.run(
                    [sys.executable, "-m", "imubench", "run", "--config", str(p), "--check"],
                    capture_output=True, text=True, timeout=120)
                lines = proc.stderr.splitlines()
                ok = proc.returncode == 0 or (proc.returncode == 2 and lines and all(
                    line.startswith(f"imubench run: error: {p}") for line in lines))
                by_kind[("cli", "ok" if ok else "bad")] += 1
                if not ok:
                    bad.append(f"cli {kind}: status {proc.returncode}: {proc.stderr[:2000]}")
        wall = time.perf_counter() - t_start
    kinds = sorted({k for k, _ in by_kind})
    print(f"# config fuzz, {args.n} damaged configs, seed {args.seed}, "
          f"{platform.node()} {platform.machine()}, Python {platform.python_version()}")
    print(f"{'damage':<10} {'accepted':>9} {'refused':>9} {'bad':>5}")
    for k in kinds:
        if k == "cli":
            continue
        print(f"{k:<10} {by_kind[(k, 'accepted')]:>9} {by_kind[(k, 'refused')]:>9} "
              f"{by_kind[(k, 'bad')]:>5}")
    if args.cli:
        print(f"through `imubench run --check`: {by_kind[('cli', 'ok')]} clean, "
              f"{by_kind[('cli', 'bad')]} bad")
    times.sort()
    print(f"load time: median {1e3 * times[len(times) // 2]:.2f} ms, p99 "
          f"{1e3 * times[int(len(times) * 0.99)]:.1f} ms, max {1e3 * times[-1]:.1f} ms; "
          f"total {wall:.0f} s")
    for line in bad[:5]:
        print("BAD:", line)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
