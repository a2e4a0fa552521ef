"""Calibration fits against independent references (hand-built data, numpy.polyfit),
the calibration file (round trip, provenance, errors naming file and key, application
that leaves raw counts alone), and the capture-mean intervals (coverage on white noise)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from imubench.batch import Batch
from imubench.calibration import Calibration, CalibrationError, SensorCalibration
from imubench.calibration.accel import SIX_POSITIONS, flip_two_point, one_point_offset, six_position
from imubench.calibration.gyro import rate_table
from imubench.calibration.means import capture_mean
from imubench.calibration.temperature import polynomial, three_point_exact, three_point_note

PROV = {"serial": "SN1", "date_utc": "2026-11-23T00:00:00+00:00", "station": "bench1"}
FACES = list(SIX_POSITIONS)


def _readings(u: np.ndarray, M: np.ndarray, b: np.ndarray, q: np.ndarray) -> np.ndarray:
    return u @ M.T + q * u**2 + b


def test_six_position_recovers_a_hand_built_sensor() -> None:
    M = np.array([[1.02, 0.004, -0.003], [0.002, 0.985, 0.006], [-0.005, 0.001, 1.01]])
    b, q = np.array([0.03, -0.02, 0.05]), np.array([0.004, -0.002, 0.003])
    u = np.array([SIX_POSITIONS[f] for f in FACES])
    fit = six_position(FACES, _readings(u, M, b, q), np.full((6, 3), 1e-4), quadratic=True)
    assert np.allclose(fit.matrix, M, atol=1e-12) and np.allclose(fit.offset, b, atol=1e-12)
    assert np.allclose(fit.nonlinearity, q, atol=1e-12)
    assert np.allclose(fit.residuals, 0.0, atol=1e-12)
    assert np.allclose(fit.cross_axis[0], [0.0, 0.004 / 1.02, -0.003 / 1.02])
    # the 12-parameter fit cannot tell q from an offset seen along gravity: the offset
    # takes q/3 (q in 2 of 6 positions) and the residuals are 2q/3 and -q/3
    lin = six_position(FACES, _readings(u, M, b, q), np.full((6, 3), 1e-4))
    assert np.allclose(lin.offset, b + q / 3.0, atol=1e-12)
    assert np.allclose(lin.residuals[:2, 0], 2.0 * q[0] / 3.0, atol=1e-12)
    assert np.allclose(lin.residuals[2:, 0], -q[0] / 3.0, atol=1e-12)
    # the correction inverts the model
    from imubench.calibration.sensor import correct

    probe = np.array([[0.3, -0.5, 0.81], [0.0, 0.0, 1.0]])
    assert np.allclose(correct(_readings(probe, M, b, q), M, b, q), probe, atol=1e-9)


def test_one_point_and_flip() -> None:
    assert np.allclose(one_point_offset([0.01, -0.02, 1.03], [0, 0, 1]), [0.01, -0.02, 0.03])
    off, gain = flip_two_point(np.array([1.02, 0.99, 1.05]), np.array([-0.98, -1.01, -0.97]))
    assert np.allclose(off, [0.02, -0.01, 0.04]) and np.allclose(gain, [1.0, 1.0, 1.01])
    with pytest.raises(CalibrationError, match="reads no more at \\+1 g"):
        flip_two_point(np.array([1.0, -1.0, 1.0]), np.array([-1.0, 1.0, -1.0]))


def test_degenerate_designs_are_refused() -> None:
    with pytest.raises(CalibrationError, match=r"faces \['-Z'\] were not measured"):
        six_position(FACES[:5], np.zeros((5, 3)), np.ones((5, 3)))
    with pytest.raises(CalibrationError, match="were not measured"):
        six_position(["+Z"] * 6, np.zeros((6, 3)), np.ones((6, 3)))
    from imubench.calibration.sensor import fit_sensor

    with pytest.raises(CalibrationError, match=r"axis x: the positions or rates do not"
                                               r" determine every parameter \(rank 2 < 4\)"):
        fit_sensor(np.tile([0.0, 0.0, 1.0], (6, 1)) * [[1], [-1], [1], [-1], [1], [-1]],
                   np.zeros((6, 3)), np.ones((6, 3)), quadratic=False, what="t")
    rates = np.zeros((4, 3))
    rates[:, 0] = [0.0, 100.0, -100.0, 0.0]
    with pytest.raises(CalibrationError, match="4 observations cannot determine 5 parameters"):
        rate_table(rates, np.zeros((4, 3)), np.ones((4, 3)))


def test_temperature_fits() -> None:
    a, beta, c0 = 0.01, 1e-4, 0.3
    temps = np.array([25.0, 45.0, 65.0, 85.0, 0.0, -20.0, -40.0])
    d = temps - 25.0
    y = np.stack([c0 + a * d + beta * d**2] * 3, axis=1)
    note = three_point_note(temps, y, 25.0, 85.0, -40.0)
    # the literal sequential procedure: c1 = a + beta dT_hot, c2 = beta (dTc - dTh) / dTc
    assert note.coeff1[0] == pytest.approx(a + beta * 60.0)
    assert note.coeff2[0] == pytest.approx(beta * (-65.0 - 60.0) / -65.0)
    # ...and misses the hot point by beta dTh^2 (dTh - dTc) / dTc: 1.92 x the quadratic
    r_hot = note.residuals(temps, y)[3, 0]
    assert r_hot == pytest.approx(beta * 60.0**2 * (60.0 + 65.0) / -65.0)
    assert r_hot / (beta * 60.0**2) == pytest.approx(-1.923, abs=1e-3)
    exact = three_point_exact(temps, y, 25.0, 85.0, -40.0)
    assert exact.coeff1[0] == pytest.approx(a) and exact.coeff2[0] == pytest.approx(beta)
    assert np.allclose(exact.residuals(temps, y), 0.0, atol=1e-12)
    # weighted least squares against numpy.polyfit (weights 1/sigma)
    rng = np.random.default_rng(5)
    noisy = y + rng.normal(0, 0.002, y.shape)
    sigma = np.full(y.shape, 0.002)
    poly = polynomial(temps, noisy, sigma, 25.0)
    ref = np.polyfit(d, noisy[:, 1], 2, w=1.0 / sigma[:, 1])
    assert poly.coeff2[1] == pytest.approx(ref[0]) and poly.coeff1[1] == pytest.approx(ref[1])
    assert poly.offset[1] == pytest.approx(ref[2])
    _, cov = np.polyfit(d, noisy[:, 1], 2, w=1.0 / sigma[:, 1], cov="unscaled")
    assert poly.stderr1 is not None and poly.stderr2 is not None
    scale = math.sqrt(max(1.0, poly.chi2 / poly.dof))  # Birge ratio: at least 1 here
    assert poly.stderr1[1] >= math.sqrt(cov[1, 1]) * 0.999
    assert poly.stderr1[1] <= math.sqrt(cov[1, 1]) * scale * 3.0


def _sensor(unit: str, **kw: object) -> SensorCalibration:
    args: dict[str, object] = {"unit": unit, "method": "test", "temp_ref_c": 25.0,
                               "offset": np.array([0.01, 0.02, -0.03]),
                               "matrix": np.diag([1.01, 0.99, 1.02])}
    args.update(kw)
    return SensorCalibration(**args)  # type: ignore[arg-type]


def test_calibration_file_round_trip_and_application(tmp_path: Path) -> None:
    cal = Calibration(PROV, gyro=_sensor("dps", temp_coeff1=np.array([0.01, 0.0, 0.0])),
                      accel=_sensor("g", nonlinearity=np.array([0.004, 0.0, 0.0]),
                                    residuals={"six_position_mg": [[0.1, 0.2, 0.3]]}))
    saved = cal.save(tmp_path / "cal.toml")
    back = Calibration.load(saved.path)
    assert back.sha256 == saved.sha256 and back.provenance == PROV
    assert back.accel is not None and back.gyro is not None
    assert np.allclose(back.accel.nonlinearity, [0.004, 0, 0])
    assert back.accel.residuals["six_position_mg"] == [[0.1, 0.2, 0.3]]
    again = Calibration.from_description(back.describe())
    assert again.describe()["accel"] == back.describe()["accel"]
    n = 5
    raw = np.tile(np.array([100, -200, 300, 1000, 2000, 16000], np.int16), (n, 1))
    values = raw * np.array([8.75e-3] * 3 + [0.061e-3] * 3)
    batch = Batch(np.arange(n), np.arange(n) / 104.0, values, np.full(n, 35.0), raw)
    out = back.apply(batch)
    assert out.raw is batch.raw and np.array_equal(out.index, batch.index)
    # gyro x at 35 degC: (y - b - c1 dT) / M_xx
    assert out.values[0, 0] == pytest.approx((values[0, 0] - 0.01 - 0.01 * 10.0) / 1.01)
    # accel: M u + q u^2 + b = y, checked by putting u back
    u = out.values[0, 3:6]
    y = np.diag([1.01, 0.99, 1.02]) @ u + np.array([0.004, 0, 0]) * u**2 + [0.01, 0.02, -0.03]
    assert np.allclose(y, values[0, 3:6], atol=1e-12)
    no_temp = Batch(batch.index, batch.t_s, values, np.full(n, np.nan), raw)
    with pytest.raises(CalibrationError, match="temperature terms"):
        back.apply(no_temp)


def test_calibration_file_errors_name_file_and_key(tmp_path: Path) -> None:
    p = tmp_path / "c.toml"
    good = Calibration(PROV, accel=_sensor("g")).to_toml()
    p.write_text(good.replace('unit = "g"', 'unit = "m/s2"'))
    with pytest.raises(CalibrationError, match=r"c\.toml: \[accel\] key 'unit' must be 'g'"):
        Calibration.load(p)
    p.write_text(good.replace("offset = ", "ofset = "))
    with pytest.raises(CalibrationError, match=r"c\.toml: \[accel\]: unknown keys \['ofset'\]"):
        Calibration.load(p)
    p.write_text(good.replace('serial = "SN1"\n', ""))
    with pytest.raises(CalibrationError, match=r"lacks \['serial'\]"):
        Calibration.load(p)
    with pytest.raises(CalibrationError, match="an axis does not respond"):
        Calibration(PROV, gyro=_sensor("dps", matrix=np.diag([1.0, 0.0, 1.0])))


def test_capture_mean_interval_covers_on_white_noise() -> None:
    rng = np.random.default_rng(11)
    hits = 0
    trials = 400
    for _ in range(trials):
        y = 0.3 + 0.04 * rng.standard_normal(208)
        lo, hi = capture_mean(y, 104.0, 8.75e-3, "t").ci(0.95)
        hits += lo <= 0.3 <= hi
    # binomial(400, 0.95): 3 sd = 13 trials
    assert abs(hits / trials - 0.95) < 0.035
    # a constant output: the LSB floor, never a zero interval
    m = capture_mean(np.full(300, 0.5), 104.0, 0.01, "stuck")
    assert m.stderr == pytest.approx(0.01 / math.sqrt(12.0))
    with pytest.raises(CalibrationError, match="at least 16"):
        capture_mean(np.full(10, 1.0), 104.0, 0.01, "few")


def test_a_calibration_is_refused_on_another_chip_or_range_and_warns_outside_its_sweep(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """An LSM6DSL 2 g / 250 dps calibration was applied silently to an LSM6DSM and to a
    16 g / 2000 dps recording; one swept over 20-30 degC made the values at -40 degC
    worse than raw, without a word."""
    from imubench.cli import main
    from imubench.recording import convert

    cal = Calibration({**PROV, "chip": "lsm6dsl"},
                      gyro=_sensor("dps", full_scale=250.0, temp_range_c=(20.0, 30.0),
                                   temp_coeff1=np.array([0.01, 0.0, 0.0])),
                      accel=_sensor("g", full_scale=2.0))
    path = cal.save(tmp_path / "cal.toml").path
    assert path is not None
    back = Calibration.load(path)
    assert back.gyro is not None and back.gyro.temp_range_c == (20.0, 30.0)
    assert back.gyro.full_scale == 250.0
    for name, args in (("dsm", ["--chip", "lsm6dsm"]),
                       ("fs", ["--chip", "lsm6dsl", "--fs-dps", "2000"]),
                       ("cold", ["--chip", "lsm6dsl", "--temperature", "-40"])):
        rec = tmp_path / f"{name}.imbr"
        assert main(["sim", *args, "--duration-s", "2", "--out", str(rec)]) == 0
        out = tmp_path / f"{name}_cal.csv"
        if name == "cold":
            with caplog.at_level("WARNING"):
                convert(rec, out, calibration=path)
            assert "outside the 20.0 to 30.0 degC the [gyro] temperature terms" in caplog.text
        else:
            with pytest.raises(CalibrationError, match=r"lsm6dsm|full scale 250 dps"):
                convert(rec, out, calibration=path)
            assert not out.exists()
    assert main(["acquire", "sim://lsm6dsm?odr_hz=104", "--duration-s", "1", "--out",
                 str(tmp_path / "a.imbr"), "--calibration", str(path)]) == 2


def test_a_live_acquisition_says_when_its_die_temperature_leaves_the_sweep(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``acquire`` and ``run`` were checked against a calibration's chip and range at the
    start only: a board that warmed 30 degC past its sweep got extrapolated values
    without a word."""
    import json

    from imubench.cli import main

    cal = Calibration({**PROV, "chip": "lsm6dsl"},
                      gyro=_sensor("dps", temp_range_c=(20.0, 30.0),
                                   temp_coeff1=np.array([0.01, 0.0, 0.0])))
    path = cal.save(tmp_path / "cal.toml").path
    assert path is not None
    stats = tmp_path / "stats.json"
    uri = ("sim://lsm6dsl?odr_hz=104&watermark_s=0.1"
           "&temperature=steps%3A0%3D25%2C1%3D60%2C2%3D25")
    assert main(["acquire", uri, "--duration-s", "3", "--out", str(tmp_path / "a.imbr"),
                 "--calibration", str(path), "--stats-json", str(stats)]) == 0
    err = capsys.readouterr().err
    assert "outside the 20.0 to 30.0 degC the [gyro] temperature terms" in err
    assert "back within the [gyro] calibration's 20.0 to 30.0 degC" in err
    from imubench.recording import load_recording

    rec = load_recording(tmp_path / "a.imbr")
    hot = int(np.sum(rec.temp_c > 35.0))
    assert 0.8 * 104 < hot < 1.2 * 104
    doc = json.loads(stats.read_text())
    assert doc["calibration_extrapolated"] == hot
    # the range reached outside, not the first batch's (89.9 to 91.1 on a ramp to 110)
    lo, hi = doc["calibration_extrapolated_range_c"]["gyro"]
    assert lo == pytest.approx(rec.temp_c[rec.temp_c > 35.0].min(), abs=1e-6)
    assert hi == pytest.approx(rec.temp_c.max(), abs=1e-6)
    assert f"outside it, it reached {lo:.1f} to {hi:.1f} degC" in err


def test_the_temperature_polynomial_separates_a_drift_in_time_from_the_temperature() -> None:
    """A sweep that climbs and falls (25 ... 85, 0 ... -40, 25 degC) over 80 min aliased
    the bias's drift into the linear term; with the points' times a drift term takes it,
    and its error, estimated from the residuals, carries their degrees of freedom."""
    temps = np.array([25.0, 45.0, 65.0, 85.0, 0.0, -20.0, -40.0, 25.0])
    times = np.arange(8) * 600.0
    a, drift_per_h = 0.01, 0.02  # dps/degC, dps/h
    rng = np.random.default_rng(3)
    noise = rng.normal(0.0, 1e-4, (8, 3))
    y = (a * (temps - 25.0) + drift_per_h * (times - times.mean()) / 3600.0)[:, None] + noise
    sigma = np.full((8, 3), 1e-4)
    plain = polynomial(temps, y, sigma, 25.0)
    assert plain.stderr_dof is not None and plain.drift_per_h is None
    assert plain.stderr_dof[0] == 5.0  # the drift left in the residuals: Birge-scaled
    with_drift = polynomial(temps, y, sigma, 25.0, times_s=times)
    assert with_drift.drift_per_h is not None and with_drift.stderr1 is not None
    assert with_drift.drift_per_h[0] == pytest.approx(drift_per_h, rel=0.05)
    assert abs(with_drift.coeff1[0] - a) < 3 * with_drift.stderr1[0]
    assert abs(with_drift.coeff1[0] - a) < abs(plain.coeff1[0] - a) / 5.0
    # against numpy's least squares on the same design
    X = np.stack([np.ones(8), temps - 25.0, (temps - 25.0) ** 2,
                  times / 3600.0 - times.mean() / 3600.0], axis=1)
    ref, *_ = np.linalg.lstsq(X, y[:, 1], rcond=None)
    assert with_drift.coeff1[1] == pytest.approx(ref[1], rel=1e-9)
    # errors scaled by the Birge ratio carry the residuals' dof (8 points - 4 parameters)
    loose = polynomial(temps, y, sigma / 10.0, 25.0, times_s=times)
    assert loose.stderr_dof is not None and np.all(loose.stderr_dof == 4.0)
    tight = polynomial(temps, y, sigma * 10.0, 25.0, times_s=times)
    assert tight.stderr_dof is not None and np.all(np.isinf(tight.stderr_dof))


def test_a_jig_interval_from_an_estimated_error_takes_students_t() -> None:
    from scipy.stats import t as student_t

    from imubench.jig.analysis import interval_from_stderr

    normal = interval_from_stderr(1.0, 0.1, 0.95, "m")
    assert normal.ci[1] - 1.0 == pytest.approx(0.1 * 1.959964, rel=1e-6)
    four = interval_from_stderr(1.0, 0.1, 0.95, "m", dof=4.0)
    assert four.ci[1] - 1.0 == pytest.approx(0.1 * float(student_t.ppf(0.975, 4)), rel=1e-12)
    assert four.ci[1] - 1.0 == pytest.approx(0.2776, abs=1e-4)  # t(4) table value 2.776


def test_the_daemons_live_deviations_are_those_of_the_calibrated_values(
        tmp_path: Path) -> None:
    """``imubench run`` with ``calibration.file`` recorded calibrated values but fed the
    live engine (MQTT) the raw counts: its deviations were the uncalibrated sensor's,
    1.02x the recording's for a gyro gain of 1.02 (an outside reviewer)."""
    import subprocess
    import sys

    from imubench import stats
    from imubench.config import quickstart_file
    from imubench.recording import load_recording
    from imubench.stats.streaming import StreamingAllan
    from tests.mqtt_fixtures import free_port

    cal = Calibration({**PROV, "chip": "lsm6dsl"},
                      gyro=_sensor("dps", matrix=np.diag([1.02, 0.97, 1.0])))
    path = cal.save(tmp_path / "cal.toml").path
    text = (quickstart_file().read_text()
            .replace('memory = "bounded"',
                     f'memory = "exact"\nstate_path = "{tmp_path}/state.npz"')
            .replace("clock=wall", "clock=virtual").replace("port = 1883",
                                                            f"port = {free_port()}")
            .replace('path = "recordings/', f'path = "{tmp_path}/recordings/')
            .replace('live_table = "auto"', 'live_table = "off"'))
    cfg = tmp_path / "c.toml"
    cfg.write_text(text + f'\n[calibration]\nfile = "{path}"\n[run]\nduration_s = 20.0\n')
    proc = subprocess.run([sys.executable, "-m", "imubench.cli", "run", "--config", str(cfg)],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rec = load_recording(next((tmp_path / "recordings").glob("*.imbr")))
    eng = StreamingAllan.load_state((tmp_path / "state.npz").read_bytes())
    live = eng.snapshot()
    assert isinstance(live, list)
    for k, ch in enumerate(("gx", "gy")):
        ref = stats.oadev(rec.channel(ch), rec.rate_hz, data_type="freq", taus="octave")
        got = live[k]["oadev"]
        n = min(len(ref.dev), len(got.dev))
        assert n >= 5
        assert np.allclose(got.dev[:n], ref.dev[:n], rtol=1e-9)


def test_a_calibration_refuses_data_that_lack_one_of_its_sensors_axes(tmp_path: Path) -> None:
    """``convert --calibration`` of a one-channel file wrote every value empty (the
    correction mixes the three axes: one NaN made all three NaN) and exited 0."""
    from imubench.cli import main
    from imubench.recording import convert

    cal = Calibration({**PROV, "chip": "lsm6dsl"}, gyro=_sensor("dps"))
    path = cal.save(tmp_path / "cal.toml").path
    assert path is not None
    rec = tmp_path / "r.imbr"
    assert main(["sim", "--chip", "lsm6dsl", "--duration-s", "2", "--out", str(rec)]) == 0
    convert(rec, tmp_path / "gx.dat", channel="gx")
    with pytest.raises(CalibrationError, match=r"\[gyro\] corrects gx, gy, gz together .* "
                                               r"lack gy, gz"):
        convert(tmp_path / "gx.dat", tmp_path / "cal.csv", calibration=path)
    assert not (tmp_path / "cal.csv").exists()


def test_capture_mean_with_a_hole_in_the_middle_has_a_finite_standard_error() -> None:
    """Samples lost in the middle of a capture removed every OADEV term at m = N/4 (the
    standard error came out NaN and every fit using the capture failed): the longest
    averaging factor that still has terms is used. White noise: the standard error
    stays near sigma / sqrt(n) (checked over seeds against the independent formula)."""
    ratios = []
    for seed in range(20):
        y = np.random.default_rng(seed).normal(0.5, 0.01, 6240)
        y[3000:3200] = np.nan
        m = capture_mean(y, 104.0, 8.75e-3, "static +Z")
        assert m.n == 6040 and np.isfinite(m.stderr) and np.isfinite(m.edf)
        ratios.append(m.stderr / (0.01 / np.sqrt(m.n)))
    assert 0.8 < float(np.median(ratios)) < 1.25, ratios


def test_run_check_refuses_a_calibration_for_another_chip_or_range(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``run --check`` said "configuration is valid" for a calibration of another chip
    or full scale, which ``run`` then refused at its start."""
    from imubench.cli import main

    cal = Calibration({**PROV, "chip": "lsm6dsl"}, gyro=_sensor("dps", full_scale=250.0))
    path = cal.save(tmp_path / "cal.toml").path
    assert path is not None
    for uri, words in (("sim://lsm6dsm?odr_hz=104", "lsm6dsm"),
                       ("sim://lsm6dsl?odr_hz=104&fs_dps=500", "500 dps"),
                       ("sim://lsm6dsl?odr_hz=104", None)):
        cfg = tmp_path / "run.toml"
        cfg.write_text(f'[source]\nuri = "{uri}"\n[calibration]\nfile = "{path}"\n')
        code = main(["run", "--config", str(cfg), "--check"])
        out = capsys.readouterr()
        if words is None:
            assert code == 0 and "configuration is valid" in out.out
        else:
            assert code == 2 and words in out.err, out.err
