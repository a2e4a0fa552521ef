"""Batch analysis on Dask (issue 17, acceptance 4): ``imubench fit`` over 24 one-hour
recordings, sequential (one process, one task after another) and on a 2-worker
LocalCluster, in one run; identical outputs and the wall-time ratio (target <= 0.6).

    .venv/bin/python bench/bench_batch.py [--recordings 24] [--hours 1] [--odr-hz 104]
        [--workers 2] [--keep DIR]

The recordings are made with ``imubench sim`` (virtual time, the datasheet-typical
LSM6DSL model, one seed each) in a temporary directory (or ``--keep DIR``, reused when it
holds them already). Both runs are the ``imubench fit DIR --out-dir ...`` command as a
subprocess, so each pays its own start-up (for Dask: the cluster's); wall and CPU time
(the command and its children, from psutil) are printed, and every report file of the
two runs is compared (the model files' ``created`` time stamp aside).
"""

from __future__ import annotations

import argparse
import datetime
import filecmp
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

MODEL = "datasheet:lsm6dsl"
"""The shipped datasheet-typical LSM6DSL noise model."""


def make_recordings(folder: Path, n: int, hours: float, odr_hz: float) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i in range(n):
        p = folder / f"rec{i:02d}.imbr"
        if not p.exists():
            subprocess.run([sys.executable, "-m", "imubench.cli", "sim", "--chip", "lsm6dsl",
                            "--odr-hz", f"{odr_hz:g}", "--duration-s", f"{hours * 3600:g}",
                            "--model", str(MODEL), "--seed", str(100 + i), "--out", str(p)],
                           check=True, capture_output=True)
        paths.append(p)
    return paths


def timed_run(args: list[str]) -> tuple[float, float, str]:
    """(wall s, CPU s of the process tree, stderr) of one command."""
    t0 = time.monotonic()
    proc = psutil.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    cpu: dict[int, float] = {}
    while proc.poll() is None:
        try:
            for p in [proc, *proc.children(recursive=True)]:
                with p.oneshot():
                    t = p.cpu_times()
                    cpu[p.pid] = t.user + t.system
        except psutil.Error:
            pass
        time.sleep(0.2)
    out, err = proc.communicate()
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(args)} failed ({proc.returncode}):\n{err}")
    return time.monotonic() - t0, sum(cpu.values()), out + err


def same_reports(a: Path, b: Path) -> tuple[int, list[str]]:
    """(files compared, names that differ); TOML compared without the created line."""
    names = sorted(p.name for p in a.iterdir())
    if names != sorted(p.name for p in b.iterdir()):
        return 0, ["(different file lists)"]
    differ = []
    for name in names:
        if name.endswith(".toml"):
            strip = re.compile(r'^created = ".*"$', re.M)
            if strip.sub("", (a / name).read_text()) != strip.sub("", (b / name).read_text()):
                differ.append(name)
        elif name == "fit.json":  # the table's header names workers and scheduler
            import json

            ra, rb = json.loads((a / name).read_text()), json.loads((b / name).read_text())
            if ra["rows"] != rb["rows"]:
                differ.append(name)
        elif not filecmp.cmp(a / name, b / name, shallow=False):
            differ.append(name)
    return len(names), differ


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--recordings", type=int, default=24)
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--odr-hz", type=float, default=104.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--keep", type=Path, default=None)
    args = ap.parse_args()
    print(f"# bench_batch {datetime.datetime.now().isoformat(timespec='seconds')} "
          f"{platform.node()} {platform.machine()} cores={os.cpu_count()} "
          f"python={platform.python_version()} load={os.getloadavg()}")
    with tempfile.TemporaryDirectory(prefix="bench-batch-") as tmp_name:
        tmp = Path(tmp_name)
        data = args.keep or tmp / "recordings"
        t0 = time.monotonic()
        recs = make_recordings(data, args.recordings, args.hours, args.odr_hz)
        print(f"{len(recs)} recordings of {args.hours:g} h at {args.odr_hz:g} Hz in {data} "
              f"({time.monotonic() - t0:.0f} s to make)")
        fit = [sys.executable, "-m", "imubench.cli", "fit", str(data)]
        seq_wall, seq_cpu, _ = timed_run([*fit, "--out-dir", str(tmp / "seq")])
        print(f"sequential:         wall {seq_wall:7.1f} s  CPU {seq_cpu:7.1f} s  "
              f"load {os.getloadavg()}")
        par_wall, par_cpu, _ = timed_run([*fit, "--out-dir", str(tmp / "dask"),
                                            "--workers", str(args.workers)])
        print(f"dask, {args.workers} workers:  wall {par_wall:7.1f} s  CPU {par_cpu:7.1f} s  "
              f"load {os.getloadavg()}")
        n, differ = same_reports(tmp / "seq", tmp / "dask")
        ratio = par_wall / seq_wall
        print(f"reports compared: {n}, differing: {differ or 'none'}")
        print(f"wall ratio dask/sequential = {ratio:.3f} (target <= 0.6); "
              f"CPU ratio {par_cpu / seq_cpu:.3f}")
        ok = not differ and n > 0 and ratio <= 0.6
        print("RESULT:", "target met" if ok else "target missed")
        return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
