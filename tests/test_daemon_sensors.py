"""Several sensors in one daemon (``[[sensors]]``): each with its own pipeline, recording
and topics over one broker connection whose last will is the node's status; a sensor
whose node is offline is offline in the fleet inventory (and so in ``fleet status`` and
the live view)."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path
from typing import Any

import pytest
from fleet_helpers import MODEL, start_daemon
from test_fleet_status import states

from imubench.config import ConfigError, load_config
from imubench.fleet.inventory import Inventory
from imubench.recording import load_recording

STATION = "rig"
SENSORS = (("imu0", "sim://lsm6dsl?odr_hz=104&seed=1&clock=wall&model=" + MODEL),
           ("imu1", "sim://lsm6dsm?odr_hz=208&seed=2&clock=wall"),
           ("st0", "sensortile-sim://?seed=3&clock=wall"))


def config(path: Path, broker: str, record_dir: Path, *, duration_s: float | None = None,
           sensors: tuple[tuple[str, str], ...] = SENSORS) -> Path:
    tables = "".join(f'[[sensors]]\nname = "{n}"\nuri = "{u}"\n' for n, u in sensors)
    run = "" if duration_s is None else f"[run]\nduration_s = {duration_s}\n"
    path.write_text(f"""
[log]
path = "{record_dir}/{{station}}_{{sensor}}_{{start}}.imbr"
[allan]
stats = ["oadev"]
[mqtt]
broker = "{broker}"
station = "{STATION}"
node = "bench-pc"
keepalive_s = 5
[display]
live_table = "off"
{run}{tables}""")
    return path


def test_node_status_turns_its_sensors_offline() -> None:
    inv = Inventory()
    now = time.monotonic()
    status = {"state": "online", "station": "s", "node": "n1", "client_id": "c"}
    for name in ("a", "b"):
        inv.apply(f"imubench/s/{name}/status", json.dumps({**status, "sensor": name}).encode(),
                  now)
    inv.apply("imubench/s/c/status", b'{"state": "online"}', now)  # a one-sensor daemon
    inv.apply("imubench/s/node/n1/status", b'{"state": "online", "node": "n1"}', now)
    assert inv.sensors["s/a"].node_online is True
    assert {k: s.state(now, 3, 3) for k, s in inv.sensors.items()} == {
        "s/a": "waiting", "s/b": "waiting", "s/c": "waiting"}
    assert inv.apply("imubench/s/node/n1/status", b"offline", now)  # the will
    views = {v["key"]: v for v in inv.views(now)}
    assert [views[k]["state"] for k in ("s/a", "s/b", "s/c")] == [
        "offline", "offline", "waiting"]
    assert views["s/a"]["status_state"] == "offline" and views["s/a"]["node"] == "n1"
    assert views["s/a"]["offline_at"] is not None
    # the node restarts: its statuses come back (node first, then each sensor's)
    inv.apply("imubench/s/node/n1/status", b'{"state": "online"}', now)
    assert inv.sensors["s/a"].state(now, 3, 3) == "waiting"
    # a sensor status that arrives before its node's is not held offline
    inv.apply("imubench/s/d/status", json.dumps({**status, "node": "n2"}).encode(), now)
    assert inv.sensors["s/d"].node_online is None


def test_sensors_config_is_checked(tmp_path: Path) -> None:
    one = (("imu0", SENSORS[0][1]),)
    path = config(tmp_path / "c.toml", "embedded", tmp_path, sensors=one * 2)
    with pytest.raises(ConfigError, match=r"c\.toml: .*name imu0 appears more than once"):
        load_config(path)
    text = path.read_text().replace("{sensor}", "")
    path.write_text(text.replace('name = "imu0"', 'name = "imu9"', 1))
    with pytest.raises(ConfigError, match=r"log\.path needs \{sensor\}"):
        load_config(path)
    bad = config(tmp_path / "d.toml", "embedded", tmp_path,
                 sensors=(one[0], ("imu1", "sim://lsm6dsl?odr_hz=1666")))
    with pytest.raises(ConfigError, match=r"d\.toml:\d+: sensors\.1\.uri = .*1666 Hz"):
        load_config(bad)


def _summaries(output: str) -> dict[str, tuple[int, int, int, int, int]]:
    """Per sensor: produced, engine delivered, engine lost, recording written, lost."""
    rx = re.compile(r"^(\w+): stopped after (\d+) samples produced; engine (\d+) delivered, "
                    r"(\d+) lost; recording (\d+) written, (\d+) lost$", re.M)
    return {m[1]: tuple(int(x) for x in m.groups()[1:]) for m in rx.finditer(output)}


def test_one_daemon_several_sensors(private_mosquitto: Any, tmp_path: Path) -> None:
    broker = private_mosquitto()
    url = f"mqtt://127.0.0.1:{broker.port}"
    keys = [f"{STATION}/{name}" for name, _ in SENSORS]

    # a daemon killed: one connection, one will (the node's), every sensor offline
    rec_a = tmp_path / "a"
    daemon = start_daemon(config(tmp_path / "a.toml", url, rec_a), tmp_path)
    try:
        for _ in SENSORS:
            daemon.wait_for(r"recording to", 90)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            seen = states(url)
            if all(seen.get(k) == "online" for k in keys):
                break
        assert all(seen.get(k) == "online" for k in keys), seen
        daemon.kill()
        deadline = time.monotonic() + 10  # (one listen for all three, not one each)
        while time.monotonic() < deadline:
            seen = states(url)
            if all(seen.get(k) == "offline" for k in keys):
                break
        assert all(seen.get(k) == "offline" for k in keys), seen
    finally:
        daemon.kill()
    for name, _ in SENSORS:  # each sensor's own recording, readable after SIGKILL
        (path,) = rec_a.glob(f"{STATION}_{name}_*.imbr")
        assert len(load_recording(path)) > 0

    # a clean run of 2 s: every sample accounted per sensor, in the recording too
    rec_b = tmp_path / "b"
    daemon = start_daemon(config(tmp_path / "b.toml", url, rec_b, duration_s=2), tmp_path)
    assert daemon.proc.wait(120) == 0, daemon.output()
    out = daemon.output()
    sums = _summaries(out)
    assert set(sums) == {name for name, _ in SENSORS}, out
    for name, (produced, delivered, lost, written, rec_lost) in sums.items():
        assert produced > 0 and delivered + lost == produced and written + rec_lost == produced
        (path,) = rec_b.glob(f"{STATION}_{name}_*.imbr")
        rec = load_recording(path)
        assert len(rec) == written and rec.lost_samples == rec_lost, name
        assert rec.metadata["sensor"] == name
    assert states(url) == {k: "offline" for k in keys}


def test_sigint_while_the_sensors_are_prepared_ends_cleanly(tmp_path: Path) -> None:
    """SIGINT after the first sensor is built, while the others are still prepared in
    the worker thread: exit 0 within the stop bound, no C++ abort ("terminate called")
    from a thread left inside native code at interpreter exit, no traceback, and every
    recording already opened is readable."""
    import signal

    sensors = tuple((f"imu{k}", f"sim://{chip}?odr_hz=1660&seed={k}&clock=wall"
                     f"&model=datasheet:{chip}")
                    for k, chip in enumerate(("lsm6dsl", "lsm6dsm", "lsm6ds3h")))
    sensors += (("imu3", "sensortile-sim://?seed=4&clock=wall"),)
    rec = tmp_path / "rec"
    daemon = start_daemon(config(tmp_path / "c.toml", "embedded", rec, sensors=sensors),
                          tmp_path)
    try:
        daemon.wait_for(r"imu0: source ", 90)
        time.sleep(1.0)
        t0 = time.monotonic()
        daemon.signal(signal.SIGINT)
        code = daemon.proc.wait(30)
        took = time.monotonic() - t0
    finally:
        daemon.kill()
    out = daemon.output()
    assert code == 0, out
    assert took < 10.0, out
    assert "terminate called" not in out and "Traceback" not in out, out
    for path in rec.glob("*.imbr"):
        load_recording(path)
