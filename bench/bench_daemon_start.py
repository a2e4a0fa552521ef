"""Daemon start and stop times (issue 12 acceptance 3), measured on real subprocesses.

For an empty numba cache (``NUMBA_CACHE_DIR`` a new directory: the kernels compile) and a
warm one: seconds from the process start until the retained status ``online`` reaches a
subscriber on the embedded broker (target < 3 s), and seconds from SIGINT, sent 3 s
after the start, until the process has exited (target < 2 s). Each case ``--repeats``
times; min / median / max printed, with the machine's load (a shared machine's load
shows in the figures).

Run: ``.venv/bin/python bench/bench_daemon_start.py [--repeats 5]``.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def one(cold: bool) -> tuple[float, float]:
    tmp = Path(tempfile.mkdtemp(prefix="imubench-start-"))
    port = free_port()
    cfg = tmp / "d.toml"
    cfg.write_text(
        '[source]\nuri = "sim://lsm6dsl?odr_hz=104&clock=wall&model=datasheet:lsm6dsl"\n'
        f'[log]\npath = "{tmp}/{{station}}_{{sensor}}.imbr"\n'
        f'[mqtt]\nport = {port}\n[display]\nlive_table = "off"\n')
    env = dict(os.environ)
    if cold:
        env["NUMBA_CACHE_DIR"] = str(tmp / "numba-cache")
    t0 = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "imubench.cli", "run", "--config", str(cfg)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    online = float("nan")
    while time.monotonic() - t0 < 30:
        sub = subprocess.run(["mosquitto_sub", "-h", "127.0.0.1", "-p", str(port), "-t",
                              "imubench/bench1/imu0/status", "-C", "1", "-W", "1"],
                             capture_output=True, text=True)
        if sub.stdout.strip() and json.loads(sub.stdout).get("state") == "online":
            online = time.monotonic() - t0
            break
    time.sleep(max(0.0, 3.0 - (time.monotonic() - t0)))
    t1 = time.monotonic()
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=60)
    return online, time.monotonic() - t1


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    print(f"machine: {os.uname().nodename} {os.cpu_count()} cores; "
          f"{time.strftime('%Y-%m-%d %H:%M')}; load {os.getloadavg()[0]:.2f}")
    for cold in (True, False):
        runs = [one(cold) for _ in range(args.repeats)]
        on = [r[0] for r in runs]
        off = [r[1] for r in runs]
        name = "cold numba cache" if cold else "warm numba cache"
        print(f"{name}: online {min(on):.2f} / {statistics.median(on):.2f} / {max(on):.2f} s "
              f"(target < 3); SIGINT at 3 s -> exit {min(off):.2f} / "
              f"{statistics.median(off):.2f} / {max(off):.2f} s (target < 2)")
    print(f"load at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
