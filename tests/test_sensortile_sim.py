"""The simulated SensorTile firmware on a real pty, read with real pyserial.

The oracle is the firmware's own log of what it sent (``sim_stats.log``: values before
the line faults, and whether a fault touched the frame); the decoding path under test
(pyserial -> TMsg deframer -> stream parser -> RTC index -> Batch) never sees it.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
import serial
from lsm6ds.sensortile import commands as cmds
from lsm6ds.sensortile.link import LinkConfig, SensorTileError, SensorTileLink
from lsm6ds.sensortile.stream import parse_stream_message
from lsm6ds.sensortile.tmsg import Frame, FrameDecoder
from lsm6ds_sim.sensortile_fw import SensorTileFirmware, SerialFaults

from imubench.batch import Batch
from imubench.errors import SourceError
from imubench.sources.registry import open_source
from imubench.sources.sensortile import SensorTileSource

pytestmark = pytest.mark.timeout(120)


def _collect(source: SensorTileSource) -> Batch:
    with source:
        batches = list(source)
    assert source.firmware is None or source.firmware.error is None
    return Batch.concat(batches)


def _oracle(fw: SensorTileFirmware, period_cs: int = 1) -> dict[int, object]:
    """Sent frames by index relative to the first frame the firmware put on the line."""
    sent = [f for f in fw.sim_stats.log if f.sent]
    first_cs = sent[0].rtc_cs
    return {(f.rtc_cs - first_cs) // period_cs: f for f in sent}


def _check_exact(batch: Batch, oracle: dict[int, object]) -> None:
    """Every decoded sample equals what the firmware sent at that index (exactly)."""
    sent = [oracle[int(i)] for i in batch.index]
    gyro = np.array([f.gyro_mdps for f in sent], dtype=np.float64) / 1000.0  # type: ignore[attr-defined]
    accel = np.array([f.accel_mg for f in sent], dtype=np.float64) / 1000.0  # type: ignore[attr-defined]
    np.testing.assert_array_equal(batch.values[:, :3], gyro)
    np.testing.assert_array_equal(batch.values[:, 3:], accel)


def _sim_source(fw: SensorTileFirmware, duration_s: float, **link: float) -> SensorTileSource:
    return SensorTileSource(
        "sensortile-sim://test",
        fw.url,
        mode=fw.mode,
        period_s=fw.period_s,
        duration_s=duration_s,
        host_check_s=None,
        firmware=fw,
        link_config=LinkConfig(**link),  # type: ignore[arg-type]
    )


# ------------------------------------------------------------------ raw pyserial client
def test_pyserial_client_decodes_every_frame_exactly() -> None:
    with SensorTileFirmware(seed=3, keep_log=True) as fw:
        port = serial.serial_for_url(fw.url, timeout=1.0)
        port.write(cmds.frame(cmds.start_streaming_request(0x70)))
        dec = FrameDecoder()
        frames: list[Frame] = []
        while len(frames) < 501:  # the reply, then 500 stream frames
            frames += [f for f in dec.feed(port.read(port.in_waiting or 1)) if isinstance(f, Frame)]
        port.write(cmds.frame(cmds.stop_streaming_request()))
        port.close()
    assert frames[0].message == bytes([0x01, 0x32, 0x88])
    sent = [f for f in fw.sim_stats.log if f.sent]
    assert dec.bad_frames == 0
    for frame, oracle in zip(frames[1:501], sent, strict=False):
        got = parse_stream_message(frame.message)
        assert got.gyro_mdps == oracle.gyro_mdps
        assert got.accel_mg == oracle.accel_mg
        assert got.mag_mgauss == (220, -45, -410)
        assert got.rtc_cs == oracle.rtc_cs
        assert got.flags == oracle.flags
    # the chip behind is noisy and sampled on the firmware's timer: values vary
    assert len({f.gyro_mdps for f in sent[:500]}) > 100


def test_commands_on_the_pty() -> None:
    with SensorTileFirmware(seed=0) as fw, SensorTileLink(fw.url) as link:
        link.ping()
        assert link.presentation() == "MEMS shield demo,101,4.0.0,0.0.0,STLKT01V1"
        assert link.check_mode() == 101
        name = link.command(cmds.get_name_request(cmds.SensorType.GYROSCOPE))
        assert name.payload == bytes([0x01, 0x02]) + b"LSM6DSM"
        who = link.command(cmds.read_register_request(cmds.SensorType.ACCELEROMETER, 0x0F))
        assert who.payload[-1] == 0x6A  # WHO_AM_I of the LSM6DSM
        with pytest.raises(SensorTileError, match="NACK"):
            link.command(bytes([0x32, 0x01, 0x0F]))  # reset: not handled by the firmware


# ------------------------------------------------------------------ source, clean and faulty
def test_clean_stream_has_no_holes_and_exact_values() -> None:
    fw = SensorTileFirmware(seed=1, keep_log=True)
    batch = _collect(_sim_source(fw, duration_s=5.0))
    assert len(batch) == 500
    np.testing.assert_array_equal(batch.index, np.arange(500))
    np.testing.assert_allclose(batch.t_s, batch.index * 0.01, atol=1e-9)
    _check_exact(batch, _oracle(fw))
    assert batch.raw is None
    assert np.all(np.isfinite(batch.temp_c))


@pytest.mark.parametrize(("frames", "seed"), [(3000, 11)])
def test_corruption_1e3_every_frame_decoded_or_counted(frames: int, seed: int) -> None:
    fw = SensorTileFirmware(
        seed=seed,
        keep_log=True,
        faults=SerialFaults(corrupt_rate=1e-3, drop_rate=1e-4, split_rate=0.02),
    )
    src = _sim_source(fw, duration_s=frames / 100)
    batch = _collect(src)
    oracle = _oracle(fw)
    last = int(batch.index[-1])
    c = src.counters
    # frames sent = decoded + counted lost, exactly
    assert len(batch) + c["lost_samples"] == last + 1
    assert c["samples"] == len(batch)
    assert c["bad_frames"] > 0 and c["gaps"] > 0
    _check_exact(batch, oracle)
    decoded = set(batch.index.tolist())
    in_range = {i: f for i, f in oracle.items() if i <= last}
    damaged = {i for i, f in in_range.items() if f.damaged}  # type: ignore[attr-defined]
    assert damaged and not damaged & decoded  # no damaged frame got through
    # an intact frame is lost only when the one before lost its terminator
    lost_intact = set(in_range) - damaged - decoded
    assert all(i - 1 in damaged for i in lost_intact)
    assert len(damaged) >= 0.04 * len(in_range)  # ~60 bytes x 1.1e-3 per frame


def test_corruption_and_two_unplugs_resume() -> None:
    fw = SensorTileFirmware(
        seed=5,
        keep_log=True,
        faults=SerialFaults(
            corrupt_rate=1e-3, unplug_every_s=8.0, replug_after_s=0.5, max_unplugs=2
        ),
    )
    src = _sim_source(fw, duration_s=25.0, backoff_initial_s=0.01, backoff_max_s=0.1)
    batch = _collect(src)
    assert fw.sim_stats.unplugs == 2 and fw.sim_stats.replugs == 2
    assert src.counters["reconnects"] == 2
    assert src.counters["io_errors"] >= 2
    assert len(batch) + src.counters["lost_samples"] == int(batch.index[-1]) + 1
    _check_exact(batch, _oracle(fw))
    # the stream resumed after each replug: decoded frames after each outage
    unsent = [f.tick for f in fw.sim_stats.log if not f.sent]
    assert len(unsent) >= 2 * 50
    outages = np.split(np.array(unsent), np.nonzero(np.diff(unsent) > 1)[0] + 1)
    first_tick = next(f.tick for f in fw.sim_stats.log if f.sent)
    for outage in outages[:2]:
        after = int(outage[-1]) + 1 - first_tick
        assert np.any((batch.index > after) & (batch.index < after + 200))
    # START was re-sent after each reconnect (3 starts in all)
    assert fw.sim_stats.commands >= 3 + 3  # presentation, check mode, 2x get fs, ...


def test_reconnect_backoff_doubles_and_gives_up() -> None:
    slept: list[float] = []

    def sleeping(dt_s: float) -> None:
        slept.append(dt_s)
        time.sleep(dt_s)

    cfg = LinkConfig(backoff_initial_s=0.01, backoff_max_s=0.04, reconnect_timeout_s=0.2)
    link = SensorTileLink("/nonexistent/imubench-tty", config=cfg, sleep=sleeping)
    with pytest.raises(SensorTileError, match="did not come back"):
        link.reconnect()
    assert slept[:4] == [0.01, 0.02, 0.04, 0.04]


def test_the_unplug_timer_counts_from_the_hosts_stream_start() -> None:
    """``unplug_every_s`` counts streaming time: a host that takes longer than that to
    start its stream (a loaded machine compiling) still gets samples before the pull;
    counted from plug-in, the kit was gone before the first one."""
    from lsm6ds_sim.clock import SimClock

    faults = SerialFaults(unplug_every_s=0.3, replug_after_s=100.0, max_unplugs=1)
    with SensorTileFirmware(seed=3, clock=SimClock("wall"), faults=faults) as fw:
        link = SensorTileLink(fw.url, config=LinkConfig(reconnect_timeout_s=0.05))
        link.open()
        time.sleep(0.8)  # plugged and idle for longer than unplug_every_s
        assert fw.sim_plugged and fw.sim_stats.unplugs == 0
        link.start_streaming()
        got: list[object] = []
        with pytest.raises(SensorTileError, match="did not come back"):
            while True:
                got += link.read_stream()
        link.close()
    assert fw.sim_stats.unplugs == 1
    assert 15 <= len(got) <= 35  # 0.3 s at 100 Hz, less what the pull cut off


def test_a_kit_lost_for_good_has_its_outage_counted_before_the_error() -> None:
    """Unplugged and not back within ``reconnect_timeout_s``: the frames the kit made
    from the newest one received to the give-up are one gap ("serial link down"),
    delivered before the error (an outside reviewer: "151 recorded, 0 lost", where a stop
    during the same outage counted 226 lost)."""
    src = open_source("sensortile-sim://?clock=wall&unplug_every_s=1&replug_after_s=100"
                      "&reconnect_timeout_s=1")
    got: list[Batch] = []
    t0 = time.monotonic()
    with pytest.raises(SourceError, match="did not come back"), src:
        for b in src:
            got.append(b)
    wall = time.monotonic() - t0
    n = sum(len(b) for b in got)
    gaps = [g for b in got for g in b.gaps]
    assert 50 <= n <= 110 and [g.reason for g in gaps] == ["serial link down"]
    # the kit's 100 Hz over the host's time to the give-up (opening took some of it)
    assert 100 * (wall - 1.0) <= n + gaps[0].lost <= 100 * wall + 2, (n, gaps, wall)


def test_link_reconnects_after_unplug_and_restarts_stream() -> None:
    with SensorTileFirmware(seed=2, keep_log=True) as fw:
        link = SensorTileLink(fw.url, config=LinkConfig(backoff_initial_s=0.01))
        link.open()
        link.start_streaming()
        got = []
        while len(got) < 100:
            got += link.read_stream()
        fw.sim_unplug()
        while link.counters["reconnects"] == 0 or len(got) < 300:
            got += link.read_stream()
        link.close()
    assert link.counters["reconnects"] == 1
    assert fw.sim_stats.unplugs == 1 and fw.sim_stats.replugs == 1
    rtcs = [r.item.rtc_cs for r in got]  # type: ignore[union-attr]
    jumps = np.diff(rtcs)
    assert np.count_nonzero(jumps > 1) == 1  # one hole: the outage (0.5 s of ticks)
    assert int(jumps.max()) >= 50


# ------------------------------------------------------------------ ASCII fallback
def test_ascii_mode_values_exact_with_split_writes() -> None:
    fw = SensorTileFirmware(
        mode="ascii", seed=4, keep_log=True, faults=SerialFaults(split_rate=0.05)
    )
    src = _sim_source(fw, duration_s=6.0)
    batch = _collect(src)
    assert len(batch) == 300
    np.testing.assert_array_equal(batch.index, np.arange(300))
    sent = {f.tick: f for f in fw.sim_stats.log}
    # the firmware streamed before the host opened the port (pyserial flushes that):
    # index 0 is the record stamped firmware_t0_s
    first = round(src.info.config["firmware_t0_s"] * 1000 / fw.period_ms)
    gyro = np.array([sent[first + i].gyro_mdps for i in batch.index]) / 1000.0
    np.testing.assert_array_equal(batch.values[:, :3], gyro)
    assert np.all(np.isnan(batch.temp_c))


# ------------------------------------------------------------------ registry and URIs
def test_registry_uri_and_model(tmp_path: object) -> None:
    from pathlib import Path

    from lsm6ds_sim.model import NoiseModel

    path = Path(str(tmp_path)) / "quiet.toml"
    path.write_text(NoiseModel.quiet().to_toml())
    src = open_source(f"sensortile-sim://?seed=2&duration_s=1&model={path}")
    assert isinstance(src, SensorTileSource)
    batch = _collect(src)
    assert len(batch) == 100
    assert src.info.fs_g == 2.0 and src.info.fs_dps == 250.0 and src.info.odr_hz == 100.0
    # a quiet sensor at rest: 1 g on Z = round(1 / 0.061e-3) = 16393 counts; the BSP gives
    # (int32)(16393 * 0.061f) = 999 mg; zero rate gives 0 mdps
    np.testing.assert_array_equal(batch.values[:, :3], 0.0)
    np.testing.assert_array_equal(batch.values[:, 3:], np.tile([0.0, 0.0, 0.999], (100, 1)))


@pytest.mark.parametrize(
    ("uri", "match"),
    [
        ("sensortile-sim://?bogus=1", "unknown parameter"),
        ("sensortile-sim://?period_ms=15", "multiple of 10"),
        ("sensortile-sim://?corrupt_rate=2", "corrupt_rate"),
        ("sensortile-sim://?mode=hex", "binary, ascii"),
        ("sensortile://", "names no port"),
    ],
)
def test_bad_uris(uri: str, match: str) -> None:
    with pytest.raises(SourceError, match=match):
        open_source(uri)


def test_real_scheme_on_a_pty_and_wall_clock() -> None:
    """``sensortile://PATH`` (the real-kit source) against a wall-clock firmware."""
    from lsm6ds_sim.clock import SimClock

    with SensorTileFirmware(clock=SimClock("wall"), seed=9) as fw:
        src = open_source(f"sensortile://{fw.url}?duration_s=0.3")
        batch = _collect(src)
    assert len(batch) > 0
    assert len(batch) + src.counters["lost_samples"] == int(batch.index[-1]) + 1
    np.testing.assert_allclose(batch.t_s, batch.index * 0.01, atol=1e-9)


@pytest.mark.slow
def test_long_run_corruption_accounting() -> None:
    fw = SensorTileFirmware(
        seed=21,
        keep_log=True,
        faults=SerialFaults(
            corrupt_rate=1e-3, drop_rate=1e-4, split_rate=0.01, unplug_every_s=60.0
        ),
    )
    src = _sim_source(fw, duration_s=300.0, backoff_initial_s=0.01)
    batch = _collect(src)
    assert len(batch) + src.counters["lost_samples"] == int(batch.index[-1]) + 1
    assert src.counters["reconnects"] == fw.sim_stats.replugs >= 4
    _check_exact(batch, _oracle(fw))
