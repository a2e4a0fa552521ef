"""The exact block-mean likelihood (imubench.noisefit.blockmean) and the ``exact`` method:
block-mean covariance against closed forms and a Monte Carlo of the independent generator,
the Durbin-Levinson likelihood against a dense one, round trips, refused gaps."""

from __future__ import annotations

import math

import numpy as np
import pytest
from independent_noise import circulant_gaussian, flicker_increment_acv, white_flicker_walk
from scipy.linalg import toeplitz

from imubench.noisefit import fit_channel
from imubench.noisefit.blockmean import block_increments, term_acv, toeplitz_nll
from imubench.noisefit.errors import FitError

RATE = 100.0
TAU0 = 1.0 / RATE


@pytest.mark.parametrize("m", [1, 7, 50])
def test_block_covariance_matches_the_closed_forms(m: int) -> None:
    # white: block means are iid with variance 1/(m tau0), so D is an MA(1):
    # (2, -1, 0) / (m tau0). Random walk of interval means: a block mean is the mean of the
    # Wiener rate over m tau0, so D is the interval-mean MA(1) at tau = m tau0:
    # (2/3, 1/6, 0) tau.
    tau = m * TAU0
    white = term_acv("white", m, 4, RATE)
    walk = term_acv("random_walk", m, 4, RATE)
    assert white == pytest.approx(np.array([2.0, -1.0, 0.0, 0.0]) / tau, abs=1e-9 / tau)
    assert walk == pytest.approx(np.array([2 / 3, 1 / 6, 0.0, 0.0]) * tau, abs=1e-12)


def test_flicker_block_covariance_matches_a_monte_carlo() -> None:
    # the generator's circulant flicker (not the kernels' G), m = 8, 3000 records: sample
    # autocovariance of D at lags 0..3 within 4 Monte Carlo standard errors
    m, n_blocks, reps = 8, 24, 3000
    rng = np.random.default_rng(11)
    acv = flicker_increment_acv(m * n_blocks)
    d = np.array([block_increments(np.cumsum(circulant_gaussian(acv, rng)), m)
                  for _ in range(reps)])
    want = term_acv("flicker", m, 4, RATE)
    for lag in range(4):
        prod = d[:, : d.shape[1] - lag] * d[:, lag:]
        per_record = prod.mean(axis=1)
        se = per_record.std(ddof=1) / math.sqrt(reps)
        assert abs(per_record.mean() - want[lag]) < 4.0 * se + 1e-12


def test_durbin_levinson_equals_the_dense_gaussian_likelihood() -> None:
    rng = np.random.default_rng(5)
    acvs = np.vstack([
        term_acv("flicker", 10, 200, RATE) + 1e3 * term_acv("random_walk", 10, 200, RATE),
        term_acv("white", 10, 200, RATE) + term_acv("flicker", 10, 200, RATE),
    ])
    x = rng.standard_normal(200)
    got = toeplitz_nll(acvs, x)
    for row, value in zip(acvs, got, strict=True):
        sigma = toeplitz(row)
        _, logdet = np.linalg.slogdet(sigma)
        assert value == pytest.approx(0.5 * (logdet + x @ np.linalg.solve(sigma, x)),
                                      rel=1e-10)


def test_a_gappy_record_is_refused() -> None:
    y = white_flicker_walk(20_000, RATE, seed=1, white=0.004, flicker=0.0015,
                           random_walk=1e-4)
    y[5000:5100] = np.nan
    with pytest.raises(FitError, match="whittle"):
        fit_channel(y, RATE, method="exact")


@pytest.mark.slow
@pytest.mark.parametrize("seed", [21, 22, 23])
def test_round_trip_on_the_independent_generator(seed: int) -> None:
    # 1 h at 100 Hz with a random walk 3x the bench's: each estimate within 3.3 of its own
    # reported standard deviations (the 95 % interval's half-width in log / 1.96; about a
    # 0.1 % miss rate per term for a calibrated interval)
    truth = {"white": 0.004, "flicker": 0.0015, "random_walk": 3e-4}
    y = white_flicker_walk(360_000, RATE, seed=seed, **truth)
    fit = fit_channel(y, RATE, method="exact", terms="white,flicker,random_walk")
    assert fit.method == "exact"
    for key, true in truth.items():
        lo, hi = fit.ci[key]
        est = fit.params[key]
        assert lo < est < hi
        sd = math.log(hi / lo) / (2.0 * 1.959964)
        assert abs(math.log(est / true)) < 3.3 * sd, key


def test_profile_end_stops_at_the_span_on_a_flat_profile() -> None:
    """A random walk the block means barely see has a flat profile likelihood: the
    secant search for the interval end doubled its step 12 times and overflowed
    math.exp (Samsung S5 accelerometer x, `fit --method exact`). It stops at the span."""
    from typing import cast

    from imubench.noisefit.exactfit import PROFILE_SPAN, _Profile, _profile_end

    class Flat:
        def at(self, log_k2: float) -> float:
            math.exp(log_k2)  # what the real profile computes first
            return 10.0

    for sign in (1.0, -1.0):
        end = _profile_end(cast(_Profile, Flat()), 10.0, -20.0, 0.3, 3.84, sign)
        assert end == -20.0 + sign * PROFILE_SPAN
