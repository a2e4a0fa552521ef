"""Benchmark of the fleet (issue 17, acceptance 1 and 3): 8 simulated daemons
(``imubench run``, 104-1666 Hz, keep-alive 5 s) publishing to one private mosquitto,
watched by ``imubench view`` with a headless Chromium page open and by
``imubench fleet status``.

Usage::

    .venv/bin/python bench/bench_fleet.py [--daemons 8] [--window-s 60] [--no-browser]

Printed, in one run (machine, date and load first):

(a) per daemon: the delay from its first ``allan`` snapshot (seen by an independent
    subscriber) to the page showing its curve (the page is open before the daemons
    start); target < 2 s;
(b) ``fleet status`` and ``/api/fleet``: every sensor listed online;
(c) CPU of the view process (user + system, from /proc via psutil) over ``--window-s``
    with every daemon publishing once a second and the page connected, as % of one core;
    target < 10 %; the daemons' CPU next to it;
(d) one daemon killed (SIGKILL: the kernel closes its socket) and one frozen (SIGSTOP:
    only the keep-alive tells): time until the view shows each offline; target within
    1.5 keep-alives (7.5 s). The frozen one shows ``stale`` first (no snapshot for 3 s).

Exit status 1 when a target is missed.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
import psutil

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from fleet_helpers import Proc, daemon_config, start_daemon, start_view
from mqtt_fixtures import MosquittoProcess, find_mosquitto

ODRS = (104, 208, 416, 833, 1660, 104, 416, 1660)  # the chip's ODRs (1660 is '1.66 kHz')
KEEPALIVE_S = 5


class FirstSnapshots:
    """Wall time at which each sensor's first allan snapshot reached this subscriber."""

    def __init__(self, port: int) -> None:
        self.at: dict[str, float] = {}
        self.client = paho.Client(paho.CallbackAPIVersion.VERSION2)
        self.client.on_connect = lambda c, *a: c.subscribe("imubench/+/+/allan")
        self.client.on_message = self._message
        self.client.connect("127.0.0.1", port)
        self.client.loop_start()

    def _message(self, client: Any, userdata: Any, msg: Any) -> None:
        key = "/".join(msg.topic.split("/")[1:3])
        self.at.setdefault(key, time.time())

    def close(self) -> None:
        self.client.loop_stop()
        self.client.disconnect()


def api_states(url: str) -> dict[str, str]:
    with urllib.request.urlopen(url + "api/fleet", timeout=5) as resp:
        return {s["key"]: s["state"] for s in json.load(resp)["sensors"]}


def wait_state(url: str, key: str, state: str, timeout_s: float) -> float | None:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        if api_states(url).get(key) == state:
            return time.monotonic() - t0
        time.sleep(0.1)
    return None


class PagePoller(threading.Thread):
    """A headless Chromium on the view's page, noting when each card first has points."""

    def __init__(self, url: str, profile: Path) -> None:
        super().__init__(daemon=True)
        self.url = url
        self.profile = profile
        self.shown: dict[str, float] = {}
        self.ready = threading.Event()
        self.stop = threading.Event()
        self.error: str | None = None

    def run(self) -> None:
        from playwright.sync_api import sync_playwright

        try:
            with sync_playwright() as p:
                ctx = p.chromium.launch_persistent_context(
                    str(self.profile), executable_path=shutil.which("chromium")
                    or "/usr/bin/chromium", headless=True,
                    args=["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                          "--disable-background-networking", "--disable-component-update",
                          "--disable-sync"])
                page = ctx.new_page()
                page.goto(self.url)
                self.ready.set()
                while not self.stop.is_set():
                    keys = page.evaluate(
                        "[...document.querySelectorAll('section.sensor')]"
                        ".filter(c => Number(c.dataset.points) > 0).map(c => c.dataset.key)")
                    now = time.time()
                    for k in keys:
                        self.shown.setdefault(k, now)
                    time.sleep(0.05)
                ctx.close()
        except Exception as exc:  # reported in the summary
            self.error = repr(exc)
            self.ready.set()


def cpu_s(proc: psutil.Process) -> float:
    t = proc.cpu_times()
    return t.user + t.system


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--daemons", type=int, default=8)
    ap.add_argument("--window-s", type=float, default=60.0)
    ap.add_argument("--no-browser", action="store_true")
    args = ap.parse_args()
    print(f"# bench_fleet {datetime.datetime.now().isoformat(timespec='seconds')} "
          f"{platform.node()} {platform.machine()} cores={os.cpu_count()} "
          f"python={platform.python_version()} load={os.getloadavg()}")
    binary = find_mosquitto()
    if binary is None:
        print("no mosquitto binary: apt-get install mosquitto")
        return 1
    ok = True
    with tempfile.TemporaryDirectory(prefix="bench-fleet-") as tmp_name:
        tmp = Path(tmp_name)
        (tmp / "mq").mkdir()
        broker = MosquittoProcess(binary, tmp / "mq").start()
        url_broker = f"mqtt://127.0.0.1:{broker.port}"
        daemons: list[Proc] = []
        view: Proc | None = None
        poller: PagePoller | None = None
        first = FirstSnapshots(broker.port)
        try:
            view, url = start_view(url_broker, tmp)
            if not args.no_browser:
                poller = PagePoller(url, tmp / "chromium")
                poller.start()
                poller.ready.wait(60)
            keys = []
            for i in range(args.daemons):
                station, sensor = f"bench{i // 2 + 1}", f"imu{i % 2}"
                keys.append(f"{station}/{sensor}")
                cfg = daemon_config(tmp / f"d{i}.toml", broker=url_broker, station=station,
                                    sensor=sensor, odr_hz=ODRS[i % len(ODRS)],
                                    keepalive_s=KEEPALIVE_S, seed=i + 1)
                daemons.append(start_daemon(cfg, tmp))
            t0 = time.monotonic()
            while time.monotonic() - t0 < 180:
                dead = [d for d in daemons if d.proc.poll() is not None]
                if dead:
                    print(f"a daemon exited:\n{dead[0].output()}")
                    return 1
                st = api_states(url)
                if len(st) == len(keys) and all(v == "online" for v in st.values()):
                    break
                time.sleep(0.5)
            print(f"all {len(keys)} online after {time.monotonic() - t0:.1f} s: "
                  f"{api_states(url)}")

            # (a) first snapshot -> page
            if poller is not None:
                time.sleep(3)
                print("\n(a) first snapshot -> curve on the page (s), target < 2")
                for k in keys:
                    if k in poller.shown and k in first.at:
                        d = poller.shown[k] - first.at[k]
                        ok &= d < 2.0
                        print(f"  {k:14s} {d:6.2f}")
                    else:
                        ok = False
                        print(f"  {k:14s} not shown ({poller.error or 'no curve'})")

            # (b) fleet status
            fs = subprocess.run([sys.executable, "-m", "imubench.cli", "fleet", "status",
                                 "--broker", url_broker, "--wait-s", "2"],
                                capture_output=True, text=True, timeout=60)
            print("\n(b) imubench fleet status\n" + fs.stdout)
            online = sum(1 for ln in fs.stdout.splitlines()[1:-1] if " online " in ln)
            ok &= online == len(keys)

            # (c) CPU of the view
            vp = psutil.Process(view.pid)
            dps = [psutil.Process(d.pid) for d in daemons]
            c0, d0, w0 = cpu_s(vp), [cpu_s(p) for p in dps], time.monotonic()
            time.sleep(args.window_s)
            wall = time.monotonic() - w0
            view_pct = 100 * (cpu_s(vp) - c0) / wall
            dae_pct = [100 * (cpu_s(p) - c) / wall for p, c in zip(dps, d0, strict=True)]
            ok &= view_pct < 10.0
            print(f"(c) over {wall:.0f} s: view {view_pct:.2f} % of a core (target < 10); "
                  f"daemons " + ", ".join(f"{ODRS[i % len(ODRS)]} Hz {p:.1f} %"
                                          for i, p in enumerate(dae_pct))
                  + f"; load {os.getloadavg()}")

            # (d) kill one, freeze one
            daemons[0].kill()
            t_kill = wait_state(url, keys[0], "offline", 3 * KEEPALIVE_S)
            daemons[1].signal(signal.SIGSTOP)
            t0 = time.monotonic()
            t_stale = wait_state(url, keys[1], "stale", 3 * KEEPALIVE_S)
            t_stop = wait_state(url, keys[1], "offline", 3 * KEEPALIVE_S)
            t_stop = None if t_stop is None else time.monotonic() - t0
            daemons[1].signal(signal.SIGCONT)
            limit = 1.5 * KEEPALIVE_S
            ok &= t_kill is not None and t_kill <= limit
            ok &= t_stop is not None and t_stop <= limit + 0.5
            print(f"(d) offline on the view after SIGKILL: {t_kill} s; after SIGSTOP: "
                  f"stale (no snapshot) after {t_stale} s, offline (will at keep-alive "
                  f"expiry) after {t_stop} s; 1.5 keep-alives = {limit} s")
            print(f"    states now: {api_states(url)}")
            for d in daemons[2:]:
                if d.proc.poll() is not None:
                    ok = False
                    print(f"daemon {d.args[-1]} exited with {d.proc.returncode}:\n"
                          + "".join(d.lines[-15:]))
        finally:
            if poller is not None:
                poller.stop.set()
                poller.join(10)
            first.close()
            for d in daemons:
                d.stop()
            if view is not None:
                view.stop()
            broker.stop()
    print("\nRESULT:", "all targets met" if ok else "a target was missed")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
