"""imubench report: every file is written and the plots are real images."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from lsm6ds_sim.model import NoiseModel, load_model

from imubench.cli import main
from tests.test_fit_cli import write_recording


def test_report_writes_plots_fit_and_html(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    model = NoiseModel.quiet().with_all(white=0.004, flicker=0.001) \
        .with_channel("ax", white=8e-5, flicker=2e-5).with_channel("ay", white=8e-5) \
        .with_channel("az", white=8e-5)
    rec = write_recording(tmp_path / "r.imbr", model, 40_000)
    out = tmp_path / "rep"
    rc = main(["report", str(rec), "--out", str(out), "--terms", "white,flicker"])
    assert rc == 0, capsys.readouterr().err
    for name in ("sigma_tau_gyro", "sigma_tau_accel", "psd_gyro", "psd_accel"):
        png = (out / f"{name}.png").read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000
        assert "<svg" in (out / f"{name}.svg").read_text()[:2000]
    assert load_model(out / "model.toml")["gx"].white > 0
    doc = json.loads((out / "fit.json").read_text())
    assert set(doc["channels"]) == {"gx", "gy", "gz", "ax", "ay", "az"}
    page = (out / "index.html").read_text()
    assert "sigma_tau_gyro.png" in page and "Kalibr" in page
    assert "gyroscope_noise_density" in (out / "imu.yaml").read_text()


def test_report_bad_recording(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "r.txt"
    bad.write_text("x")
    assert main(["report", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "r.txt" in capsys.readouterr().err
