"""Daemon load (issue 12 acceptance 6): one sensor at 6660 Hz with the datasheet noise
model for ``--minutes`` of wall time through ``imubench run`` as a real subprocess; with
``--sensors N`` (issue 17 acceptance 2: ``--sensors 4 --odr-hz 1660``) one daemon with N
simulated sensors (``[[sensors]]``) at that ODR, accounted per sensor.

Measured in the steady state (after ``--warmup-s``): CPU share of one core (from
/proc/PID/stat), RSS every 5 s (flat within 10 % of its value after warm-up?), the
interval between ``allan`` snapshots seen by a subscriber on the embedded broker (within
10 % of ``publish_interval_s``?), and the samples lost after the first second (the daemon's
final accounting). In the same run, the reference: ``imubench acquire`` of the same source
for the same time (simulated chip + driver + recorder, no engine, no MQTT): the difference
is what the live analysis and publishing cost. The simulated chip and its noise generator
run in the daemon's process; on hardware that share is replaced by the I2C transfers
(6660 Hz x 12 B = 80 kB/s of FIFO data, twice a 400 kHz bus: needs 1 MHz Fast-mode Plus).

Run: ``.venv/bin/python bench/bench_daemon_load.py [--minutes 10] [--quick]
[--sensors N --odr-hz HZ]``.
"""

from __future__ import annotations

import argparse
import itertools
import os
import re
import resource
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

CLK_TCK = os.sysconf("SC_CLK_TCK")
PAGE = os.sysconf("SC_PAGE_SIZE")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def proc_cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK  # utime + stime


def proc_rss_mib(pid: int) -> float:
    return int(Path(f"/proc/{pid}/statm").read_text().split()[1]) * PAGE / 2**20


def subscribe(port: int, stamps: dict[str, list[float]], stop: threading.Event) -> None:
    """Arrival times of the ``allan`` snapshots, per topic."""
    proc = subprocess.Popen(
        ["mosquitto_sub", "-h", "127.0.0.1", "-p", str(port), "-t",
         "imubench/bench1/+/allan", "-F", "%t"],
        stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    try:
        while not stop.is_set():
            line = proc.stdout.readline()
            if not line:
                break
            stamps.setdefault(line.strip(), []).append(time.monotonic())
    finally:
        proc.terminate()


CHIPS = ("lsm6dsl", "lsm6dsm", "lsm6ds3h")


def daemon_config(tmp: Path, port: int, odr: int, sensors: int) -> str:
    """One sensor in ``[source]``, or N in ``[[sensors]]`` (chips in turn)."""
    common = (f'[log]\npath = "{tmp}/{{station}}_{{sensor}}.imbr"\n'
              '[allan]\nstats = ["oadev", "mdev", "ohdev"]\nmemory = "bounded"\n'
              f'[mqtt]\nport = {port}\npublish_interval_s = 1.0\n'
              '[display]\nlive_table = "off"\n')
    if sensors == 1:
        return (f'[source]\nuri = "sim://lsm6dsl?odr_hz={odr}&seed=1&clock=wall'
                '&model=datasheet:lsm6dsl"\n' + common)
    tables = "".join(
        f'[[sensors]]\nname = "imu{i}"\nuri = "sim://{CHIPS[i % 3]}?odr_hz={odr}'
        f'&seed={i + 1}&clock=wall&model=datasheet:{CHIPS[i % 3]}"\n' for i in range(sensors))
    return common + tables


def run_daemon(minutes: float, warmup_s: float, odr: int, sensors: int) -> dict[str, Any]:
    tmp = Path(tempfile.mkdtemp(prefix="imubench-load-"))
    port = free_port()
    cfg = tmp / "load.toml"
    cfg.write_text(daemon_config(tmp, port, odr, sensors))
    proc = subprocess.Popen([sys.executable, "-m", "imubench.cli", "run", "--config", str(cfg)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert proc.stdout is not None
    out: list[str] = []
    threading.Thread(target=lambda: out.extend(proc.stdout), daemon=True).start()  # type: ignore[arg-type]
    while sum("recording to" in line for line in out) < sensors:
        if proc.poll() is not None:
            raise SystemExit("daemon ended early:\n" + "".join(out))
        time.sleep(0.1)
    stamps: dict[str, list[float]] = {}
    stop = threading.Event()
    threading.Thread(target=subscribe, args=(port, stamps, stop), daemon=True).start()
    time.sleep(warmup_s)
    t0, c0 = time.monotonic(), proc_cpu_s(proc.pid)
    rss = [proc_rss_mib(proc.pid)]
    end = t0 + minutes * 60
    while time.monotonic() < end:
        time.sleep(min(5.0, max(0.0, end - time.monotonic())))
        rss.append(proc_rss_mib(proc.pid))
    cpu = (proc_cpu_s(proc.pid) - c0) / (time.monotonic() - t0)
    steady = {topic: [s for s in st if t0 <= s <= end] for topic, st in stamps.items()}
    stop.set()
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=30)
    text = "".join(out)
    rx = re.compile(r"^(?:(\w+): )?stopped after (\d+) samples produced; engine (\d+) "
                    r"delivered, (\d+) lost; recording (\d+) written, (\d+) lost", re.M)
    accounts = {m[1] or "imu0": tuple(int(x) for x in m.groups()[1:]) for m in rx.finditer(text)}
    if len(accounts) != sensors:
        raise SystemExit("no final accounting for every sensor:\n" + text)
    intervals = [b - a for st in steady.values() for a, b in itertools.pairwise(st)]
    return {
        "cpu_core": cpu, "rss_start_mib": rss[0], "rss_max_mib": max(rss),
        "rss_end_mib": rss[-1],
        "interval_min_s": min(intervals) if intervals else float("nan"),
        "interval_max_s": max(intervals) if intervals else float("nan"),
        "snapshots": sum(len(st) for st in steady.values()), "accounts": accounts,
    }


def run_acquire(seconds: float, odr: int) -> float:
    """CPU share of ``imubench acquire`` of the same source (the reference)."""
    tmp = Path(tempfile.mkdtemp(prefix="imubench-acq-"))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.monotonic()
    subprocess.run(
        [sys.executable, "-m", "imubench.cli", "acquire",
         f"sim://lsm6dsl?odr_hz={odr}&seed=1&clock=wall&model=datasheet:lsm6dsl",
         "--duration-s", f"{seconds:g}", "--out", str(tmp / "a.imbr")],
        capture_output=True, text=True, check=True)
    wall = time.monotonic() - t0
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (ru.ru_utime + ru.ru_stime - before.ru_utime - before.ru_stime) / wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--warmup-s", type=float, default=30.0)
    ap.add_argument("--odr-hz", type=int, default=6660)
    ap.add_argument("--sensors", type=int, default=1, help="sensors in the daemon")
    ap.add_argument("--quick", action="store_true", help="1 minute, 10 s warm-up")
    args = ap.parse_args()
    if args.quick:
        args.minutes, args.warmup_s = 1.0, 10.0
    print(f"machine: {os.uname().nodename} {os.cpu_count()} cores; "
          f"{time.strftime('%Y-%m-%d %H:%M')}; load {os.getloadavg()[0]:.2f}")
    ref = run_acquire(args.minutes * 60 / 2, args.odr_hz)
    d = run_daemon(args.minutes, args.warmup_s, args.odr_hz, args.sensors)
    growth = d["rss_max_mib"] / d["rss_start_mib"] - 1
    n = args.sensors
    print(f"daemon {n} sensor(s) at {args.odr_hz} Hz, {args.minutes:g} min steady state:")
    print(f"  CPU {d['cpu_core']:.1%} of a core, {d['cpu_core'] / n:.1%} per sensor "
          f"(target < 25 % for one sensor at 6660 Hz); acquire of one sensor alone "
          f"{ref:.1%} (ratio daemon per sensor/acquire {d['cpu_core'] / n / ref:.2f})")
    print(f"  RSS {d['rss_start_mib']:.0f} -> max {d['rss_max_mib']:.0f} MiB "
          f"(+{growth:.1%}, target < 10 %)")
    print(f"  snapshot interval {d['interval_min_s']:.3f}..{d['interval_max_s']:.3f} s "
          f"(target 0.9..1.1 s), {d['snapshots']:.0f} snapshots")
    for name, (produced, delivered, lost, written, rec_lost) in sorted(d["accounts"].items()):
        ok = delivered + lost == produced and written + rec_lost == produced
        print(f"  {name}: produced {produced}, engine delivered {delivered} lost {lost}, "
              f"recording written {written} lost {rec_lost}: "
              f"{'accounted' if ok else 'NOT ACCOUNTED'} (target: lost 0 after the first "
              "second)")


if __name__ == "__main__":
    main()
