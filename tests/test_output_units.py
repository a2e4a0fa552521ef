"""Every number a person reads carries its unit (issue 13): the JSON of ``allan``,
``fit`` and ``gap`` name the unit of each of their numbers, the tables print them, and
imubench's CSV says what its columns are in."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from recording_damage import run_command

from imubench.noisefit.fit import PARAM_KEYS

GYRO_PARAM_UNITS = {"white": "dps/sqrt(Hz)", "flicker": "dps", "random_walk": "dps/sqrt(s)",
                    "ramp": "dps/s", "quantization": "dps*s", "markov_tau": "s"}


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """2 min of a simulated LSM6DSL at 104 Hz."""
    path = tmp_path_factory.mktemp("units") / "sim.imbr"
    subprocess.run([sys.executable, "-m", "imubench", "sim", "--chip", "lsm6dsl",
                    "--odr-hz", "104", "--duration-s", "120", "--model",
                    "datasheet:lsm6dsl", "--seed", "2", "--out", str(path)],
                   check=True, capture_output=True, timeout=300)
    return path


def _json(argv: list[str], out: Path) -> dict:
    status, _, err = run_command([*argv, "--json", str(out)])
    assert status == 0, err
    return json.loads(out.read_text())


def test_allan_json_and_table_carry_units(recording: Path, tmp_path: Path) -> None:
    for column, unit in (("gx", "dps"), ("az", "g")):
        doc = _json(["allan", str(recording), "--stat", "oadev", "--column", column],
                    tmp_path / f"{column}.json")
        assert doc["channel"] == column and doc["data_unit"] == unit
        u = doc["units"]
        assert u["dev"] == u["ci_low"] == u["ci_high"] == unit and u["var"] == f"{unit}^2"
        assert u["tau_s"] == "s" and u["rate_hz"] == "Hz"
        numeric = {k for k, v in doc.items() if not isinstance(v, bool) and (
            isinstance(v, int | float)
            or (isinstance(v, list) and v and all(isinstance(x, int | float) for x in v)))}
        assert numeric <= set(u), numeric - set(u)
    status, table, _ = run_command(["allan", str(recording), "--stat", "oadev", "--column",
                                    "gx"])
    assert status == 0 and "dev in dps" in table.splitlines()[0]


def test_fit_json_and_summary_carry_units(recording: Path, tmp_path: Path) -> None:
    doc = _json(["fit", str(recording), "-o", str(tmp_path / "m.toml"), "--channels",
                 "gx,ax", "--terms", "white,flicker,random_walk"], tmp_path / "fit.json")
    for ch, base in (("gx", "dps"), ("ax", "g")):
        c = doc["channels"][ch]
        units = c["units"]
        assert set(c["params"]) == set(PARAM_KEYS) and set(PARAM_KEYS) <= set(units)
        assert set(c["ci95"]) <= set(units) and units["bias"] == base
        assert units["avar"] == f"{base}^2" and units["tau_s"] == "s"
        for key, unit in GYRO_PARAM_UNITS.items():
            assert units[key] == unit.replace("dps", base), (ch, key)
        assert doc["datasheet_comparison"][ch]["unit"] == f"{base}/sqrt(Hz)"
    assert set(doc["kalibr_units"]) >= {"gyroscope_noise_density", "accelerometer_random_walk",
                                        "update_rate"}
    status, summary, err = run_command(["fit", str(recording), "-o",
                                        str(tmp_path / "m2.toml"), "--channels", "gx",
                                        "--terms", "white"])
    assert status == 0, err
    assert "white=" in summary and "dps/sqrt(Hz) [" in summary


def test_gap_json_carries_units(recording: Path, tmp_path: Path) -> None:
    doc = _json(["gap", str(recording), "--model", "datasheet:lsm6dsl", "--channels",
                 "gx,az", "--realisations", "3", "--effects", "flicker,random_walk"],
                tmp_path / "gap.json")
    units = doc["units"]
    for ch, base in (("gx", "dps"), ("az", "g")):
        c = doc["channels"][ch]
        for key in ("gap_before", "gap_after", "gap_excess_before"):
            assert key in c and "ln(ADEV_real/ADEV_sim)" in units[key]
        for effect in c["effects"]:
            for key in effect["params"]:
                assert units["params"][ch][key].startswith(base) or key.endswith(
                    ("_tau", "_freq", "_hz", "_rate")), (ch, key)


def test_imubench_csv_states_its_columns_units(recording: Path, tmp_path: Path) -> None:
    out = tmp_path / "r.csv"
    status, _, err = run_command(["convert", str(recording), str(out)])
    assert status == 0, err
    meta = [line for line in out.read_text().splitlines()[:40] if line.startswith("# units:")]
    assert len(meta) == 1
    assert json.loads(meta[0].split(":", 1)[1]) == {
        "t": "s", "gx": "dps", "gy": "dps", "gz": "dps", "ax": "g", "ay": "g", "az": "g",
        "temp": "degC", "index": "samples"}


def test_no_plot_label_says_unit_literally() -> None:
    """Plot axes name real units: no ``(unit)`` or ``unit^2`` placeholder in a label."""
    import re

    src = Path(__file__).resolve().parents[1] / "src" / "imubench"
    bad = []
    for path in src.rglob("*.py"):
        for k, line in enumerate(path.read_text().splitlines(), 1):
            if re.search(r"set_[xy]label\(\"[^\"]*\bunit\b", line):
                bad.append(f"{path}:{k}: {line.strip()}")
    assert not bad, bad
