"""imubench gap (issue 8): short blind cases, JSON contract, CLI end to end, bad input.

Blind cases are 10 or 15 min at 104 Hz (half fit, half held out, 5 realisations) made
by the project's simulator with one effect withheld from the model given to the
diagnosis (four of the nine are ``slow``); the harness bench/bench_gap.py runs the 1 h
cases and the independent generator. Bad-input tests call the CLI in-process; one end-to-
end test runs it as a subprocess.
"""

from __future__ import annotations

import json
import math
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
from imubench.gap.curves import (
    ALPHA_FAMILY,
    Z_REGION,
    Comparison,
    Features,
    SimFeatures,
    compare,
    family_z,
    welch_psd,
    wilson_hilferty_z,
)
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
    "markov": {"markov_sigma": 0.003, "markov_tau": 3.0},  # tau_c <= 79 s / MARKOV_SPAN
    "sine": {"sine_amplitude": 0.006, "sine_freq": 3.3},
    "temperature": {"temp_coeff": 0.003},
    "outliers": {"outlier_rate": 0.2, "outlier_amplitude": 0.5},
    "base_model": {"bandwidth_hz": 20.0, "filter_order": 2},  # a withheld output filter
}
CONTRACT_KEYS = {"gap_before", "significant", "regions", "effects", "verdict", "gap_after",
                 "holdout"}


LONG_CASES = {"markov", "flicker", "quantization", "base_model", "random_walk", "ramp"}
"""Cases whose evidence needs long taus (or is only ``slow``) use N samples; the others
10 min (the default run stays fast)."""


def blind(extra: dict[str, float], seed: int = 12345, n: int = N) -> Series:
    s = simulate(BASE.with_channel("gx", **extra), n, RATE, seed=seed, temperature=TEMP,
                 channels=["gx"])
    return Series(s["gx"], s["temp_c"], RATE, "blind")


SLOW_CASES = {"base_model", "quantization", "ramp", "flicker"}
"""Blind cases run only with ``-m slow`` (the default run keeps the five whose evidence
differs most: Allan bump, rising curve, spectral line, tails, temperature)."""


@pytest.mark.parametrize("effect", [
    pytest.param(e, marks=pytest.mark.slow) if e in SLOW_CASES else e for e in sorted(CASES)
])
def test_blind_case_identified(effect: str) -> None:
    n = N if effect in LONG_CASES else int(600 * RATE)
    d = diagnose_channel(BASE, "gx", blind(CASES[effect], n=n),
                         GapOptions(seed=3, realisations=5))
    assert d.verdict == effect, [(c.effect, c.score) for c in d.candidates]
    out = d.to_dict()
    assert out["significant"] is True
    assert out["gap_after"] < out["gap_before"] or effect in ("sine", "outliers")
    key = MAIN_PARAM[effect]
    truth = CASES[effect][key]
    fitted = d.candidates[0].params[key]
    assert abs(fitted - truth) / truth < 0.35, (fitted, truth)


def test_null_case_gives_none() -> None:
    d = diagnose_channel(BASE, "gx", blind({}, seed=777, n=int(600 * RATE)),
                         GapOptions(seed=3, realisations=5))
    assert d.verdict == "none"
    out = d.to_dict()
    assert out["significant"] is False and out["regions"] == []
    assert out["gap_after"] == out["gap_before"]
    # under the null gap^2 / gap_null^2 is about chi2(n) / n (n ~ 14 taus): below 2^2
    assert 0 < out["gap_before"] < 2.0 * out["gap_null"]
    assert out["gap_excess_before"] < out["gap_null"]


def _null_comparison(m: int, k: int, spike_z: float | None) -> Comparison:
    """compare() on m taus and 6 bands: the real curve is the realisations' mean, except
    (spike_z) one tau moved to that z; line, tails and slopes neutral."""
    rng = np.random.default_rng(8)
    tau = np.logspace(-2, 3, m)
    curve = 1e-5 / tau + 1e-8 * tau
    avar = curve * np.exp(2 * 0.1 * rng.standard_normal((k, m)))
    bands = np.exp(0.2 * rng.standard_normal((k, 6)))
    sims = SimFeatures(avar, bands, np.ones((k, 8)), np.zeros(k),
                       rng.standard_normal(k), rng.standard_normal(k),
                       rng.standard_normal(k), rng.standard_normal(k),
                       rng.standard_normal(k), np.zeros(k))
    edges = np.logspace(-2, 1, 7)

    def run(real_avar: np.ndarray) -> Comparison:
        real = Features(real_avar, bands.mean(axis=0), np.ones(8), 0, line_ln=0.0,
                        temp_corr=0.0, trend_corr=0.0, level_corr=0.0)
        return compare(real, np.full(m, np.nan), sims, tau, edges)

    base = run(avar.mean(axis=0))
    if spike_z is None:
        return base
    # the d whose Wilson-Hilferty z is spike_z: (r^(1/3) - 1 + v) / sqrt(v), r = exp(2 d)
    v = 4.0 * base.sigma[m // 2] ** 2 / 9.0
    d = np.zeros(m)
    d[m // 2] = 1.5 * np.log(1.0 - v + spike_z * np.sqrt(v))
    return run(avar.mean(axis=0) * np.exp(2 * d))


def test_family_wise_threshold_keeps_a_null_with_many_taus_none() -> None:
    """One tau at z 3.8 among 40 (> Z_REGION, the old per-tau threshold) is what a null
    record shows about once in eight: no region, not significant, so the verdict is none;
    the same tau at z 6 is a region."""
    m = 40
    assert Z_REGION < 3.8 < family_z(m)
    null = _null_comparison(m, 10, 3.8)
    assert abs(null.z[m // 2] - 3.8) < 1e-6
    assert null.regions == [] and null.bands == [] and not null.significant
    strong = _null_comparison(m, 10, 6.0)
    assert len(strong.regions) == 1 and strong.significant


def test_family_z_is_sidak_by_monte_carlo() -> None:
    """max |z| of m independent normals exceeds family_z(m) with probability
    ALPHA_FAMILY (counted on 400 000 simulated families, not from the formula)."""
    rng = np.random.default_rng(21)
    m, n = 30, 400_000
    hits = 0
    for _ in range(8):
        zmax = np.abs(rng.standard_normal((n // 8, m))).max(axis=1)
        hits += int((zmax > family_z(m)).sum())
    expected = ALPHA_FAMILY * n  # 1080, binomial sd ~33
    assert abs(hits - expected) < 5 * math.sqrt(expected), (hits, expected)
    assert family_z(1) == Z_REGION and family_z(0) == Z_REGION


def test_gap_excess_is_the_systematic_part() -> None:
    """A known constant offset of ln ADEV on top of the band's scatter (no simulator)."""
    from imubench.gap.curves import Comparison

    rng = np.random.default_rng(4)
    sigma = np.full(400, 0.1)
    d = 0.3 + sigma * rng.standard_normal(400)
    nan = np.full(400, np.nan)
    c = Comparison(np.arange(400.0), nan, nan, nan, nan, d, d / sigma, sigma, nan, nan,
                   nan, 0.0, 0.0, 0.0)
    assert c.gap_null == pytest.approx(0.1)
    # gap^2 = 0.3^2 + 0.1^2 in expectation: the excess recovers the offset
    assert c.gap == pytest.approx(np.hypot(0.3, 0.1), rel=0.05)
    assert c.gap_excess == pytest.approx(0.3, rel=0.06)
    assert c.gap_excess == c.excess_moment  # far above its floor: reported as estimated


def test_a_perfect_model_leaves_no_systematic_gap_nine_times_in_ten() -> None:
    """The record and K = 10 realisations all drawn from one white + random-walk process
    (numpy, not the simulator; 10 min at 104 Hz, 80 records): the moment estimate
    ``sqrt(max(0, gap^2 - gap_null^2))`` is positive about one time in three (an outside
    reviewer read 0.09-0.17 as the systematic gap its perfect models left); the reported
    ``gap_excess`` is 0 unless the excess passes its floor, which it does at most 15 % of
    the time (measured 4-9 %), and the floor is above the largest excess it hid."""
    from lsm6ds_sim.model import ChannelModel

    from imubench.gap.parts import PartSetup

    white_d, k_rw, n, k = 0.004, 2e-4, int(600 * RATE), 10
    rng = np.random.default_rng(11)

    def draw() -> np.ndarray:
        return (rng.normal(0.0, white_d * math.sqrt(RATE), n)
                + np.cumsum(rng.normal(0.0, k_rw / math.sqrt(RATE), n)))

    cm = ChannelModel().replace(white=white_d, random_walk=k_rw)
    moment, reported = [], []
    for _ in range(80):
        part = PartSetup(Series(draw(), None, RATE, "null"), cm)
        c = part.compare(part.sim_features(np.array([draw() for _ in range(k)])))
        moment.append(c.excess_moment)
        reported.append(c.gap_excess)
        assert c.gap_excess in (0.0, c.excess_moment)
        assert c.gap_excess > 0.0 or c.excess_moment <= c.gap_excess_floor
    assert np.mean(np.array(moment) > 0) > 0.25
    assert np.mean(np.array(reported) > 0) <= 0.15


@pytest.mark.parametrize(("n", "nperseg"), [(187_200, 4096), (187_200, 187_200),
                                             (1001, 64), (999, 999), (5000, 333)])
def test_welch_psd_is_scipys_welch(n: int, nperseg: int) -> None:
    """The gap's own Welch estimate gives scipy.signal.welch's numbers (Hann, half
    overlap, each segment less its mean), odd and even segment lengths, NaN as 0."""
    from scipy.signal import welch

    rng = np.random.default_rng(n + nperseg)
    y = rng.standard_normal(n) + 1e-3 * rng.standard_normal(n).cumsum() + 5.0
    y[n // 3] = np.nan
    f, p = welch_psd(y, 104.0, nperseg)
    v = np.where(np.isfinite(y), y - np.nanmean(y), 0.0)
    f0, p0 = welch(v, fs=104.0, window="hann", nperseg=nperseg, noverlap=nperseg // 2,
                   detrend="constant")
    np.testing.assert_array_equal(f, f0)
    np.testing.assert_allclose(p, p0, rtol=1e-10, atol=0)


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


def run_inproc(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    """(exit status, stderr) of ``imubench gap ARGS`` in this process."""
    from imubench.cli import main

    try:
        rc = main(["gap", *args])
    except SystemExit as exc:  # argparse errors
        rc = int(exc.code or 0)
    return rc, capsys.readouterr().err


def test_cli_end_to_end(csv_rec: tuple[Path, Path], tmp_path: Path) -> None:
    rec, model = csv_rec
    out = tmp_path / "gap.json"
    rep = tmp_path / "report"
    r = run_cli(str(rec), "--model", str(model), "--channels", "gx,gy", "--seed", "1",
                "--realisations", "4", "--effects", "temperature,random_walk,flicker,ramp",
                "--report", str(rep), "--json", str(out))
    assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    assert set(doc["channels"]) == {"gx", "gy"}
    for ch, c in doc["channels"].items():
        assert set(c) >= CONTRACT_KEYS, ch
        assert set(c["holdout"]) >= {"gap_before", "gap_after", "gap_excess_before",
                                     "gap_excess_after", "gap_null", "gap_null_after"}
        assert "gap_null_after" in c
        for r_ in c["regions"]:
            assert {"tau_min_s", "tau_max_s", "direction"} <= set(r_)
        for b in c["bands"]:
            assert {"f_min_hz", "f_max_hz", "direction", "z_max", "z_max_after"} <= set(b)
        for k in c["kept"]:
            assert k["holdout_region_gap_after"] is not None
        for e in c["effects"]:
            assert {"effect", "params", "gap_after"} <= set(e)
        assert c["verdict"] in (*CASES, "none", "unexplained")
        assert {e["effect"] for e in c["effects"]} <= {"temperature", "random_walk",
                                                       "flicker", "ramp"}
    assert doc["channels"]["gx"]["verdict"] == "none"
    gy = doc["channels"]["gy"]
    assert gy["verdict"] == "temperature"
    assert gy["effects"][0]["params"]["temp_coeff"] == pytest.approx(0.008, rel=0.2)
    assert gy["holdout"]["gap_after"] < 0.5 * gy["holdout"]["gap_before"]
    assert gy["holdout"]["gap_excess_after"] < 0.3 * gy["holdout"]["gap_excess_before"]
    assert gy["kept"][-1]["holdout_region_gap_after"] == pytest.approx(
        gy["holdout"]["region_gap_after"])
    for f in ("index.html", "gx_adev.png", "gx_adev.svg", "gy_evidence.png",
              "gy_evidence.svg"):
        assert (rep / f).stat().st_size > 0, f
    index = (rep / "index.html").read_text()
    assert "Verdict temperature (temp_coeff = " in index  # the reasons, not only plots
    assert "Verdict none: no test on the fit part departs beyond the scatter" in index
    assert "Held-out part (never used for the fit)" in index
    assert "  Verdict temperature (temp_coeff = " in r.stdout  # and on the terminal


def test_channels_in_parallel_give_the_same_result(csv_rec: tuple[Path, Path]) -> None:
    """``jobs`` > 1 diagnoses the channels in spawned processes; every channel's
    realisations are seeded from the options alone, so the JSON is the same, and
    ``progress`` hears of every channel once."""
    from lsm6ds_sim.model import load_model

    from imubench.gap import diagnose_recording
    from imubench.recording import load_recording

    rec, model_path = csv_rec
    recording, model = load_recording(rec), load_model(model_path)
    opt = GapOptions(seed=3, realisations=4, effects=("temperature", "random_walk"))
    runs = []
    for jobs in (1, 2):
        heard: list[str] = []
        out, diags = diagnose_recording(recording, model, ["gx", "gy"], opt,
                                        progress=heard.append, jobs=jobs)
        assert sorted(heard) == ["gx", "gy"]
        assert list(out["channels"]) == ["gx", "gy"] == list(diags)
        runs.append(json.dumps(out, sort_keys=True))
    assert runs[0] == runs[1]
    assert json.loads(runs[1])["channels"]["gy"]["verdict"] == "temperature"


def test_an_error_in_a_parallel_channel_is_raised_as_itself(csv_rec: tuple[Path, Path]
                                                            ) -> None:
    """A channel's GapError (here: the model has no noise on gy) reaches the caller from
    the worker process unchanged."""
    from imubench.gap import diagnose_recording
    from imubench.recording import load_recording

    model = NoiseModel.quiet().with_channel("gx", white=0.004)
    with pytest.raises(GapError, match=r"\[channels.gy\] has no noise term"):
        diagnose_recording(load_recording(csv_rec[0]), model, ["gx", "gy"],
                           GapOptions(realisations=3), jobs=2)


def test_a_constant_channel_is_refused_by_name(tmp_path: Path) -> None:
    """A stuck axis (every sample the same) is a clear error naming the channel, not a
    division by zero deep in a statistic."""
    model = NoiseModel.quiet().with_all(white=0.004)
    series = Series(np.zeros(20000), None, RATE, "stuck.csv")
    with pytest.raises(GapError, match=r"stuck.csv: gz is constant \(0 in every sample\)"):
        diagnose_channel(model, "gz", series, GapOptions(realisations=3))


@pytest.mark.parametrize(("args", "message"), [
    (["--channels", "gx,gy,gx"], "--channels: gx given more than once"),
    (["--jobs", "0"], "--jobs 0: use 1 or more"),
    (["--jobs", "two"], "--jobs 'two': not a whole number"),
])
def test_cli_refuses_bad_channels_and_jobs(csv_rec: tuple[Path, Path], tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str],
                                           args: list[str], message: str) -> None:
    rec, model = csv_rec
    rc, err = run_inproc(capsys, str(rec), "--model", str(model), *args,
                         "--json", str(tmp_path / "g.json"))
    assert rc == 2 and message in err


def test_cli_replicate_holdout(csv_rec: tuple[Path, Path], tmp_path: Path,
                               capsys: pytest.CaptureFixture[str]) -> None:
    rec, model = csv_rec
    rep2 = tmp_path / "rep2.csv"
    write_csv(rep2, int(300 * RATE), {"temp_coeff": 0.008}, seed=9)
    out = tmp_path / "g.json"
    rc, err = run_inproc(capsys, str(rec), "--model", str(model), "--channels", "gy",
                         "--realisations", "4", "--holdout", str(rep2), "--json", str(out))
    assert rc == 0, err
    h = json.loads(out.read_text())["channels"]["gy"]["holdout"]
    (rec2,) = h["recordings"]
    assert rec2["recording"].endswith("rep2.csv")
    assert rec2["gap_after"] < 0.5 * rec2["gap_before"]


def test_cli_unknown_channel(csv_rec: tuple[Path, Path], tmp_path: Path,
                             capsys: pytest.CaptureFixture[str]) -> None:
    rec, model = csv_rec
    rc, err = run_inproc(capsys, str(rec), "--model", str(model), "--channels", "gq",
                         "--json", str(tmp_path / "x.json"))
    assert rc == 2
    assert "no channel 'gq'" in err and "real.csv" in err


def test_cli_bad_fraction(csv_rec: tuple[Path, Path], tmp_path: Path,
                          capsys: pytest.CaptureFixture[str]) -> None:
    rec, model = csv_rec
    rc, err = run_inproc(capsys, str(rec), "--model", str(model), "--holdout-fraction",
                         "1.5", "--json", str(tmp_path / "x.json"))
    assert rc == 2
    assert "--holdout-fraction" in err and "[0, 1)" in err


def test_missing_temp_column_when_temperature_requested(
        tmp_path: Path, csv_rec: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    _, model = csv_rec
    rec = tmp_path / "notemp.csv"
    write_csv(rec, int(120 * RATE), {}, with_temp=False)
    rc, err = run_inproc(capsys, str(rec), "--model", str(model), "--effects",
                         "temperature,ramp", "--json", str(tmp_path / "x.json"))
    assert rc == 2
    assert "notemp.csv" in err and "'temp' column" in err


def test_options_validation() -> None:
    with pytest.raises(GapError, match="holdout-fraction"):
        GapOptions(holdout_fraction=-0.1)
    with pytest.raises(GapError, match="unknown effect"):
        GapOptions(effects=("wobble",))
    with pytest.raises(ImubenchError, match="too few"):
        diagnose_channel(BASE, "gx", Series(np.zeros(300), None, RATE, "tiny"))


def test_global_chi2_is_chi_squared_under_correlated_null() -> None:
    """z drawn with a known correlation: omnibus mean ~ m dof, smooth part mean ~ 3 dof."""
    from imubench.gap.curves import SMOOTH_DEGREE, global_chi2

    m = 12
    tau = 2.0 ** np.arange(m)
    idx = np.arange(m)
    corr = 0.6 ** np.abs(idx[:, None] - idx[None, :])  # AR(1)-like correlation of octaves
    chol = np.linalg.cholesky(corr)
    rng = np.random.default_rng(5)
    stats = np.array([global_chi2(chol @ rng.standard_normal(m), corr, tau)
                      for _ in range(4000)])
    assert abs(stats[:, 0].mean() - m) < 0.5  # sd of the mean: sqrt(2 m / 4000) = 0.08
    assert stats[:, 1].min() == m
    assert abs(stats[:, 2].mean() - (SMOOTH_DEGREE + 1)) < 0.2


def test_broad_random_walk_gap_is_not_none() -> None:
    """Issue 15: a random walk K 2e-4 over white 0.004 + flicker 0.0008 (1 h) came out
    `none` with a systematic gap three times the scatter; the whole-curve test fires.

    The random walk is added by numpy to the simulator's base record (independent of the
    simulator's random-walk term)."""
    base = NoiseModel.single_term("gx", white=0.004, flicker=0.0008)
    n = int(3600 * RATE)
    rng = np.random.default_rng(1003)
    y = simulate(base, n, RATE, seed=780, channels=["gx"])["gx"]
    y = y + np.cumsum(2e-4 * rng.standard_normal(n) / math.sqrt(RATE))
    d = diagnose_channel(base, "gx", Series(y, None, RATE, "rw"), GapOptions(seed=3)).to_dict()
    assert d["global"]["fired"]
    assert d["verdict"] == "random_walk"


def test_allan_z_follows_the_chi_squared_law_of_an_allan_variance() -> None:
    """The per-tau z of ``compare`` (Wilson-Hilferty) against scipy's chi-squared: an
    AVAR estimate with nu degrees of freedom at its p-quantile gives the normal
    p-quantile within 0.1 (0.2 at nu = 5), also at the few dof of the long taus where
    ln chi2 is skewed (d / s was off by 0.7 at p = 0.002, nu = 20)."""
    from scipy.stats import chi2, norm

    for nu in (5.0, 20.0, 200.0):
        s = math.sqrt(1.0 / (2.0 * nu))  # sd of ln ADEV
        for p in (0.002, 0.05, 0.5, 0.95, 0.998):
            d = 0.5 * math.log(chi2.ppf(p, nu) / nu)
            z = float(wilson_hilferty_z(np.array([d]), np.array([s]))[0])
            assert abs(z - norm.ppf(p)) < (0.2 if nu < 10 else 0.1), (nu, p, z)
    d_low = 0.5 * math.log(chi2.ppf(0.002, 20.0) / 20.0)
    assert abs(d_low / math.sqrt(1.0 / 40.0) - norm.ppf(0.002)) > 0.5  # what d / s gave


def test_cli_says_how_much_of_the_recording_is_missing(tmp_path: Path) -> None:
    """A record 10 % in holes was diagnosed without a word about them (the realisations
    carry the same holes, so the numbers were right, but the user could not tell)."""
    rng = np.random.default_rng(9)
    n = 40_000
    keep = np.ones(n, dtype=bool)
    keep[10_000:14_000] = False
    rec = tmp_path / "holes.csv"
    rec.write_text("t,gx\n" + "".join(
        f"{i / 100:.2f},{'' if 20_000 <= i < 20_100 else f'{v:.5f}'}\n"
        for i, v in enumerate(rng.normal(0, 0.04, n)) if keep[i]))
    model = tmp_path / "m.toml"
    model.write_text(NoiseModel.single_term("gx", white=0.004).to_toml())
    out = tmp_path / "gap.json"
    r = run_cli(str(rec), "--model", str(model), "--channels", "gx", "--realisations", "3",
                "--effects", "random_walk", "--json", str(out))
    assert r.returncode == 0, r.stderr
    head = r.stdout.splitlines()
    assert "36000 samples, 1 hole(s) (4000 samples, 10 % missing" in head[0]
    # empty cells are the channel's lost samples too (they were warned of, nothing more)
    assert ("gx: 4100 samples lost in 2 run(s), 100 of them empty cells beside the "
            "recording's 1 hole(s)") in head[1]
    assert "empty cells (gx 100 on lines 16002-16101)" in r.stderr
    doc = json.loads(out.read_text())
    # samples: the record's span (holes included), as before
    assert (doc["samples"], doc["lost_samples"], doc["holes"]) == (40000, 4000, 1)
    assert (doc["channels"]["gx"]["lost_samples"], doc["channels"]["gx"]["holes"]) == (4100, 2)
    assert doc["effects_untested"] == {} and doc["effects_tested"] == ["random_walk"]


def test_a_recording_without_temperature_says_the_temperature_went_untested(
        tmp_path: Path, csv_rec: tuple[Path, Path]) -> None:
    """An outside reviewer's header ``t,gx,tmep``: the default effects' temperature was
    listed as tested and the text named temperature tests that never ran."""
    from imubench.gap.explain import explain_channel

    _, model = csv_rec
    rec = tmp_path / "notemp.csv"
    write_csv(rec, int(120 * RATE), {}, with_temp=False)
    out = tmp_path / "x.json"
    r = run_cli(str(rec), "--model", str(model), "--channels", "gx", "--realisations", "3",
                "--json", str(out))
    assert r.returncode == 0, r.stderr
    assert f"# temperature not tested: {rec} has no temperature column" in r.stdout
    doc = json.loads(out.read_text())
    assert "temperature" not in doc["effects_tested"]
    assert doc["effects_untested"] == {"temperature": f"{rec} has no temperature column"}
    said = [x for x in explain_channel(doc["channels"]["gx"], 3)
            if x.startswith("Nothing exceeds")]
    assert said and all("temperature level" not in x and "no temperature test" in x
                        for x in said), said


def test_a_bias_step_verdict_shows_the_block_means_of_the_whole_record(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The evidence plot of a bias step was the fit part's per-tau z: a step in the
    held-out part left both curves flat, the plot showing nothing behind the verdict."""
    n = int(480 * RATE)
    model = NoiseModel.quiet().with_all(white=0.004)
    s = simulate(model, n, RATE, seed=8, temperature=TEMP)
    vals = np.column_stack([s[c] for c in CHANNELS])
    vals[int(0.7 * n):, 0] += 0.05  # gx steps in the held-out part
    rec = tmp_path / "step.csv"
    with open_writer(rec, {"odr_hz": RATE}) as w:
        w.write(Batch(np.arange(n, dtype=np.int64), s["t_s"], vals, s["temp_c"]))
    mfile = tmp_path / "m.toml"
    mfile.write_text(model.to_toml(), encoding="utf-8")
    rep = tmp_path / "rep"
    rc, err = run_inproc(capsys, str(rec), "--model", str(mfile), "--channels", "gx",
                         "--realisations", "4", "--json", str(tmp_path / "g.json"),
                         "--report", str(rep))
    assert rc == 0, err
    doc = json.loads((tmp_path / "g.json").read_text())
    assert doc["channels"]["gx"]["verdict"] == "bias_step"
    svg = (rep / "gx_evidence.svg").read_text()
    assert "block means over the whole record" in svg and "time in the record (s)" in svg
