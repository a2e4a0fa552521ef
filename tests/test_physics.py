"""Sensor physics: true input, sensor errors, temperature, output filter, quantize helper."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from lsm6ds_sim.model import NoiseModel
from lsm6ds_sim.physics import SensorPhysics, quantize, quantize_counts, simulate
from lsm6ds_sim.temperature import (
    ConstantTemperature,
    RampTemperature,
    ReplayTemperature,
    SineTemperature,
    StepTemperature,
    parse_profile,
)
from scipy.signal import welch
from scipy.spatial.transform import Rotation

from imubench.errors import ModelError, ProfileError

DT = 1.0 / 104.0


def test_quiet_sensor_reads_gravity_on_z_at_25c() -> None:
    s = SensorPhysics().generate(100, DT)
    assert s.gyro_dps.shape == (100, 3) and s.accel_g.shape == (100, 3)
    assert np.all(s.gyro_dps == 0.0)
    assert np.all(s.accel_g == np.array([0.0, 0.0, 1.0]))
    assert np.all(s.temp_c == 25.0)


def test_jig_sets_rate_and_orientation() -> None:
    p = SensorPhysics()
    p.set_rate_dps([10.0, -20.0, 30.0])
    p.set_orientation([0.0, -1.0, 0.0])  # specific-force vector: Y axis pointing down
    s = p.generate(5, DT)
    assert np.all(s.gyro_dps == [10.0, -20.0, 30.0])
    assert np.all(s.accel_g == [0.0, -1.0, 0.0])
    # a rotation matrix: sensor rolled +90 deg about X -> gravity reaction along +Y
    r_ws = Rotation.from_euler("x", 90, degrees=True).as_matrix()
    p.set_orientation(r_ws)
    np.testing.assert_allclose(p.generate(1, DT).accel_g[0], [0.0, 1.0, 0.0], atol=1e-12)
    with pytest.raises(ModelError, match="rotation matrix"):
        p.set_orientation(np.ones((3, 3)))
    with pytest.raises(ModelError, match="3 values"):
        p.set_rate_dps([1.0, 2.0])


def test_sensitivity_nonlinearity_cross_axis_g_sensitivity_bias() -> None:
    m = (
        NoiseModel.quiet()
        .with_channel("gx", scale_error=0.02, cross_y=0.01, nonlinearity=1e-4, bias=0.5)
        .with_channel("gz", g_sensitivity_z=0.05, g_sensitivity_x=0.1)
        .with_channel("ay", cross_z=-0.003, scale_error=-0.01)
    )
    p = SensorPhysics(m, rate_dps=(100.0, 50.0, 0.0))
    s = p.generate(3, DT)
    expected_gx = 1.02 * (100.0 + 1e-4 * 100.0**2 + 0.01 * 50.0) + 0.5
    np.testing.assert_allclose(s.gyro_dps[:, 0], expected_gx, rtol=1e-12)
    np.testing.assert_allclose(s.gyro_dps[:, 2], 0.05 * 1.0, rtol=1e-12)  # +1 g on Z
    np.testing.assert_allclose(s.accel_g[:, 1], 0.99 * (0.0 - 0.003 * 1.0), rtol=1e-12)
    p.set_orientation([1.0, 0.0, 0.0])
    np.testing.assert_allclose(p.generate(2, DT).gyro_dps[:, 2], 0.1, rtol=1e-12)


def test_temperature_acts_on_bias_and_sensitivity_linearly_and_quadratically() -> None:
    m = NoiseModel.quiet().with_channel(
        "gy",
        bias=0.1,
        temp_coeff=0.01,
        temp_coeff2=-2e-4,
        temp_ref=20.0,
        scale_temp_coeff=1e-3,
        scale_temp_coeff2=1e-5,
    )
    ramp = RampTemperature(start_c=0.0, rate_c_per_s=1.0)
    p = SensorPhysics(m, temperature=ramp, rate_dps=(0.0, 10.0, 0.0))
    s = p.generate(5000, DT)
    dT = s.temp_c - 20.0
    expected = (1 + 1e-3 * dT + 1e-5 * dT**2) * 10.0 + 0.1 + 0.01 * dT - 2e-4 * dT**2
    np.testing.assert_allclose(s.gyro_dps[:, 1], expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(s.temp_c, np.arange(5000) * DT, rtol=1e-12)


def test_temperature_profiles() -> None:
    t = np.array([0.0, 5.0, 10.0, 20.0, 100.0])
    np.testing.assert_array_equal(ConstantTemperature(30.0).at(t), 30.0)
    np.testing.assert_allclose(RampTemperature(20.0, 0.5, 30.0).at(t), [20, 22.5, 25, 30, 30])
    steps = StepTemperature((0.0, 10.0, 50.0), (20.0, 30.0, 25.0))
    np.testing.assert_array_equal(steps.at(t), [20, 20, 30, 30, 25])
    sine = SineTemperature(25.0, 5.0, 40.0)
    np.testing.assert_allclose(sine.at(t), 25 + 5 * np.sin(2 * np.pi * t / 40), atol=1e-12)
    rep = ReplayTemperature(np.array([0.0, 10.0]), np.array([20.0, 40.0]))
    np.testing.assert_allclose(rep.at(t), [20, 30, 40, 40, 40])


def test_parse_profile(tmp_path: Path) -> None:
    assert parse_profile("31.5") == ConstantTemperature(31.5)
    assert parse_profile("ramp:20:0.01:40") == RampTemperature(20.0, 0.01, 40.0)
    assert parse_profile("steps:0=20,600=30") == StepTemperature((0.0, 600.0), (20.0, 30.0))
    assert parse_profile("sine:25:5:3600") == SineTemperature(25.0, 5.0, 3600.0)
    csv = tmp_path / "temp.csv"
    csv.write_text("# logged\ntime,T\n0,21\n100,23\n", encoding="utf-8")
    rep = parse_profile(f"replay:{csv}:time:T")
    assert rep.at(np.array([50.0]))[0] == pytest.approx(22.0)
    with pytest.raises(ProfileError, match="unknown kind 'cube'"):
        parse_profile("cube:1")
    with pytest.raises(ProfileError, match="malformed"):
        parse_profile("ramp:1")
    with pytest.raises(ProfileError, match="needs columns"):
        parse_profile(f"replay:{csv}")


def test_replay_real_temperature_recording(reference_dir: Path) -> None:
    """Temperature replayed from a real 74.5 h recording (CATS tag, 1 Hz) drives the bias."""
    rec = reference_dir / "imu-real" / "cats-tag-temperature" / "cats_temperature_calib.npz"
    data = np.load(rec)
    t_rec, temp_rec = data["t_s"], data["temperature_c"]
    prof = ReplayTemperature(t_rec, temp_rec, name="cats")
    m = NoiseModel.quiet().with_channel("gx", temp_coeff=0.02, temp_ref=25.0)
    n = 3600 * 10  # first hour at 10 Hz
    out = simulate(m, n, 10.0, temperature=prof)
    np.testing.assert_allclose(out["temp_c"][::10], temp_rec[:3600], rtol=0, atol=1e-9)
    np.testing.assert_allclose(out["gx"], 0.02 * (out["temp_c"] - 25.0), rtol=1e-12, atol=1e-15)


def _psd_ratio_at(bandwidth_hz: float, order: int) -> float:
    m = NoiseModel.single_term("gx", white=0.01, bandwidth_hz=bandwidth_hz, filter_order=order)
    y = simulate(m, 1 << 19, 104.0, seed=2)["gx"]
    f, p = welch(y, fs=104.0, nperseg=1 << 12)
    flat = np.median(p[(f > 0.2) & (f < 1.0)])
    near = (f > bandwidth_hz * 0.97) & (f < bandwidth_hz * 1.03)
    return float(np.mean(p[near]) / flat)


@pytest.mark.parametrize("order", [1, 2])
def test_output_filter_is_3db_down_at_bandwidth(order: int) -> None:
    # white noise of PSD 2 N^2 through the low-pass: PSD ratio |H(f_bw)|^2 = 1/2 (-3 dB)
    assert _psd_ratio_at(12.0, order) == pytest.approx(0.5, rel=0.08)


@pytest.mark.parametrize("order", [1, 2])
def test_output_filter_follows_bilinear_butterworth_response(order: int) -> None:
    """PSD / (2 N^2) = 1 / (1 + (tan(pi f / fs) / tan(pi f_c / fs))^(2 n)) over the band.

    The closed form is the Butterworth magnitude after the bilinear transform with the
    corner prewarped (Oppenheim & Schafer, Discrete-Time Signal Processing, 7.1.2).
    """
    fs, fc, N = 104.0, 5.0, 0.01
    m = NoiseModel.single_term("gx", white=N, bandwidth_hz=fc, filter_order=order)
    y = simulate(m, 1 << 19, fs, seed=3)["gx"]
    f, p = welch(y, fs=fs, nperseg=1 << 12)
    sel = (f > 0.5) & (f < 40.0)
    h2 = 1.0 / (1.0 + (np.tan(np.pi * f[sel] / fs) / np.tan(np.pi * fc / fs)) ** (2 * order))
    ratio = p[sel] / (2 * N**2 * h2)
    assert np.median(ratio) == pytest.approx(1.0, rel=0.03)
    assert np.percentile(np.abs(np.log(ratio)), 90) < 0.25  # no band where the shape is off


def test_output_filter_starts_in_steady_state_and_keeps_dc() -> None:
    m = NoiseModel.quiet().with_all(bandwidth_hz=2.0, filter_order=2).with_channel("ax", bias=0.3)
    s = SensorPhysics(m).generate(500, DT)
    np.testing.assert_allclose(s.accel_g[:, 0], 0.3, rtol=1e-9)
    np.testing.assert_allclose(s.accel_g[:, 2], 1.0, rtol=1e-9)


def test_simulate_equals_chunked_physics() -> None:
    m = NoiseModel.quiet().with_all(white=0.004, flicker=0.001, random_walk=1e-4)
    n = 30_000
    out = simulate(m, n, 104.0, seed=5, temperature="sine:25:3:60")
    p = SensorPhysics(m, seed=5, temperature="sine:25:3:60", duration_hint_s=n / 104.0)
    parts = [p.generate(k, DT) for k in (100, 7000, 22_900)]
    acc = np.vstack([q.accel_g for q in parts])
    np.testing.assert_array_equal(acc[:, 2], out["az"])
    np.testing.assert_array_equal(np.concatenate([q.temp_c for q in parts]), out["temp_c"])
    assert p.time_s == pytest.approx(n * DT)


def test_quantize_helper() -> None:
    lsb = 4.375e-3
    v = np.array([0.0, 1.4 * lsb, 1.6 * lsb, -2.5 * lsb, 1e6, -1e6, np.nan])
    c = quantize_counts(v, lsb)
    assert c.dtype == np.int16
    assert list(c) == [0, 1, 2, -2, 32767, -32768, 0]
    assert list(quantize_counts(np.array([200.0, -200.0]), lsb, fs=125.0)) == [28571, -28571]
    np.testing.assert_allclose(quantize(np.array([0.01]), lsb), [2 * lsb])
    # rounding error uniform on [-lsb/2, lsb/2]: variance lsb^2/12 (Widrow)
    x = np.random.default_rng(0).uniform(-50, 50, 200_000)
    err = quantize(x, lsb) - x
    assert np.max(np.abs(err)) <= lsb / 2 + 1e-15
    assert np.var(err) == pytest.approx(lsb**2 / 12, rel=0.02)


def test_generate_rejects_bad_arguments() -> None:
    with pytest.raises(ModelError, match="dt_s > 0"):
        SensorPhysics().generate(10, 0.0)
    with pytest.raises(ModelError, match="unknown channel"):
        SensorPhysics(channels=["gx", "mx"])
    assert math.isclose(SensorPhysics().time_s, 0.0)
