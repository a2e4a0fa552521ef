"""The fleet inventory (imubench.fleet.inventory): what each message does to a sensor's
state, health and curves, and the change feed the web page reads."""

from __future__ import annotations

import json

import pytest

from imubench.fleet.inventory import Inventory

T = "imubench/lab1/imu0"


def snapshot(samples: int, time: str, **extra: object) -> bytes:
    chan = {"tau_s": [0.01, 0.02, 0.04], "dev": [0.04, 0.028, 0.02],
            "ci_low": [0.039, 0.027, 0.019], "ci_high": [0.041, 0.029, 0.021],
            "n": [99, 97, 93], "alpha": [0, 0, 0], "edf": [98, 60, 30], "units": "dps"}
    doc = {"time": time, "station": "lab1", "sensor": "imu0", "chip": "lsm6dsl",
           "odr_hz": 104.0, "samples": samples, "lost_samples": 3, "statistic": "oadev",
           "memory": "bounded", "channels": {"gx": chan},
           "statistics": {"oadev": {"gx": chan}, "mdev": {"gx": chan}}, **extra}
    return json.dumps(doc).encode()


def online(**extra: object) -> bytes:
    return json.dumps({"state": "online", "station": "lab1", "sensor": "imu0",
                       "client_id": "x", "host": "bench-pc", "pid": 42,
                       "since": "2026-11-23T10:00:00+00:00", "chip": "lsm6dsl",
                       **extra}).encode()


def test_status_then_snapshots_then_will() -> None:
    inv = Inventory(min_stale_s=3.0, stale_factor=3.0)
    assert inv.apply(f"{T}/status", online(recording_bytes=123456, backlog=7), 0.0)
    assert inv.views(0.0)[0]["state"] == "waiting"
    inv.apply(f"{T}/allan", snapshot(104, "2026-11-23T10:00:01+00:00"), 1.0)
    inv.apply(f"{T}/allan", snapshot(312, "2026-11-23T10:00:03+00:00"), 3.0)
    assert "measured_odr_hz" not in {h["key"] for h in inv.views(3.5)[0]["health"]}
    inv.apply(f"{T}/allan", snapshot(728, "2026-11-23T10:00:07+00:00"), 3.0)
    v = inv.views(3.5)[0]
    assert v["state"] == "online" and v["key"] == "lab1/imu0"
    health = {h["key"]: h["value"] for h in v["health"]}
    assert health["samples"] == 728 and health["lost_samples"] == 3
    assert health["measured_odr_hz"] == pytest.approx((728 - 104) / 6.0)
    assert health["recording_bytes"] == 123456 and health["host"] == "bench-pc"
    assert v["extra"] == {"backlog": 7}  # unknown status field, shown as published
    assert set(v["statistics"]) == {"oadev", "mdev"}
    assert v["statistics"]["oadev"]["gx"]["dev"] == [0.04, 0.028, 0.02]
    assert v["readouts"]["statistic"] == "oadev"
    # the will (plain text) turns it offline, keeping what was known
    inv.apply(f"{T}/status", b"offline", 4.0)
    v = inv.views(4.0)[0]
    assert v["state"] == "offline" and v["status_state"] == "offline" and v["offline_at"]
    assert {h["key"] for h in v["health"]} >= {"samples", "chip"}


def test_stale_after_silence_and_refresh_reports_the_change() -> None:
    inv = Inventory(min_stale_s=3.0, stale_factor=3.0)
    inv.apply(f"{T}/status", online(), 0.0)
    for i in range(4):
        inv.apply(f"{T}/allan", snapshot(104 * (i + 1), f"2026-11-23T10:00:0{i}+00:00"),
                  float(i))
    v0 = inv.version
    assert not inv.refresh(5.9)  # 2.9 s after the last snapshot: within max(3, 3 x 1 s)
    assert inv.refresh(6.1)
    changed, gone, version = inv.changes(v0, 6.1)
    assert [c["state"] for c in changed] == ["stale"] and gone == [] and version > v0
    inv.apply(f"{T}/allan", snapshot(600, "2026-11-23T10:00:07+00:00"), 7.0)
    assert inv.views(7.0)[0]["state"] == "online"


def test_cleared_status_removes_the_sensor_and_feeds_a_tombstone() -> None:
    inv = Inventory()
    inv.apply(f"{T}/status", online(), 0.0)
    v = inv.version
    assert inv.apply(f"{T}/status", b"", 1.0)
    assert inv.views(1.0) == []
    assert inv.changes(v, 1.0)[1] == ["lab1/imu0"]
    assert not inv.apply(f"{T}/status", b"", 1.0)  # nothing left to clear


def test_jig_result_kept_and_bad_payloads_reported() -> None:
    inv = Inventory()
    jig = {"verdict": "pass", "measurements": [
        {"name": "gyro noise density", "value": 4.1, "unit": "mdps/√Hz", "low": None,
         "high": 6.0, "ci_low": 3.9, "ci_high": 4.3, "verdict": "pass"}]}
    inv.apply(f"{T}/jig", json.dumps(jig).encode(), 0.0)
    inv.apply(f"{T}/allan", b"{not json", 0.0)
    inv.apply(f"{T}/status", b"\xff\xfe", 0.0)
    v = inv.views(0.0)[0]
    assert v["jig"] == jig
    assert any("allan payload is not a JSON object" in e for e in v["errors"])
    assert any("status payload is neither" in e for e in v["errors"])
    assert v["statistics"] == {}


def test_topics_outside_the_scheme_are_ignored() -> None:
    inv = Inventory()
    for topic in ("imubench/lab1/imu0/other", "imubench/lab1/status", "foo/a/b/status",
                  "imubench/a/b/c/status"):
        assert not inv.apply(topic, online(), 0.0)
    assert inv.views(0.0) == [] and inv.messages == 0


def test_measured_odr_restarts_with_the_daemon() -> None:
    inv = Inventory()
    inv.apply(f"{T}/allan", snapshot(5000, "2026-11-23T10:00:10+00:00"), 0.0)
    inv.apply(f"{T}/allan", snapshot(100, "2026-11-23T10:00:12+00:00"), 1.0)  # restarted
    assert "measured_odr_hz" not in {h["key"] for h in inv.views(1.0)[0]["health"]}
    inv.apply(f"{T}/allan", snapshot(724, "2026-11-23T10:00:18+00:00"), 2.0)
    health = {h["key"]: h["value"] for h in inv.views(2.0)[0]["health"]}
    assert health["measured_odr_hz"] == pytest.approx(104.0)


def test_the_daemons_nested_snapshot_health() -> None:
    inv = Inventory()
    health = {"phase": "acquiring", "produced": 5000, "lag": {"engine": 0},
              "source": {"gaps": 2, "measured_odr_hz": 104.1, "overruns": 0},
              "recording": {"state": "recording", "bytes": 5000, "path": "/r.imbr",
                            "segments": 1}}
    inv.apply(f"{T}/allan", snapshot(104, "2026-11-23T10:00:01+00:00", health=health), 0.0)
    v = inv.views(0.0)[0]
    shown = {h["key"]: h["value"] for h in v["health"]}
    assert shown["phase"] == "acquiring" and shown["gaps"] == 2
    assert shown["measured_odr_hz"] == 104.1  # the daemon's own, not the view's estimate
    assert shown["recording_bytes"] == 5000 and shown["recording_path"] == "/r.imbr"
    assert shown["recording_state"] == "recording"
    # the rest of the nested object, flattened, shown as published
    assert v["extra"] == {"health.produced": 5000, "health.lag.engine": 0,
                          "health.source.overruns": 0, "health.recording.segments": 1}


@pytest.mark.parametrize("junk", [
    b'{"statistics":{"oadev":{"gx":{"tau_s":["x","y","z"],"dev":[1,2,3],"units":"dps"}}}}',
    b'{"statistics":{"oadev":{"gx":{"tau_s":[1,2,3],"dev":[[1],2,3],"units":"dps"}}}}',
    b'{"statistics":{"oadev":{"gx":{"tau_s":[1,2,3],"dev":{"a":1},"units":"dps"}}}}',
    b'{"samples":NaN,"statistics":{}}', b'{"samples":1e400}'])
def test_a_malformed_snapshot_is_refused_and_the_views_stay_valid_json(junk: bytes) -> None:
    """Anyone may publish on the broker: a snapshot with text in a curve ended the
    view's listener for good (every sensor stale, ``fleet status`` exit 70), and one
    with NaN made ``/api/fleet`` answer 500. Such a message is refused, named in the
    sensor's errors, and the sensor keeps its last good snapshot."""
    inv = Inventory()
    inv.apply(T + "/status", online(), 1.0)
    inv.apply(T + "/allan", snapshot(1000, "2026-11-23T10:00:10+00:00"), 1.0)
    inv.apply(T + "/allan", junk, 2.0)
    (view,) = inv.views(2.0)
    json.dumps(view, allow_nan=False)  # valid JSON for the page and the event stream
    assert view["snapshot_time"] == "2026-11-23T10:00:10+00:00"  # the last good one
    assert view["errors"]
    s = inv.sensors["lab1/imu0"]
    assert s.errors and s.curves["oadev"]["gx"]["tau_s"] == [0.01, 0.02, 0.04]


def test_a_node_restarted_without_a_sensor_shows_it_offline_and_a_slow_cadence_is_kept(
        ) -> None:
    """A node that restarted with sensors s0 and s2 only left s1 "stale" for good with the
    dead process's pid; a daemon publishing every 10 s was flagged stale between its
    first two snapshots (a 1 s cadence assumed)."""
    inv = Inventory()
    node = "imubench/lab1/node/rig/status"
    inv.apply(node, json.dumps({"state": "online", "node": "rig",
                                "sensors": ["s0", "s1"]}).encode(), 0.0)
    for name in ("s0", "s1"):
        inv.apply(f"imubench/lab1/{name}/status", json.dumps(
            {"state": "online", "node": "rig", "publish_interval_s": 10.0}).encode(), 0.0)
        inv.apply(f"imubench/lab1/{name}/allan", snapshot(1000, "2026-11-23T10:00:10+00:00"),
                  0.0)
    assert {v["sensor"]: v["state"] for v in inv.views(8.0)} == {"s0": "online",
                                                                  "s1": "online"}
    inv.apply(node, json.dumps({"state": "online", "node": "rig",
                                "sensors": ["s0"]}).encode(), 9.0)
    assert {v["sensor"]: v["state"] for v in inv.views(9.0)} == {"s0": "online",
                                                                  "s1": "offline"}


def test_snapshots_whose_sample_count_stands_still_are_stalled() -> None:
    """A source frozen for a minute (a stalled bus) kept arriving snapshots with the same
    sample count and showed "online" with its nominal ODR."""
    inv = Inventory()
    inv.apply(T + "/status", online(), 0.0)
    for k in range(6):
        inv.apply(T + "/allan", snapshot(1000 + 104 * min(k, 1),
                                         f"2026-11-23T10:00:{10 + k:02d}+00:00"), float(k))
    (view,) = inv.views(5.0)
    assert view["state"] == "stalled"
    inv.apply(T + "/allan", snapshot(2000, "2026-11-23T10:00:16+00:00"), 6.0)
    (view,) = inv.views(6.0)
    assert view["state"] == "online"


def test_a_jig_result_alone_is_not_waiting() -> None:
    inv = Inventory()
    inv.apply("imubench/rig/dut/jig", json.dumps({"verdict": "PASS"}).encode(), 0.0)
    (view,) = inv.views(1.0)
    assert view["state"] == "jig"
