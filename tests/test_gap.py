"""imubench gap (issue 8): short blind cases, JSON contract, CLI end to end, bad input.

Blind cases are 15 min at 104 Hz (7.5 min fit + 7.5 min held out, 6 realisations) made
by the project's simulator with one effect withheld from the model given to the
diagnosis; the harness bench/bench_gap.py runs the 1 h cases and the independent
generator.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from lsm6ds_sim.model import NoiseModel
from lsm6ds_sim.physics import simulate
from lsm6ds_sim.temperature import SineTemperature

from imubench.batch import CHANNELS, Batch
from imubench.errors import ImubenchError
from imubench.gap import MAIN_PARAM, GapError, GapOptions, Series, diagnose_channel
from imubench.gap.evidence import fit_outliers, fit_sine, fit_temperature
from imubench.recording import open_writer

RATE = 104.0
N = int(900 * RATE)
BASE = NoiseModel.single_term("gx", white=0.004, flicker=0.0005)
TEMP = SineTemperature(25.0, 5.0, 700.0)

CASES: dict[str, dict[str, float]] = {
    "flicker": {"flicker": 0.002},
    "random_walk": {"random_walk": 5e-4},
    "ramp": {"ramp": 5e-5},
    "quantization": {"quantization": 2e-4},
    "markov": {"markov_sigma": 0.003, "markov_tau": 5.0},
    "sine": {"sine_amplitude": 0.006, "sine_freq": 3.3},
    "temperature": {"temp_coeff": 0.003},
    "outliers": {"outlier_rate": 0.2, "outlier_amplitude": 0.5},
    "filter": {"bandwidth_hz": 20.0, "filter_order": 2},
}
CONTRACT_KEYS = {"gap_before", "significant", "regions", "effects", "verdict", "gap_after",
                 "holdout"}


def blind(extra: dict[str, float], seed: int = 12345) -> Series:
    s = simulate(BASE.with_channel("gx", **extra), N, RATE, seed=seed, temperature=TEMP,
                 channels=["gx"])
    return Series(s["gx"], s["temp_c"], RATE, "blind")


@pytest.mark.parametrize("effect", sorted(CASES))
def test_blind_case_identified(effect: str) -> None:
    d = diagnose_channel(BASE, "gx", blind(CASES[effect]), GapOptions(seed=3, realisations=6))
    assert d.verdict == effect, [(c.effect, c.score) for c in d.candidates]
    out = d.to_dict()
    assert out["significant"] is True
    assert out["gap_after"] < out["gap_before"] or effect in ("sine", "outliers")
    key = MAIN_PARAM[effect]
    truth = CASES[effect][key]
    fitted = d.candidates[0].params[key]
    assert abs(fitted - truth) / truth < 0.35, (fitted, truth)


def test_null_case_gives_none() -> None:
    d = diagnose_channel(BASE, "gx", blind({}, seed=777), GapOptions(seed=3, realisations=6))
    assert d.verdict == "none"
    out = d.to_dict()
    assert out["significant"] is False and out["regions"] == []
    assert out["gap_after"] == out["gap_before"]


def test_temperature_regression_recovers_coefficients() -> None:
    """Block-mean regression against a known quadratic (no noise model involved)."""
    rng = np.random.default_rng(1)
    t = np.arange(20000) / 10.0
    temp = 20.0 + 8.0 * np.sin(2 * np.pi * t / 600.0)
    y = 0.01 * (temp - 25.0) - 0.002 * (temp - 25.0) ** 2 + 0.01 * rng.standard_normal(t.size)
    tf = fit_temperature(y, temp, 10.0, 25.0)
    assert tf is not None
    assert tf.temp_coeff == pytest.approx(0.01, rel=0.05)
    assert tf.temp_coeff2 == pytest.approx(-0.002, rel=0.05)


def test_sine_fit_on_textbook_sine() -> None:
    rng = np.random.default_rng(2)
    t = np.arange(60000) / 100.0
    y = 0.05 * np.sin(2 * np.pi * 1.234 * t + 0.4) + 0.1 * rng.standard_normal(t.size)
    sf = fit_sine(y, 100.0, 1.22, 0.05)
    assert sf.sine_freq == pytest.approx(1.234, abs=2e-4)
    assert sf.sine_amplitude == pytest.approx(0.05, rel=0.05)


def test_outlier_fit_on_bernoulli_gaussian_impulses() -> None:
    """Impulses drawn here (Bernoulli-Gaussian), not by the simulator."""
    rng = np.random.default_rng(3)
    n, fs = 400000, 100.0
    y = 0.01 * rng.standard_normal(n)
    hit = rng.random(n) < 0.5 / fs
    y[hit] += 0.2 * rng.standard_normal(hit.sum())
    of = fit_outliers(y, fs)
    assert of is not None
    assert of.outlier_rate == pytest.approx(0.5, rel=0.15)
    assert of.outlier_amplitude == pytest.approx(0.2, rel=0.15)


def write_csv(path: Path, n: int, extra: dict[str, float], seed: int = 5,
              with_temp: bool = True) -> None:
    model = NoiseModel.quiet().with_all(white=0.004).with_channel("gy", **extra)
    s = simulate(model, n, RATE, seed=seed, temperature=TEMP)
    vals = np.column_stack([s[c] for c in CHANNELS])
    temp = s["temp_c"] if with_temp else np.full(n, np.nan)
    with open_writer(path, {"odr_hz": RATE}) as w:
        w.write(Batch(np.arange(n, dtype=np.int64), s["t_s"], vals, temp))


@pytest.fixture(scope="module")
def csv_rec(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("gap")
    rec = d / "real.csv"
    write_csv(rec, int(480 * RATE), {"temp_coeff": 0.008})
    model = d / "model.toml"
    model.write_text(NoiseModel.quiet().with_all(white=0.004).to_toml(), encoding="utf-8")
    return rec, model


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "imubench.cli", "gap", *args],
                          capture_output=True, text=True, timeout=300)


def test_cli_end_to_end(csv_rec: tuple[Path, Path], tmp_path: Path) -> None:
    rec, model = csv_rec
    out = tmp_path / "gap.json"
    rep = tmp_path / "report"
    r = run_cli(str(rec), "--model", str(model), "--channels", "gx,gy", "--seed", "1",
                "--realisations", "6", "--report", str(rep), "--json", str(out))
    assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    assert set(doc["channels"]) == {"gx", "gy"}
    for ch, c in doc["channels"].items():
        assert set(c) >= CONTRACT_KEYS, ch
        assert set(c["holdout"]) >= {"gap_before", "gap_after"}
        for r_ in c["regions"]:
            assert {"tau_min_s", "tau_max_s", "direction"} <= set(r_)
        for e in c["effects"]:
            assert {"effect", "params", "gap_after"} <= set(e)
        assert c["verdict"] in (*CASES, "none", "unexplained")
    assert doc["channels"]["gx"]["verdict"] == "none"
    gy = doc["channels"]["gy"]
    assert gy["verdict"] == "temperature"
    assert gy["effects"][0]["params"]["temp_coeff"] == pytest.approx(0.008, rel=0.2)
    assert gy["holdout"]["gap_after"] < 0.5 * gy["holdout"]["gap_before"]
    for f in ("index.html", "gx_adev.png", "gx_adev.svg", "gy_evidence.png",
              "gy_evidence.svg"):
        assert (rep / f).stat().st_size > 0, f


def test_cli_replicate_holdout(csv_rec: tuple[Path, Path], tmp_path: Path) -> None:
    rec, model = csv_rec
    rep2 = tmp_path / "rep2.csv"
    write_csv(rep2, int(300 * RATE), {"temp_coeff": 0.008}, seed=9)
    out = tmp_path / "g.json"
    r = run_cli(str(rec), "--model", str(model), "--channels", "gy", "--realisations", "5",
                "--holdout", str(rep2), "--json", str(out))
    assert r.returncode == 0, r.stderr
    h = json.loads(out.read_text())["channels"]["gy"]["holdout"]
    (rec2,) = h["recordings"]
    assert rec2["recording"].endswith("rep2.csv")
    assert rec2["gap_after"] < 0.5 * rec2["gap_before"]


def test_cli_unknown_channel(csv_rec: tuple[Path, Path], tmp_path: Path) -> None:
    rec, model = csv_rec
    r = run_cli(str(rec), "--model", str(model), "--channels", "gq", "--json",
                str(tmp_path / "x.json"))
    assert r.returncode == 2
    assert "no channel 'gq'" in r.stderr and "real.csv" in r.stderr


def test_cli_bad_fraction(csv_rec: tuple[Path, Path], tmp_path: Path) -> None:
    rec, model = csv_rec
    r = run_cli(str(rec), "--model", str(model), "--holdout-fraction", "1.5", "--json",
                str(tmp_path / "x.json"))
    assert r.returncode == 2
    assert "--holdout-fraction" in r.stderr and "[0, 1)" in r.stderr


def test_missing_temp_column_when_temperature_requested(tmp_path: Path,
                                                        csv_rec: tuple[Path, Path]) -> None:
    _, model = csv_rec
    rec = tmp_path / "notemp.csv"
    write_csv(rec, int(120 * RATE), {}, with_temp=False)
    r = run_cli(str(rec), "--model", str(model), "--effects", "temperature,ramp", "--json",
                str(tmp_path / "x.json"))
    assert r.returncode == 2
    assert "notemp.csv" in r.stderr and "'temp' column" in r.stderr


def test_options_validation() -> None:
    with pytest.raises(GapError, match="holdout-fraction"):
        GapOptions(holdout_fraction=-0.1)
    with pytest.raises(GapError, match="unknown effect"):
        GapOptions(effects=("wobble",))
    with pytest.raises(ImubenchError, match="too few"):
        diagnose_channel(BASE, "gx", Series(np.zeros(300), None, RATE, "tiny"))
