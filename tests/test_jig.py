"""The jig's parts: verdicts, limits and station files, run directories, the serial
fixture protocol on a pty, the manual fixture's refusal, the plugin left inert outside a
jig run, the simulator's jig extensions (chamber temperature, stuck axis, FIFO that loses
patterns)."""

from __future__ import annotations

import datetime as dt
import io
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import serial
from lsm6ds_sim.temperature import ChamberTemperature

from imubench.calibration.accel import SIX_POSITIONS
from imubench.jig.dut import Dut, resolve_uri_paths
from imubench.jig.errors import JigError
from imubench.jig.fixtures.base import FACE_POSES, specific_force
from imubench.jig.fixtures.manual import ManualFixture
from imubench.jig.fixtures.serial import SerialFixture
from imubench.jig.fixtures.serial_sim import IDENT, SimSerialFixtureServer
from imubench.jig.fixtures.sim import SimFixture
from imubench.jig.limits import load_limits
from imubench.jig.measurement import FAIL, INCONCLUSIVE, PASS, Measurement, judge, overall
from imubench.jig.runner import SUITE_DIR
from imubench.jig.station import load_station
from imubench.jig.store import HISTORY_FILE, append_history, check_serial, new_run_dir

REPO = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------ verdicts
@pytest.mark.parametrize(("ci", "low", "high", "verdict"), [
    ((1.0, 2.0), 0.0, 3.0, PASS),
    ((1.0, 2.0), 1.0, 2.0, PASS),          # touching the limits is inside
    ((4.0, 5.0), 0.0, 3.0, FAIL),
    ((-2.0, -1.0), 0.0, 3.0, FAIL),
    ((2.0, 4.0), 0.0, 3.0, INCONCLUSIVE),  # straddles high
    ((-1.0, 1.0), 0.0, None, INCONCLUSIVE),
    ((0.0, 0.0), 0.0, 0.0, PASS),          # an exact count at its limit
    ((1.0, 1.0), 0.0, 0.0, FAIL),
    ((math.nan, 1.0), 0.0, 3.0, INCONCLUSIVE),
    ((0.0, 20.0), None, 30.0, PASS),       # an upper bound below the limit
    ((0.0, 40.0), None, 30.0, INCONCLUSIVE),
])
def test_judge(ci: tuple[float, float], low: float | None, high: float | None,
               verdict: str) -> None:
    assert judge(ci[0], ci[1], low, high) == verdict


def test_overall_and_measurement_json() -> None:
    assert overall([PASS, PASS]) == PASS
    assert overall([PASS, INCONCLUSIVE]) == INCONCLUSIVE
    assert overall([INCONCLUSIVE, FAIL, PASS]) == FAIL
    m = Measurement.judged("noise_density.gx", 4.0, "mdps/sqrt(Hz)", 1.0, 6.0, (3.8, 4.2))
    back = Measurement.from_dict(m.as_dict())
    assert back == m and back.verdict == PASS
    n = Measurement.judged("x", math.nan, "-", 0.0, 1.0, (math.nan, math.nan))
    assert n.as_dict()["value"] is None and n.verdict == INCONCLUSIVE


# ------------------------------------------------------------------ files
def test_shipped_limits_cover_the_suite() -> None:
    names = set()
    for chip in ("lsm6dsl", "lsm6dsm", "lsm6ds3h"):
        lim = load_limits(REPO / "config" / f"limits-{chip}.toml")
        assert lim.chip == chip
        names = set(lim.limits)
        for ch in ("gx", "gy", "gz", "ax", "ay", "az"):
            assert f"noise_density.{ch}" in lim and f"bias_instability.{ch}" in lim
            assert f"temperature_coefficient.{ch}" in lim
        assert lim["identity.who_am_i"].low == (0x69 if chip == "lsm6ds3h" else 0x6A)
    # every measurement name the shipped suite records has a limit (or passes its own)
    suite_text = "".join(p.read_text() for p in SUITE_DIR.glob("test_*.py"))
    for prefix in ("identity.", "self_test.", "zero_rate_level.", "noise_density.",
                   "angle_random_walk.", "bias_instability.", "temperature_sensor.",
                   "fifo.", "zero_g_offset.", "accel_calibration.gain_error.",
                   "accel_calibration.residual_max", "gyro_sensitivity.", "gyro_cross_axis.",
                   "temperature_coefficient.", "temperature_calibration.residual_max."):
        assert prefix.rstrip(".") in suite_text
        assert any(n.startswith(prefix) for n in names), prefix


def test_limits_errors_name_file_and_limit(tmp_path: Path) -> None:
    p = tmp_path / "lim.toml"
    p.write_text('chip = "lsm6dsl"\n[noise_density]\ngx = { low = 5.0, high = 1.0, unit = "x" }\n')
    with pytest.raises(JigError, match=r"lim\.toml: limit 'noise_density\.gx' has low 5\.0"):
        load_limits(p)
    p.write_text('chip = "lsm6dsl"\n[a]\nb = { hihg = 1.0, unit = "x" }\n')
    with pytest.raises(JigError, match=r"unknown keys \['hihg'\]"):
        load_limits(p)
    p.write_text('[a]\nb = { high = 1.0, unit = "x" }\n')
    with pytest.raises(JigError, match="key 'chip'"):
        load_limits(p)


def test_station_errors_name_file_and_key(tmp_path: Path) -> None:
    p = tmp_path / "st.toml"
    p.write_text("[capture]\nstatic_s = -1\n[fixture]\nkind = 'robot'\n")
    with pytest.raises(JigError) as err:
        load_station(p)
    text = str(err.value)
    assert "st.toml: key capture.static_s" in text and "st.toml: key fixture.kind" in text
    p.write_text("[station]\nname = 'a/b'\n")
    with pytest.raises(JigError, match=r"key station\.name.*'/'"):
        load_station(p)
    p.write_text("[capture]\nsettle_s = \"2\"\n")  # a string is no number (was 2 s)
    with pytest.raises(JigError, match=r"key capture\.settle_s"):
        load_station(p)
    p.write_text("[dut]\nuri = 'i2c:///dev/i2c-1'\n[fixture]\nkind = 'sim'\n")
    with pytest.raises(JigError, match="the DUT must be sim://"):
        load_station(p)
    p.write_text("[capture]\nhot_c = 90.0\n")
    with pytest.raises(JigError, match=r"capture\.hot_c = 90\.0 must be one of"):
        load_station(p)
    st = load_station(REPO / "config" / "station-sim.toml")
    assert st.fixture.kind == "sim" and st.station.name == "sim1"


def test_uri_paths_resolved_against_the_station(tmp_path: Path) -> None:
    uri = resolve_uri_paths("sim://lsm6dsl?seed=2&model=m.toml&clock=virtual", tmp_path)
    assert f"model={tmp_path.resolve()}/m.toml" in uri and uri.endswith("&clock=virtual")
    assert resolve_uri_paths("sim://lsm6dsl?model=/abs/m.toml", tmp_path).endswith("=/abs/m.toml")
    kept = "sim://lsm6dsl?model=datasheet:lsm6dsl"
    assert resolve_uri_paths(kept, tmp_path) == kept


def test_run_directories_never_overwrite(tmp_path: Path) -> None:
    t = dt.datetime(2026, 1, 2, 3, 4, 5, tzinfo=dt.UTC)
    a = new_run_dir(tmp_path, "SN-1", t)
    b = new_run_dir(tmp_path, "SN-1", t)
    assert a.name == "20260102T030405Z" and b.name == "20260102T030405Z-2"
    append_history(a, {"run_id": a.name, "verdict": "PASS"})
    append_history(b, {"run_id": b.name, "verdict": "FAIL"})
    lines = (tmp_path / "SN-1" / HISTORY_FILE).read_text().splitlines()
    assert len(lines) == 2 and '"FAIL"' in lines[1]
    for bad in ("../x", "a/b", "", ".."):
        with pytest.raises(JigError, match="serial number"):
            check_serial(bad)


# ------------------------------------------------------------------ fixtures
def test_faces_match_the_six_positions() -> None:
    for face, rp in FACE_POSES.items():
        assert np.allclose(specific_force(*rp), SIX_POSITIONS[face])
    f = specific_force(30.0, 0.0)  # roll 30: gravity between +Y and +Z
    assert np.allclose(f, [0.0, 0.5, math.sqrt(3) / 2])


def test_manual_fixture_refuses_without_a_terminal() -> None:
    with pytest.raises(JigError, match="needs an operator at a terminal"):
        ManualFixture(io.StringIO(""), io.StringIO())


def test_serial_fixture_protocol_on_a_pty() -> None:
    dut = Dut("sim://lsm6dsl?odr_hz=104&seed=3&clock=virtual")
    sim = SimFixture(dut.sim, 30.0)  # type: ignore[arg-type]
    with SimSerialFixtureServer(sim) as server:
        # byte-exact answers through a plain pyserial port
        port = serial.serial_for_url(server.port, timeout=2.0)
        port.write(b"ID?\n")
        assert port.readline() == f"OK {IDENT}\n".encode()
        port.write(b"FLY 3\n")
        assert port.readline().startswith(b"ERR unknown command 'FLY 3'")
        port.write(b"POSE abc 1\n")
        assert port.readline().startswith(b"ERR")
        port.close()
        fx = SerialFixture(server.port, timeout_s=5.0)
        assert fx.ident == IDENT
        fx.face("-Z")
        assert np.allclose(sim.sim.physics.specific_force_g, [0, 0, -1])
        fx.pose(30.0, 0.0)
        assert np.allclose(sim.sim.physics.specific_force_g, [0, 0.5, math.sqrt(3) / 2])
        fx.spin("y", -150.0)
        assert np.allclose(sim.sim.physics.rate_dps, [0, -150, 0])
        assert np.allclose(sim.sim.physics.specific_force_g, [0, 1, 0])
        fx.set_chamber(60.0)
        assert fx.chamber_temperature_c() == 60.0
        with pytest.raises(JigError, match="spin axis"):
            fx.spin("w", 1.0)
        fx.close()
        assert server.error is None and server.commands >= 8
    dut.close()


# ------------------------------------------------------------------ simulator
def test_chamber_temperature_is_a_first_order_lag() -> None:
    ch = ChamberTemperature(25.0, 100.0)
    ch.set_point(10.0, 85.0)
    t = np.array([0.0, 10.0, 110.0, 310.0])
    want = [25.0, 25.0, 85.0 - 60.0 * math.exp(-1.0), 85.0 - 60.0 * math.exp(-3.0)]
    assert np.allclose(ch.at(t), want)
    here = float(ch.at(np.array([50.0]))[0])
    ch.set_point(50.0, -40.0)
    assert math.isclose(float(ch.at(np.array([150.0]))[0]),
                        -40.0 + (here + 40.0) * math.exp(-1.0))
    # times before a set point are unchanged by it
    assert np.allclose(ch.at(np.array([0.0, 10.0, 40.0])),
                       [25.0, 25.0, 85.0 - 60.0 * math.exp(-0.3)])
    with pytest.raises(ValueError, match="before the previous change"):
        ch.set_point(20.0, 0.0)


def test_stuck_axis_and_fifo_drops_reach_the_driver() -> None:
    dut = Dut("sim://lsm6dsl?odr_hz=104&seed=4&clock=virtual&model="
              + "datasheet:lsm6dsl&duration_s=400")
    chip = dut.sim.chip  # type: ignore[union-attr]
    chip.sim_stick_axis("gy")
    chip.sim_set_fifo_drop_rate(0.02, seed=9)
    st = dut.self_test()
    gyro_y = next(a for a in st.axes if a.sensor == "gyro" and a.axis == "Y")
    assert gyro_y.deflection == 0.0 and not gyro_y.passed
    cap = dut.capture(120.0, "check")
    gy = cap.channel("gy")
    assert np.ptp(gy[np.isfinite(gy)]) == 0.0 and np.nanstd(cap.channel("gx")) > 0.01
    dropped = chip.sim_stats["fifo_dropped_patterns"]
    assert dropped > 0 and cap.lost > 0
    # each lost pattern costs its own 8 samples at least (the driver resyncs on it)
    assert cap.lost >= 8 * dropped * 0.5
    assert {g.reason for g in cap.gaps} <= {"fifo resync", "fifo overrun", "fifo realign"}
    dut.close()


# ------------------------------------------------------------------ plugin
def test_plugin_is_inert_without_a_station(tmp_path: Path) -> None:
    (tmp_path / "test_user.py").write_text(textwrap.dedent("""
        def test_plain():
            assert 1 + 1 == 2

        def test_needs_dut(dut, measure):
            measure("x", 1.0, (1.0, 1.0), low=0.0, high=2.0)
    """))
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "imubench.jig.plugin", "-p", "no:cacheprovider",
         "-c", os.devnull, "--rootdir", str(tmp_path), str(tmp_path), "-q", "-rs"],
        capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "1 passed, 1 skipped" in proc.stdout
    assert "jig fixtures need a jig run" in proc.stdout
    assert not (tmp_path / "measurements.json").exists()


def test_limits_in_another_unit_of_the_kind_load_and_others_are_refused(
        tmp_path: Path) -> None:
    """A limit may state any unit of the measurement's kind (converted at the
    measurement); one of another kind, or a name the suite does not measure under a
    suite group (a typo), is refused at load naming the file and the limit: they were
    judged 1000x off, or FAILed the board at the end of the run."""
    text = (REPO / "config" / "limits-lsm6dsl.toml").read_text()
    p = tmp_path / "lim.toml"
    p.write_text(text.replace(
        'ax = { low = -90.0, high = 90.0, unit = "mg"',
        'ax = { low = -0.09, high = 0.09, unit = "g"'))
    assert load_limits(p)["zero_g_offset.ax"].unit == "g"
    p.write_text(text.replace('unit = "mdps/sqrt(Hz)"', 'unit = "deg/h"', 1))
    with pytest.raises(JigError, match=r"lim\.toml: limit 'noise_density\.gx' is in "
                                       r"'deg/h', which is not a unit of"):
        load_limits(p)
    p.write_text(text.replace("[zero_rate_level]\ngx =", "[zero_rate_level]\ngzz ="))
    with pytest.raises(JigError, match=r"limit 'zero_rate_level\.gzz': the suite measures "
                                       r"no such quantity"):
        load_limits(p)


def test_unit_conversions_against_their_definitions() -> None:
    from imubench.jig.units import conversion_factor

    assert conversion_factor("g", "mg") == pytest.approx(1e3)
    assert conversion_factor("mdps/sqrt(Hz)", "deg/sqrt(h)") == pytest.approx(0.06)
    assert conversion_factor("deg/h", "dps") == pytest.approx(1 / 3600)
    assert conversion_factor("m/s2", "g") == pytest.approx(1 / 9.80665)
    assert conversion_factor("%", "ppm") == pytest.approx(1e4)
    with pytest.raises(JigError):
        conversion_factor("dps", "g")


def test_arw_and_noise_density_are_the_white_term_beside_flicker() -> None:
    """A board with white 4 mdps/sqrt(Hz) and flicker B = 6 mdps (21.6 deg/h, inside the
    30 deg/h limit): ARW read as OADEV(1 s) x 60 came out 0.31-0.39 deg/sqrt(h) against
    the true 0.24, no interval covering it. The white term of the fit covers it."""
    from lsm6ds_sim.model import NoiseModel
    from lsm6ds_sim.physics import quantize, simulate

    from imubench.batch import CHANNELS
    from imubench.jig.analysis import angle_random_walk, noise_density
    from imubench.jig.dut import Capture

    model = NoiseModel.single_term("gx", white=0.004).with_channel("gx", flicker=0.006)
    covered_arw = covered_nd = 0
    for seed in range(10):
        y = quantize(simulate(model, 6240, 104.0, seed, channels=["gx"])["gx"], 8.75e-3)
        values = np.zeros((6240, 6))
        values[:, 0] = y
        lsb = np.array([8.75e-3] * 3 + [6.1e-5] * 3)
        cap = Capture("static", 104.0, 0, values, np.full(6240, 25.0), 0.0, (), lsb,
                      np.zeros(len(CHANNELS), np.int64))
        nd = noise_density(cap, "gx", 0.95)
        arw = angle_random_walk(nd)
        covered_arw += arw.ci[0] <= 0.24 <= arw.ci[1]
        covered_nd += nd.ci[0] <= 0.004 <= nd.ci[1]
        assert arw.value == pytest.approx(60.0 * nd.value)
    assert covered_arw >= 8 and covered_nd >= 8, (covered_arw, covered_nd)
