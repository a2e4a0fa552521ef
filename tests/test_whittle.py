"""The Whittle spectral fit (imubench.noisefit.whittle): kernels against closed forms, the
expected periodogram against a Monte Carlo, round trips on the independent generator,
gaps, bad input, and the CLI."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from independent_noise import circulant_gaussian, flicker_increment_acv, white_flicker_walk
from lsm6ds_sim.model import load_model

from imubench.batch import Batch
from imubench.cli import main
from imubench.noisefit import fit_channel
from imubench.noisefit.errors import FitError
from imubench.noisefit.fit import METHODS
from imubench.noisefit.whittle import expected_periodogram, increment_acv, spectrum
from imubench.recording import open_writer

RATE = 100.0
TAU0 = 1.0 / RATE


@pytest.mark.parametrize(
    ("term", "head"),
    [
        ("white", [2.0 / TAU0, -1.0 / TAU0, 0.0]),
        ("random_walk", [2.0 * TAU0 / 3.0, TAU0 / 6.0, 0.0]),
        ("quantization", [6.0 / TAU0**2, -4.0 / TAU0**2, 1.0 / TAU0**2, 0.0]),
        ("flicker", list(flicker_increment_acv(6))),
    ],
)
def test_increment_autocovariance_matches_the_closed_forms(term: str, head: list[float]
                                                           ) -> None:
    # white: e_k - e_{k-1}; walk of interval means: an MA(1) with variance 2/3 K^2 tau0
    # and lag-1 covariance 1/6; quantization: second difference of the angle error over
    # tau0; flicker: Hosking's ARFIMA(0, -1/2, 0) recursion (the generator's own formula)
    got = increment_acv(term, 64, TAU0)
    assert got[:len(head)] == pytest.approx(head, rel=1e-12, abs=1e-12 / TAU0**2)


def test_markov_increments_follow_from_the_ar1_autocovariance() -> None:
    tau_c = 0.37
    phi = math.exp(-TAU0 / tau_c)
    k = np.arange(5)
    g = phi ** np.abs(k)
    want = 2 * g - phi ** np.abs(k - 1) - phi ** (k + 1)
    assert increment_acv("markov", 5, TAU0, tau_c_s=tau_c) == pytest.approx(want, rel=1e-12)


def test_expected_periodogram_matches_a_monte_carlo() -> None:
    # white + flicker + walk, 2048 samples, 400 records: mean tapered periodogram of the
    # increments vs the debiased expectation, per band of 16 frequencies (rel. sd ~1.3 %)
    n, reps = 2048, 400
    truth = {"white": 0.004, "flicker": 0.0015, "random_walk": 1e-3}
    acc = None
    for seed in range(reps):
        sp = spectrum(white_flicker_walk(n, RATE, seed=seed, **truth), RATE)
        acc = sp.pgram.copy() if acc is None else acc + sp.pgram
    assert acc is not None
    mc = acc / reps
    expect = sum(v**2 * sp.band_mean(expected_periodogram(
        increment_acv(t, sp.n_increments, TAU0), sp)) for t, v in truth.items())
    groups = np.add.reduceat(mc, np.arange(0, mc.size, 16))
    ref = np.add.reduceat(expect, np.arange(0, mc.size, 16))
    assert np.max(np.abs(groups / ref - 1.0)) < 0.08
    # the lowest frequency, where only the taper keeps the edges out, within 4 sd
    assert mc[0] / expect[0] == pytest.approx(1.0, abs=4.0 / math.sqrt(reps))


def test_circulant_generator_has_the_flicker_autocovariance() -> None:
    rng = np.random.default_rng(3)
    acv = flicker_increment_acv(64)
    draws = np.array([circulant_gaussian(acv, rng)[:3] for _ in range(4000)])
    assert np.var(draws[:, 0]) == pytest.approx(4.0 / math.pi, rel=0.07)
    assert np.mean(draws[:, 0] * draws[:, 1]) == pytest.approx(acv[1], rel=0.15)


def _log_error_in_se(fit_value: float, ci: tuple[float, float], truth: float) -> float:
    """|log(fit/truth)| in units of the fit's own standard error of log(amplitude)."""
    se = math.log(ci[1] / ci[0]) / (2 * 1.959964)
    return abs(math.log(fit_value / truth)) / se


@pytest.mark.parametrize("seed", [11, 12])
def test_round_trip_on_the_independent_generator(seed: int) -> None:
    # 1 h at 100 Hz: sd of log N ~ 0.001, log B ~ 0.06 (Whittle information); 4 se is a
    # 6e-5 two-sided chance per term, and the absolute bounds catch a wrong scale
    truth = {"white": 0.004, "flicker": 0.0015, "random_walk": 3e-4}
    y = white_flicker_walk(360_000, RATE, seed=seed, **truth)
    fit = fit_channel(y, RATE, method="whittle", terms="white,flicker,random_walk")
    assert fit.method == "whittle"
    assert fit.params["white"] == pytest.approx(0.004, rel=0.01)
    assert fit.params["flicker"] == pytest.approx(0.0015, rel=0.3)
    assert fit.params["random_walk"] == pytest.approx(3e-4, rel=0.8)
    for key, v in truth.items():
        assert _log_error_in_se(fit.params[key], fit.ci[key], v) < 4.0, key
    ci_n = fit.ci["white"]
    assert ci_n[1] / ci_n[0] < 1.01  # N is pinned by 1.8e5 frequencies
    assert fit.tau_s.size > 5 and fit.avar.size == fit.tau_s.size  # points for the plot


def test_auto_selection_keeps_what_is_there_and_adds_nothing() -> None:
    y = white_flicker_walk(360_000, RATE, seed=21, white=0.004, flicker=0.0015,
                           random_walk=0.0)
    fit = fit_channel(y, RATE, method="whittle")
    assert set(fit.present) == {"white", "flicker"}
    assert fit.ci["random_walk"][0] == 0.0 and fit.ci["random_walk"][1] < 3e-4
    assert fit.reasons["random_walk"].startswith("dropped")
    assert fit.reasons["markov"].startswith("dropped")


def test_gaps_are_tapered_out_not_filled() -> None:
    y = white_flicker_walk(200_000, RATE, seed=31, white=0.004, flicker=0.0015,
                           random_walk=0.0)
    full = fit_channel(y, RATE, method="whittle", terms="white,flicker")
    gappy = y.copy()
    gappy[50_000:53_000] = np.nan
    gappy[120_000:120_010] = np.nan
    fit = fit_channel(gappy, RATE, method="whittle", terms="white,flicker")
    assert any("touch missing samples" in n for n in fit.notes)
    assert fit.params["white"] == pytest.approx(full.params["white"], rel=0.005)
    assert _log_error_in_se(fit.params["flicker"], fit.ci["flicker"], 0.0015) < 4.0
    mostly = y.copy()
    mostly[::2] = np.nan
    with pytest.raises(FitError, match="touch missing samples"):
        fit_channel(mostly, RATE, method="whittle")


@pytest.mark.parametrize(
    ("y", "terms", "message"),
    [
        (np.ones((10, 10)), "auto", "1-D"),
        (np.zeros(1000), "auto", "constant"),
        (np.random.default_rng(1).normal(size=5000), "white,ramp", "ramp"),
        (np.random.default_rng(1).normal(size=5000), "white,sine", "sine"),
        (np.random.default_rng(1).normal(size=5000), "white,pink", "unknown term"),
    ],
)
def test_bad_input_names_the_field(y: np.ndarray, terms: str, message: str) -> None:
    with pytest.raises(FitError, match=message):
        fit_channel(y, RATE, method="whittle", terms=terms)


def test_fit_cli_whittle_method(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert "whittle" in METHODS
    n = 40_000
    cols = [white_flicker_walk(n, RATE, seed=40 + i, white=0.004, flicker=0.0,
                               random_walk=0.0) for i in range(6)]
    idx = np.arange(n, dtype=np.int64)
    rec = tmp_path / "r.imbr"
    meta = {"chip": "lsm6dsl", "odr_hz": RATE, "gyro_sensitivity_dps": 8.75e-3,
            "accel_sensitivity_g": 0.061e-3}
    with open_writer(rec, meta) as w:
        w.write(Batch(idx, idx / RATE, np.column_stack(cols), np.full(n, 25.0)))
    out = tmp_path / "w.toml"
    rc = main(["fit", str(rec), "--channels", "gy", "--method", "whittle", "-o", str(out)])
    assert rc == 0, capsys.readouterr().err
    assert load_model(out)["gy"].white == pytest.approx(0.004, rel=0.02)
