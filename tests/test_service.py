"""sd_notify messages on a real unix datagram socket named by NOTIFY_SOCKET."""

from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
import sys
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from imubench.service import ServiceNotifier

REPO = Path(__file__).resolve().parents[1]
UNIT = REPO / "packaging" / "systemd" / "imubench.service"


@pytest.fixture
def notify_socket(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[socket.socket]:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    path = tmp_path / "notify.sock"
    sock.bind(str(path))
    sock.settimeout(5.0)
    monkeypatch.setenv("NOTIFY_SOCKET", str(path))
    monkeypatch.setenv("WATCHDOG_USEC", "3000000")
    monkeypatch.setenv("WATCHDOG_PID", str(os.getpid()))
    yield sock
    sock.close()


def received(sock: socket.socket, n: int) -> list[str]:
    return [sock.recv(4096).decode() for _ in range(n)]


def test_ready_status_watchdog_stopping(notify_socket: socket.socket) -> None:
    n = ServiceNotifier()
    assert n.active and n.watchdog_interval_s == 1.5  # half of WATCHDOG_USEC
    n.status("opening  sim://lsm6dsl\n(104 Hz)")
    n.ready("recording")
    assert n.watchdog_due()
    n.watchdog()
    assert not n.watchdog_due()
    n.stopping()
    assert received(notify_socket, 5) == [
        "STATUS=opening sim://lsm6dsl (104 Hz)\n", "STATUS=recording\n", "READY=1\n",
        "WATCHDOG=1\n", "STOPPING=1\n",
    ]


def test_abstract_socket_name(monkeypatch: pytest.MonkeyPatch) -> None:
    name = f"imubench-test-{uuid.uuid4().hex}"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
        sock.bind("\0" + name)
        sock.settimeout(5.0)
        monkeypatch.setenv("NOTIFY_SOCKET", "@" + name)
        ServiceNotifier().ready()
        assert sock.recv(4096) == b"READY=1\n"


def test_outside_systemd_does_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("NOTIFY_SOCKET", raising=False)
    n = ServiceNotifier()
    assert not n.active
    n.ready("x")
    n.watchdog()
    n.stopping()


def test_a_vanished_socket_is_logged_once_not_raised(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture) -> None:
    monkeypatch.setenv("NOTIFY_SOCKET", str(tmp_path / "gone.sock"))
    n = ServiceNotifier()
    n.ready()
    n.watchdog()
    warnings = [r for r in caplog.records if "cannot notify" in r.getMessage()]
    assert len(warnings) == 1


def test_watchdog_pid_of_another_process_disables_the_timeout(
        notify_socket: socket.socket, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("WATCHDOG_PID", str(os.getpid() + 1))
    assert ServiceNotifier().watchdog_interval_s == 12 * 3600


def test_notifier_from_a_child_process(notify_socket: socket.socket) -> None:
    """The way the daemon runs: a separate process, the socket from its environment."""
    code = ("from imubench.service import ServiceNotifier as N; n = N(); "
            "n.ready('up'); n.watchdog(); n.stopping('bye')")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)
    assert received(notify_socket, 5) == ["STATUS=up\n", "READY=1\n", "WATCHDOG=1\n",
                                          "STATUS=bye\n", "STOPPING=1\n"]


def test_unit_file_runs_as_a_notify_service_with_watchdog() -> None:
    text = UNIT.read_text()
    settings = dict(line.split("=", 1) for line in text.splitlines()
                    if "=" in line and not line.lstrip().startswith("#"))
    assert settings["Type"] == "notify" and settings["Restart"] == "on-failure"
    assert int(settings["WatchdogSec"]) >= 10
    assert settings["CacheDirectory"] == "imubench"
    assert "NUMBA_CACHE_DIR=%C/imubench" in text
    assert settings["ExecStart"].split()[1:] == ["run", "--config",
                                                 "/etc/imubench/imubench.toml"]


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="no systemd-analyze")
def test_unit_file_passes_systemd_analyze_verify(tmp_path: Path) -> None:
    unit = tmp_path / "imubench.service"
    exec_start = re.search(r"^ExecStart=(\S+)", UNIT.read_text(), re.M)
    assert exec_start is not None
    unit.write_text(UNIT.read_text().replace(exec_start.group(1), shutil.which("true") or ""))
    proc = subprocess.run(["systemd-analyze", "verify", str(unit)], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
