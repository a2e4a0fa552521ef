"""Real subprocesses for the fleet and live-view tests and benches: simulated daemons
(``imubench run``) and the view (``imubench view``), each with its output collected by a
reader thread so a pipe never fills up.
"""

from __future__ import annotations

import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

MODEL = "datasheet:lsm6dsl"
"""The shipped datasheet-typical LSM6DSL noise model."""


def daemon_config(path: Path, *, broker: str, station: str, sensor: str,
                  odr_hz: float = 104, keepalive_s: int = 5, seed: int = 1,
                  stats: tuple[str, ...] = ("oadev", "mdev"), port: int = 1883,
                  record_dir: Path | None = None) -> Path:
    """Write a daemon configuration: a simulated LSM6DSL in real time with the datasheet
    noise model, publishing to ``broker`` (``embedded`` or ``mqtt://...``)."""
    log = ("enabled = false" if record_dir is None
           else f'path = "{record_dir}/{{station}}_{{sensor}}_{{start}}.imbr"')
    stat_list = ", ".join(f'"{s}"' for s in stats)
    path.write_text(f"""
[source]
uri = "sim://lsm6dsl?odr_hz={odr_hz:g}&seed={seed}&clock=wall&model={MODEL}"
[log]
{log}
[allan]
stats = [{stat_list}]
[mqtt]
broker = "{broker}"
port = {port}
station = "{station}"
sensor = "{sensor}"
keepalive_s = {keepalive_s}
[display]
live_table = "off"
""")
    return path


def subprocess_env() -> dict[str, str]:
    """This environment with PYTHONPATH made absolute (relative entries would move with
    a subprocess's working directory) and unbuffered output."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    if env.get("PYTHONPATH"):
        env["PYTHONPATH"] = os.pathsep.join(
            str(Path(e).resolve()) for e in env["PYTHONPATH"].split(os.pathsep) if e)
    return env


class Proc:
    """A subprocess whose stdout+stderr lines are queued by a reader thread."""

    def __init__(self, args: list[str], cwd: Path) -> None:
        self.args = args
        self.proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True, env=subprocess_env(), cwd=cwd)
        self.lines: list[str] = []
        self._queue: queue.Queue[str] = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line)
            self._queue.put(line)

    @property
    def pid(self) -> int:
        return self.proc.pid

    def wait_for(self, pattern: str, timeout_s: float) -> re.Match[str]:
        """The first new output line matching ``pattern`` (a regex)."""
        end = time.monotonic() + timeout_s
        rx = re.compile(pattern)
        while time.monotonic() < end:
            try:
                line = self._queue.get(timeout=0.1)
            except queue.Empty:
                if self.proc.poll() is not None and self._queue.empty():
                    break
                continue
            m = rx.search(line)
            if m:
                return m
        raise AssertionError(f"{self.args[3:5]} never printed /{pattern}/ within "
                             f"{timeout_s} s; output:\n{self.output()}")

    def output(self) -> str:
        return "".join(self.lines)

    def signal(self, sig: int) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)

    def stop(self, timeout_s: float = 10.0) -> int:
        """SIGTERM, then SIGKILL after ``timeout_s``; the exit code."""
        self.signal(signal.SIGTERM)
        try:
            return self.proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return self.proc.wait(5)

    def kill(self) -> None:
        """SIGKILL: no clean stop, the broker publishes the last will."""
        self.signal(signal.SIGKILL)
        self.proc.wait(5)


def start_daemon(config: Path, cwd: Path) -> Proc:
    return Proc([sys.executable, "-m", "imubench.cli", "run", "--config", str(config)], cwd)


def start_view(broker: str, cwd: Path, *extra: str) -> tuple[Proc, str]:
    """``imubench view`` on a free loopback port; (process, page URL)."""
    view = Proc([sys.executable, "-m", "imubench.cli", "view", "--broker", broker,
                 "--listen", "127.0.0.1:0", *extra], cwd)
    m = view.wait_for(r"live view on (http://\S+)", 60)
    return view, m.group(1)
