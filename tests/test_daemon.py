"""``imubench run`` end to end, as a real subprocess (issue 2, acceptance 2).

Simulated LSM6DSL in real time -> recording + OADEV -> embedded MQTT broker; an external
subscriber (``mosquitto_sub``, else an aiomqtt client) must see a snapshot per second for
all six channels; SIGTERM must end it within 2 s with exit 0 and a recording that
converts to CSV with every sample in order.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mqtt_fixtures import free_port

from imubench.config import quickstart_file
from imubench.recording import load_recording


def start_daemon(tmp_path: Path, port: int, extra: str = "") -> tuple[subprocess.Popen, Path]:
    cfg = tmp_path / "daemon.toml"
    cfg.write_text(
        quickstart_file().read_text()
        .replace("port = 1883", f"port = {port}")
        .replace('path = "recordings/', f'path = "{tmp_path}/recordings/')
        + extra
    )
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(
        [sys.executable, "-m", "imubench.cli", "run", "--config", str(cfg)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, cwd=tmp_path,
    )
    return proc, cfg


def wait_for_line(proc: subprocess.Popen, needle: str, timeout_s: float) -> str:
    end = time.monotonic() + timeout_s
    assert proc.stdout is not None
    while time.monotonic() < end:
        line = proc.stdout.readline()
        if needle in line:
            return line
        if not line and proc.poll() is not None:
            break
    raise AssertionError(f"daemon never printed {needle!r}")


@pytest.mark.skipif(shutil.which("mosquitto_sub") is None, reason="mosquitto_sub not installed")
def test_quickstart_daemon_end_to_end(tmp_path: Path) -> None:
    port = free_port()
    proc, _ = start_daemon(tmp_path, port)
    try:
        line = wait_for_line(proc, "embedded MQTT broker listening", 30)
        assert f":{port}" in line
        sub = subprocess.run(
            ["mosquitto_sub", "-h", "127.0.0.1", "-p", str(port), "-t",
             "imubench/bench1/imu0/allan", "-C", "4", "-W", "30"],
            capture_output=True, text=True, timeout=40,
        )
        snaps = [json.loads(s) for s in sub.stdout.splitlines()]
        assert len(snaps) == 4
        for s in snaps:
            assert s["statistic"] == "oadev"
            assert set(s["channels"]) == {"gx", "gy", "gz", "ax", "ay", "az"}
            for ch in s["channels"].values():
                assert len(ch["tau_s"]) == len(ch["dev"]) == len(ch["n"]) >= 1
                assert ch["units"] in ("dps", "g")
                n_tau = len(ch["tau_s"])
                assert len(ch["ci_low"]) == len(ch["ci_high"]) == len(ch["alpha"]) == n_tau
                assert len(ch["m"]) == len(ch["gaps"]) == n_tau
                assert ch["gaps"] == [0] * n_tau  # no sample lost: no term skipped
                for tau, m in zip(ch["tau_s"], ch["m"], strict=True):
                    assert tau * s["odr_hz"] == pytest.approx(m, rel=0.1)  # the chip's clock
            assert set(s["statistics"]) == {"oadev", "mdev", "ohdev"}  # the shipped quick start
            assert s["statistics"]["oadev"] == s["channels"]
            for name, per_ch in s["statistics"].items():
                assert set(per_ch) == set(s["channels"]), name
                gx = per_ch["gx"]
                ok = [d for d in gx["dev"] if d is not None]
                assert ok and all(d > 0 for d in ok), name  # a noisy simulated gyro
        stamps = [time.mktime(time.strptime(s["time"][:19], "%Y-%m-%dT%H:%M:%S")) for s in snaps]
        assert stamps[-1] - stamps[0] <= 4.0  # at least one per second
        assert snaps[-1]["samples"] > snaps[0]["samples"]
        for s in snaps:  # the samples the deviations are computed on: N - 1 terms at m = 1
            # (it was read at the publish tick, after the snapshot was made)
            assert s["channels"]["gx"]["n"][0] == s["samples"] - 1, s["samples"]
        recs = list((tmp_path / "recordings").glob("*.imbr"))
        assert len(recs) == 1
        size1 = recs[0].stat().st_size
        time.sleep(1.5)
        assert recs[0].stat().st_size > size1  # the recording grows
        status = subprocess.run(
            ["mosquitto_sub", "-h", "127.0.0.1", "-p", str(port), "-t",
             "imubench/bench1/imu0/status", "-C", "1", "-W", "5"],
            capture_output=True, text=True, timeout=10,
        )
        retained = json.loads(status.stdout)
        assert retained["state"] == "online"  # retained
        # the fleet view's staleness rule reads the daemon's cadence from here
        assert retained["publish_interval_s"] == 1.0
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(timeout=10)
        assert time.monotonic() - t0 < 5.0  # measured (< 2 s) by bench/bench_daemon_start.py
        assert rc == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    rec = load_recording(recs[0])
    assert rec.complete and rec.damage is None
    out = tmp_path / "all.csv"
    subprocess.run([sys.executable, "-m", "imubench.cli", "convert", str(recs[0]), str(out)],
                   check=True, capture_output=True, timeout=60)
    csv = load_recording(out)
    np.testing.assert_array_equal(csv.index, np.arange(len(csv)))  # every sample, in order
    assert len(csv) == len(rec) > 104 * 3


def test_daemon_stops_on_duration_and_resumes_state(tmp_path: Path) -> None:
    port = free_port()
    extra = "\n[run]\nduration_s = 1.0\n"
    text = quickstart_file().read_text().replace(
        'memory = "bounded"', f'memory = "bounded"\nstate_path = "{tmp_path}/state.npz"'
    ).replace("clock=wall", "clock=virtual")
    cfg_text = text.replace("port = 1883", f"port = {port}").replace(
        'path = "recordings/', f'path = "{tmp_path}/recordings/') + extra
    cfg = tmp_path / "c.toml"
    cfg.write_text(cfg_text)
    for expected in ("samples", "resumed Allan state"):
        proc = subprocess.run([sys.executable, "-m", "imubench.cli", "run", "--config", str(cfg)],
                              capture_output=True, text=True, timeout=60, cwd=tmp_path)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert expected in proc.stdout
    assert "stopped after 104 samples" in proc.stdout
    assert "resumed Allan state" in proc.stdout and "(104 samples, saved " in proc.stdout
    # the two runs are two gap-free runs of the engine, not one continuous one: a resumed
    # state was joined to the new run as if no time had passed between them
    from imubench.stats.streaming import StreamingAllan

    eng = StreamingAllan.load_state((tmp_path / "state.npz").read_bytes())
    lengths, counts = eng.runs(0)
    assert list(lengths) == [105] and list(counts) == [2]  # 104 samples = 105 phase points
    assert eng.n_samples > 2 * 104


def test_a_saved_state_of_other_settings_is_not_resumed(tmp_path: Path) -> None:
    """A state was resumed when the ODR and the statistics matched: after a restart at
    2000 dps the new counts were summed at the old sensitivity (live OADEV 32 % low), and
    with a calibration added every start crashed the engine (raw counts, then values)."""
    from imubench.stats.streaming import StreamingAllan

    port = free_port()
    base = quickstart_file().read_text().replace(
        'memory = "bounded"', f'memory = "bounded"\nstate_path = "{tmp_path}/state.npz"'
    ).replace("clock=wall", "clock=virtual").replace("port = 1883", f"port = {port}").replace(
        'path = "recordings/', f'path = "{tmp_path}/recordings/') + "\n[run]\nduration_s = 1.0\n"
    cal = tmp_path / "cal.toml"
    cal.write_text('format = "imubench-calibration"\nversion = 1\n[provenance]\n'
                   'serial = "S"\ndate_utc = "2026-12-03T00:00:00Z"\nstation = "b"\n'
                   '[gyro]\nunit = "dps"\nmethod = "t"\ntemp_ref_c = 25.0\n'
                   'offset = [0.0, 0.0, 0.0]\nmatrix = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], '
                   '[0.0, 0.0, 1.0]]\n')
    runs = [("", "resumed Allan state"),
            ("&fs_dps=2000", "sensitivity per count 0.00875"),
            ("&fs_dps=2000", "resumed Allan state"),
            ("&fs_dps=2000", "input raw counts, now values (a calibration was added")]
    for k, (extra, expected) in enumerate(runs):
        text = base.replace("model=datasheet:lsm6dsl", f"model=datasheet:lsm6dsl{extra}")
        if k == 3:
            text += f'\n[calibration]\nfile = "{cal}"\n'
        cfg = tmp_path / "c.toml"
        cfg.write_text(text)
        proc = subprocess.run([sys.executable, "-m", "imubench.cli", "run", "--config",
                               str(cfg)], capture_output=True, text=True, timeout=60,
                              cwd=tmp_path)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        if k:
            assert expected in proc.stdout, proc.stdout
        eng = StreamingAllan.load_state((tmp_path / "state.npz").read_bytes())
        if k == 2:  # resumed: both runs, with the time between them as gap rows
            assert eng.n_samples > 2 * 104 and list(eng.runs(0)[0]) == [105], proc.stdout
        else:  # a fresh engine
            assert eng.n_samples == 104, (k, proc.stdout)


def test_faults_reach_the_log(tmp_path: Path) -> None:
    """A two-hour bus outage and hundreds of resets reached MQTT only: stderr (and so the
    journal) stayed empty. The daemon now writes a warning with what was lost since the
    last one, by reason, at most once a minute."""
    port = free_port()
    text = quickstart_file().read_text().replace("port = 1883", f"port = {port}").replace(
        'path = "recordings/', f'path = "{tmp_path}/recordings/').replace(
        'live_table = "auto"', 'live_table = "off"').replace(
        "model=datasheet:lsm6dsl", "model=datasheet:lsm6dsl&reset_every_s=0.7")
    cfg = tmp_path / "c.toml"
    cfg.write_text(text + "\n[run]\nduration_s = 3.0\n")
    proc = subprocess.run([sys.executable, "-m", "imubench.cli", "run", "--config", str(cfg)],
                          capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lines = [ln for ln in (proc.stdout + proc.stderr).splitlines()
             if "WARNING imubench.daemon: imu0: since the last report: source lost (chip "
                "reset) +" in ln]
    assert len(lines) == 1, proc.stdout + proc.stderr  # once a minute at most


def test_snapshots_take_at_most_their_share_of_the_engine_thread() -> None:
    """A snapshot is computed in the engine's thread: one that costs 0.48 s at a 0.2 s
    publish interval (6660 Hz, eight exact statistics) left the engine little else, and
    it lost two samples in three to its own overrun. The ticks after it are skipped
    (counted) until SNAPSHOT_DUTY of the time has passed; a cheap one skips none."""
    from imubench.daemon import SNAPSHOT_DUTY, next_tick

    assert next_tick(10.0, 1.0, 0.25, 9.75, 0.01) == (11.0, 0)
    interval, lead = 0.2, 0.05
    t, skipped = next_tick(10.0, interval, lead, 9.95, 0.48)
    assert skipped == 9 and t == pytest.approx(12.0)
    assert 0.48 / (t - lead - 9.95) <= SNAPSHOT_DUTY  # its share of the time to the next
    assert 0.48 / (t - interval - lead - 9.95) > SNAPSHOT_DUTY  # one tick fewer: above
