"""CLI: imubench fit -> model file -> load_model/simulate; imubench model; bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from lsm6ds_sim import noise
from lsm6ds_sim.model import NoiseModel, load_model
from lsm6ds_sim.physics import simulate

from imubench.batch import Batch
from imubench.cli import main
from imubench.recording import open_writer

RATE = 104.0


def write_recording(path: Path, model: NoiseModel, n: int, seed: int = 1) -> Path:
    """A native recording of simulate() output (all six channels)."""
    sim = simulate(model, n, RATE, seed)
    values = np.column_stack([sim[c] for c in ("gx", "gy", "gz", "ax", "ay", "az")])
    idx = np.arange(n, dtype=np.int64)
    meta = {"chip": "lsm6dsl", "odr_hz": RATE, "gyro_sensitivity_dps": 8.75e-3,
            "accel_sensitivity_g": 0.061e-3}
    with open_writer(path, meta) as w:
        w.write(Batch(idx, idx / RATE, values, np.full(n, 25.0)))
    return path


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    model = NoiseModel.quiet().with_all(white=0.004).with_channel("ax", white=8e-5) \
        .with_channel("ay", white=8e-5).with_channel("az", white=8e-5, random_walk=1e-5)
    return write_recording(tmp_path_factory.mktemp("rec") / "r.imbr", model, 40_000)


def test_fit_cli_writes_a_model_the_simulator_loads(recording: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "m.toml"
    js = tmp_path / "f.json"
    kal = tmp_path / "imu.yaml"
    rc = main(["fit", str(recording), "--channels", "gx,az", "-o", str(out), "--json",
               str(js), "--kalibr", str(kal)])
    assert rc == 0, capsys.readouterr().err
    model = load_model(out)
    assert model["gx"].white == pytest.approx(0.004, rel=0.03)
    assert model["az"].white == pytest.approx(8e-5, rel=0.03)
    assert model["gy"].white == 0.0  # not fitted: quiet
    sim = simulate(model, 1000, RATE, 3, channels=["gx"])
    assert np.std(sim["gx"]) == pytest.approx(0.004 * np.sqrt(RATE), rel=0.1)
    doc = json.loads(js.read_text())
    assert set(doc["channels"]) == {"gx", "az"}
    assert doc["channels"]["gx"]["datasheet_units"]["noise_density_mdps_per_sqrt_hz"] == \
        pytest.approx(4.0, rel=0.03)
    assert doc["datasheet_comparison"]["gx"]["ratio"] == pytest.approx(1.0, rel=0.03)
    assert doc["kalibr"]["update_rate"] == RATE
    assert "gyroscope_noise_density" in kal.read_text()


def test_kalibr_never_writes_a_zero_random_walk(recording: Path, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """gx is white noise only (its random walk is below detection): the file holds the
    upper 95 % confidence limit of the fit, marked as such on its line and in the header,
    and the terminal says so; --kalibr-inflate multiplies every value. The noise density
    is checked against an independent figure: white noise of std sigma at rate f has the
    density sigma / sqrt(f) (dps/sqrt(Hz)), in rad/s/sqrt(Hz) times pi/180."""
    kal, js = tmp_path / "imu.yaml", tmp_path / "f.json"
    rc = main(["fit", str(recording), "--channels", "gx,ax", "-o", str(tmp_path / "m.toml"),
               "--kalibr", str(kal), "--json", str(js)])
    err = capsys.readouterr().err
    assert rc == 0, err
    doc = json.loads(js.read_text())
    gx = doc["channels"]["gx"]
    assert "random_walk" not in gx["present"]
    upper = gx["ci95"]["random_walk"][1]
    assert upper > 0
    text = kal.read_text()
    line = next(ln for ln in text.splitlines() if ln.startswith("gyroscope_random_walk:"))
    value = float(line.split()[1])
    assert value == pytest.approx(upper * np.pi / 180, rel=1e-6) and value > 0
    assert "upper 95 % limit: not detected" in line
    assert "below detection, written as the upper 95 % confidence limit" in text
    assert ("gyroscope_random_walk (random_walk) was not detected on gx; wrote the largest "
            "value over the axes, the upper 95 % confidence limit of gx: ") in err
    assert "rad/s^2/sqrt(Hz) (marked in the file)" in err
    assert text.endswith("\n")
    from imubench.recording import load_recording

    data = load_recording(recording).channel("gx")
    density = float(np.std(data)) / np.sqrt(RATE) * np.pi / 180
    nd = float(next(ln for ln in text.splitlines()
                    if ln.startswith("gyroscope_noise_density:")).split()[1])
    assert nd == pytest.approx(density, rel=0.03)
    rc = main(["fit", str(recording), "--channels", "gx,ax", "-o", str(tmp_path / "m2.toml"),
               "--kalibr", str(tmp_path / "x2.yaml"), "--kalibr-inflate", "10"])
    assert rc == 0
    inflated = (tmp_path / "x2.yaml").read_text()
    assert "multiplied by 10 (--kalibr-inflate)" in inflated
    assert float(next(ln for ln in inflated.splitlines()
                      if ln.startswith("gyroscope_noise_density:")).split()[1]) == \
        pytest.approx(10 * nd, rel=1e-6)
    assert "gx: white=" in capsys.readouterr().out


def test_fit_cli_tangent_method(recording: Path, tmp_path: Path) -> None:
    out = tmp_path / "t.toml"
    assert main(["fit", str(recording), "--channels", "gy", "--method", "tangent",
                 "-o", str(out)]) == 0
    assert load_model(out)["gy"].white == pytest.approx(0.004, rel=0.05)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--channels", "gq"], "unknown channel"),
        (["--terms", "white,pink"], "unknown term"),
    ],
)
def test_fit_cli_bad_input(recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                           args: list[str], message: str) -> None:
    rc = main(["fit", str(recording), *args, "-o", str(tmp_path / "x.toml")])
    assert rc == 2
    assert message in capsys.readouterr().err


def test_fit_cli_missing_recording(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fit", str(tmp_path / "none.imbr"), "-o", str(tmp_path / "x.toml")]) == 2
    assert "none.imbr" in capsys.readouterr().err


def test_model_cli_matches_the_closed_forms(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "m.toml"
    path.write_text("[channels.gx]\nwhite = 0.004\nrandom_walk = 1e-4\n"
                    "[channels.az]\nquantization = 1e-4\n")
    assert main(["model", str(path), "--rate", "100", "--taus", "0.01,0.1,1,10,100",
                 "--json", "-"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc["channels"]) == {"gx", "az"}
    gx = doc["channels"]["gx"]
    tau = np.array(gx["tau_s"])
    expect = np.sqrt(noise.avar_white(tau, 0.004) + noise.avar_random_walk(tau, 1e-4))
    np.testing.assert_allclose(gx["dev"], expect, rtol=1e-9)
    az = doc["channels"]["az"]
    np.testing.assert_allclose(az["dev"], np.sqrt(noise.avar_quantization(tau, 1e-4)),
                               rtol=1e-9)


def test_model_cli_against_a_long_simulation(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    """Prediction with a filter and flicker vs allantools OADEV of a simulated record."""
    import allantools

    path = tmp_path / "m.toml"
    path.write_text("[channels.gx]\nwhite = 0.004\nflicker = 0.002\nbandwidth_hz = 15.0\n"
                    "filter_order = 2\n")
    n = 300_000
    assert main(["model", str(path), "--rate", "100", "--taus", "octave", "--n", str(n),
                 "--json", "-"]) == 0
    gx = json.loads(capsys.readouterr().out)["channels"]["gx"]
    tau = np.array(gx["tau_s"])
    y = simulate(load_model(path), n, 100.0, 9, channels=["gx"])["gx"]
    _, dev, _, _ = allantools.oadev(y, rate=100.0, data_type="freq", taus=tau)
    inside = (np.array(gx["ci_low"]) <= dev) & (dev <= np.array(gx["ci_high"]))
    assert inside.mean() >= 0.6  # 68 % intervals
    np.testing.assert_allclose(dev[:6], np.array(gx["dev"])[:6], rtol=0.02)


def test_model_cli_bad_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "m.toml"
    path.write_text("[channels.gx]\nwhite = 0.004\n")
    assert main(["model", str(path), "--rate", "100", "--taus", "octave"]) == 2
    assert "--n" in capsys.readouterr().err
    assert main(["model", str(path), "--rate", "0", "--taus", "1,2"]) == 2
    assert "--rate" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text("[channels.gx]\nwhite = -1\n")
    assert main(["model", str(bad), "--rate", "100", "--taus", "1"]) == 2
    assert "bad.toml" in capsys.readouterr().err
    # a tau is never moved, dropped or guessed without a word; a huge one is refused
    # before it allocates (1e9 s at 100 Hz asked for 1.5 TiB)
    for taus, words in (("0.015,0.01", "1.5 samples"), ("0,1", "not a positive time"),
                        ("1e9", "the largest computed"), ("1", "write 1.0 for one second")):
        assert main(["model", str(path), "--rate", "100", f"--taus={taus}"]) == 2
        assert words in capsys.readouterr().err
    assert main(["model", str(path), "--rate", "100", "--taus", "0.5", "--n", "100"]) == 2
    assert "beyond N/4" in capsys.readouterr().err
    quiet = tmp_path / "quiet.toml"
    quiet.write_text("[channels.gx]\nwhite = 0.0\n")
    assert main(["model", str(quiet), "--rate", "100", "--taus", "0.01"]) == 2
    assert "gives no channel any noise" in capsys.readouterr().err


def test_fit_shows_a_progress_bar_that_reaches_its_end(recording: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    """``--progress on``: the bar on stderr, one step per channel, drawn at 100 % when it
    closes; stdout keeps the JSON alone."""
    rc = main(["fit", str(recording), "--channels", "gx,gy", "--terms", "white",
               "-o", str(tmp_path / "m.toml"), "--json", "-", "--progress", "on"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert set(json.loads(captured.out)["channels"]) == {"gx", "gy"}
    assert "fit:" in captured.err and "100%" in captured.err


def test_kalibr_refused_when_nothing_states_the_units(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    """A one-column text file states no unit: it is read as dps with a warning, and the
    Kalibr export (SI values) is refused until --units says what the numbers are."""
    rec = tmp_path / "one.txt"
    np.savetxt(rec, np.random.default_rng(1).normal(size=20000) * 0.01)
    yaml = tmp_path / "imu.yaml"
    assert main(["fit", str(rec), "--rate", "100", "-o", str(tmp_path / "m.toml"),
                 "--kalibr", str(yaml)]) == 2
    err = capsys.readouterr().err
    assert "nothing states the unit of gx" in err and "--units" in err
    assert not yaml.exists() and not (tmp_path / "m.toml").exists()


def test_fit_prints_and_writes_the_reasons(recording: Path, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    js = tmp_path / "fit.json"
    assert main(["fit", str(recording), "--channels", "gx", "-o", str(tmp_path / "m.toml"),
                 "--json", str(js)]) == 0
    out = capsys.readouterr().out
    assert "kept: white" in out and "dropped: " in out and "sine (" in out
    gx = json.loads(js.read_text())["channels"]["gx"]
    assert gx["reasons"]["white"].startswith("kept")
    assert gx["reasons"]["sine"].startswith("dropped")
    assert set(gx["chi2_drop"]) >= {"white", "flicker", "sine"}


def test_kalibr_refuses_a_gyro_only_fit(recording: Path, tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    """Kalibr cannot load an imu.yaml without the accelerometer keys: one-line error
    naming them, exit 2, and no file written."""
    kal = tmp_path / "imu.yaml"
    rc = main(["fit", str(recording), "--channels", "gx", "-o", str(tmp_path / "m.toml"),
               "--kalibr", str(kal)])
    err = capsys.readouterr().err
    assert rc == 2
    assert len(err.strip().splitlines()) == 1, err
    assert "accelerometer_noise_density, accelerometer_random_walk" in err
    assert "no accelerometer (ax ay az) axis was fitted" in err
    assert not kal.exists() and not (tmp_path / "m.toml").exists()


def test_kalibr_requests_are_refused_before_the_recording_is_read(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A bad --kalibr-inflate or a --channels list without accelerometer axes is refused
    at once (it used to come after fitting every channel, a minute on an hour of data):
    the recording named here does not even exist."""
    missing = tmp_path / "never-read.csv"
    for extra, words in ((["--kalibr-inflate", "0.5"], "--kalibr-inflate 0.5: must be"),
                         (["--channels", "gx,gy"], "no accelerometer (ax ay az) axis")):
        rc = main(["fit", str(missing), "-o", str(tmp_path / "m.toml"),
                   "--kalibr", str(tmp_path / "imu.yaml"), *extra])
        err = capsys.readouterr().err
        assert rc == 2 and words in err and "never-read" not in err, err


def test_noise_density_is_white_before_and_after_the_filter(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Simulated white 0.004 through a 20 Hz output filter plus white 0.003 after it: the
    datasheet density is their quadrature sum, 5 mdps/sqrt(Hz), and the terminal names it
    beside the two parts the fit reports."""
    model = NoiseModel.quiet().with_channel("gx", white=0.004, bandwidth_hz=20.0,
                                            output_white=0.003)
    rec = write_recording(tmp_path / "f.imbr", model, 200_000)
    js = tmp_path / "f.json"
    assert main(["fit", str(rec), "--channels", "gx", "-o", str(tmp_path / "m.toml"),
                 "--json", str(js)]) == 0
    out = capsys.readouterr().out
    gx = json.loads(js.read_text())["channels"]["gx"]
    assert gx["datasheet_units"]["noise_density_mdps_per_sqrt_hz"] == pytest.approx(
        5.0, rel=0.03)
    assert "output_white" in gx["present"] and "white-equivalent density N=" in out, out


def test_summary_prints_the_fit_notes() -> None:
    """A discrepancy floor (the model does not describe the curve within its estimates'
    scatter) was in the JSON only; a user reading the terminal missed it."""
    from dataclasses import replace

    from imubench.commands.fit import format_summary
    from imubench.noisefit import fit_channel
    from imubench.noisefit.recording_fit import RecordingFit

    y = 0.004 * 10.0 * np.random.default_rng(2).standard_normal(20000)
    f = fit_channel(y, 100.0, channel="gx")
    note = "model discrepancy floor delta = 0.235 (relative std added to every AVAR point)"
    rf = RecordingFit("r.csv", 100.0, None, f.method, {"gx": replace(f, notes=(note,))})
    assert f"    note: {note}" in format_summary(rf)


def test_fit_refuses_an_output_it_cannot_write_before_fitting(
        recording: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """-o, --json or --kalibr in a missing folder (or naming a folder) is an error before
    the fit, not after minutes of it."""
    from imubench.noisefit import recording_fit

    def no_fit(*args: object, **kwargs: object) -> None:
        raise AssertionError("the fit must not start")

    monkeypatch.setattr(recording_fit, "fit_channel", no_fit)
    for extra, words in ((["-o", str(tmp_path / "no" / "m.toml")], "-o "),
                         (["-o", str(tmp_path)], "is a folder"),
                         (["-o", str(tmp_path / "m.toml"), "--json",
                           str(tmp_path / "no" / "f.json")], "--json "),
                         (["-o", str(tmp_path / "m.toml"), "--kalibr",
                           str(tmp_path / "no" / "imu.yaml")], "--kalibr ")):
        assert main(["fit", str(recording), *extra]) == 2
        err = capsys.readouterr().err
        assert words in err and ("does not exist" in err or "is a folder" in err)
    assert not (tmp_path / "m.toml").exists()


def test_fit_says_how_much_of_the_recording_is_missing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A record with 10 % of it in two holes was fitted without a word about them."""
    rng = np.random.default_rng(4)
    n = 20_000
    keep = np.ones(n, dtype=bool)
    keep[5000:6900] = False
    keep[12000:12100] = False
    p = tmp_path / "holes.csv"
    p.write_text("t,gx\n" + "".join(f"{i / 100:.2f},{v:.5f}\n"
                                    for i, v in enumerate(rng.normal(0, 0.05, n)) if keep[i]))
    out = tmp_path / "fit.json"
    assert main(["fit", str(p), "--channels", "gx", "--json", str(out),
                 "-o", str(tmp_path / "m.toml")]) == 0
    head = capsys.readouterr().out.splitlines()[0]
    assert "18000 samples, 2 hole(s) (2000 samples, 10 % missing" in head
    doc = json.loads(out.read_text())
    assert (doc["samples"], doc["lost_samples"], doc["holes"]) == (18000, 2000, 2)


def test_datasheet_units_of_an_absent_term_are_null_with_the_upper_limit() -> None:
    """A dropped flicker was written as bias instability 0.0 deg/h, which reads as
    measured; it is null, with the fit's upper 95 % limit beside it."""
    from imubench.noisefit import fit_channel
    from imubench.noisefit.recording_fit import fit_datasheet_units

    rng = np.random.default_rng(6)
    f = fit_channel(rng.normal(0.0, 0.04, 60_000), 100.0, channel="gx")
    assert "flicker" not in f.present and "white" in f.present
    ds = fit_datasheet_units("gx", f)
    assert ds["bias_instability_deg_per_h"] is None and ds["rrw_deg_per_h_per_sqrt_h"] is None
    _, (_, hi) = f.coefficient("flicker")
    assert ds["bias_instability_deg_per_h_upper_95"] == pytest.approx(hi * 3600.0)
    assert ds["arw_deg_per_sqrt_h"] == pytest.approx(0.004 * 60, rel=0.03)


def test_a_constant_channel_is_left_out_and_the_others_fitted(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A dead axis (gz the same value in every sample) stopped the whole fit and the
    report; it is left out with its reason in the JSON and the report, and the other
    channels are fitted (white noise of 0.004 dps/sqrt(Hz) recovered). Named with
    --channels it is still an error."""
    rng = np.random.default_rng(3)
    n, rate = 20000, 100.0
    rows = ["t,gx [dps],gy [dps],gz [dps]"]
    gx, gy = rng.normal(0, 0.04, n), rng.normal(0, 0.04, n)
    rows += [f"{k / rate:.4f},{gx[k]:.6f},{gy[k]:.6f},0.25" for k in range(n)]
    path = tmp_path / "dead.csv"
    path.write_text("\n".join(rows) + "\n")
    assert main(["fit", str(path), "-o", str(tmp_path / "m.toml"), "--json",
                 str(tmp_path / "f.json")]) == 0
    doc = json.loads((tmp_path / "f.json").read_text())
    assert sorted(doc["channels"]) == ["gx", "gy"]
    assert "constant (0.25 dps" in doc["skipped_channels"]["gz"]
    white = doc["channels"]["gx"]["params"]["white"]
    assert white == pytest.approx(0.004, rel=0.05)
    assert main(["report", str(path), "--out", str(tmp_path / "r")]) == 0
    assert "gz left out: constant" in (tmp_path / "r" / "gyro.html").read_text()
    assert main(["fit", str(path), "--channels", "gz", "-o", str(tmp_path / "z.toml")]) == 2
    assert "constant" in capsys.readouterr().err
