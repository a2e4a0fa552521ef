"""Simulator features reached through ``sim://`` URI parameters and read back through the
real driver and FIFO: the temperature profile acting on the bias, stuck output and
temperature glitches (issue 5: "Sensor physics" and "Fault injection")."""

from __future__ import annotations

from pathlib import Path
from urllib.parse import quote

import numpy as np
import pytest

from imubench.batch import Batch
from imubench.errors import SourceError
from imubench.sources.registry import open_source


def read_all(uri: str) -> tuple[object, list[Batch]]:
    src = open_source(uri)
    with src:
        batches = list(src)
    return src, batches


def test_temperature_profile_drives_bias_through_the_register_path(tmp_path: Path) -> None:
    """``temperature=ramp:15:0.02`` with gx temp_coeff 0.01 dps/degC: the temperature the
    driver reads follows the ramp, and the gyro bias it reads follows
    temp_coeff (T - temp_ref) (least-squares slope and intercept, numpy.polyfit)."""
    model = tmp_path / "temp.toml"
    model.write_text("[channels.gx]\ntemp_coeff = 0.01\ntemp_ref = 25.0\n")
    profile = quote("ramp:15:0.02")
    _, batches = read_all(
        f"sim://lsm6dsl?odr_hz=104&fs_dps=125&duration_s=1000&model={model}"
        f"&temperature={profile}&watermark_s=1"
    )
    t = np.array([b.t_s[-1] for b in batches])
    temp = np.array([b.temp_c[-1] for b in batches])
    gx_mean = np.array([b.values[:, 0].mean() for b in batches])
    assert temp[0] == pytest.approx(15.0, abs=0.1) and temp[-1] == pytest.approx(35.0, abs=0.1)
    # the temperature read at each poll is the profile at the newest sample (1/256 degC LSB)
    slope_t, _ = np.polyfit(t, temp, 1)
    assert slope_t == pytest.approx(0.02, rel=1e-3)
    # bias vs temperature: 0.01 dps/degC, zero at 25 degC (gyro LSB 4.375 mdps)
    slope, intercept = np.polyfit(temp, gx_mean, 1)
    assert slope == pytest.approx(0.01, rel=0.02)
    assert intercept + 25.0 * slope == pytest.approx(0.0, abs=4.375e-3)


def test_bad_temperature_profile_names_the_parameter() -> None:
    with pytest.raises(SourceError, match=r"temperature='ramp:x'.*malformed"):
        open_source("sim://lsm6dsl?temperature=ramp:x")


def test_stuck_output_repeats_the_last_sample_for_its_duration() -> None:
    """From 5 s for 2 s every output (six axes) repeats the sample before 5 s; the driver
    still delivers every index (the timestamps keep running), so the fault shows as a
    run of identical sample sets about 2 s x 104 Hz long, and nowhere else."""
    src, batches = read_all(
        "sim://lsm6dsl?odr_hz=104&model=datasheet:lsm6dsl&duration_s=12"
        "&stuck_output_at_s=5&stuck_output_for_s=2&watermark_s=0.25&seed=2"
    )
    raw = np.concatenate([b.raw for b in batches]).astype(np.int64)
    index = np.concatenate([b.index for b in batches])
    assert np.array_equal(index, np.arange(104 * 12))
    same = np.all(raw[1:] == raw[:-1], axis=1)
    runs = np.flatnonzero(same)
    assert 2 * 104 - 2 <= len(runs) <= 2 * 104 + 2
    assert np.all(np.diff(runs) == 1)  # one contiguous run
    t_run = np.concatenate([b.t_s for b in batches])[runs[[0, -1]]]
    assert t_run[0] == pytest.approx(5.0, abs=0.15) and t_run[1] == pytest.approx(7.0, abs=0.15)
    assert src.sim.bus.faults.injected["stuck_outputs"] == 1  # type: ignore[attr-defined]


def test_temperature_glitches_are_spikes_on_the_temperature_output() -> None:
    """Glitches of +-10 degC lasting 1 s at 0.02 per second on a constant 25 degC: the
    temperature the driver reads is 25 degC except during glitches, where it is 25 +- 10
    (or a sum of overlapping glitches); the accelerometer and gyro are untouched."""
    src, batches = read_all(
        "sim://lsm6dsl?odr_hz=104&duration_s=400&temp_glitch_rate=0.02&temp_glitch_c=10"
        "&temp_glitch_s=1&watermark_s=0.1&seed=4"
    )
    temp = np.array([b.temp_c[-1] for b in batches])
    excess = temp - 25.0
    assert np.allclose(excess / 10.0, np.round(excess / 10.0), atol=1e-3)
    spikes = np.abs(excess) > 5
    injected = src.sim.bus.faults.injected["temp_glitches"]  # type: ignore[attr-defined]
    assert injected >= 3
    polls_per_s = len(batches) / 400.0  # one temperature read per poll
    assert 0.7 * injected * polls_per_s <= spikes.sum() <= 1.1 * injected * polls_per_s
    accel_z = np.concatenate([b.values[:, 5] for b in batches])
    assert np.ptp(accel_z) == 0.0  # the quiet sensor's other outputs never move


def test_cli_sim_temperature_reaches_the_physics(tmp_path: Path) -> None:
    """``imubench sim --temperature 45 --model M``: a constant 45 degC with gx
    temp_coeff 0.01 dps/degC reads 0.2 dps of bias and 45 degC in the recording."""
    from imubench.cli import main
    from imubench.recording import load_recording

    model = tmp_path / "temp.toml"
    model.write_text("[channels.gx]\ntemp_coeff = 0.01\n")
    out = tmp_path / "t.imbr"
    args = ["sim", "--chip", "lsm6dsm", "--duration-s", "5", "--fs-dps", "125"]
    assert main([*args, "--model", str(model), "--temperature", "45", "--out", str(out)]) == 0
    rec = load_recording(out)
    assert np.allclose(rec.temp_c, 45.0, atol=1 / 256)
    assert np.allclose(rec.values[:, 0], 0.2, atol=4.375e-3 / 2)
