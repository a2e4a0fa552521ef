"""Noise readouts of a live curve (imubench.fleet.readouts) against the IEEE Std 952
Annex C model: AVAR(tau) = N^2 / tau + (2 ln2 / pi) B^2 + K^2 tau / 3, evaluated here
from those published terms, and the datasheet unit conversions done by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from imubench.fleet.readouts import channel_readouts, read_terms, sensor_readouts

N, B, K = 0.004, 0.002, 1e-5  # dps/sqrt(Hz), dps, dps/sqrt(s)
TAU = 2.0 ** np.arange(-6, 21)  # 0.0156 s .. 1e6 s


def ieee_adev(tau: np.ndarray, n: float, b: float, k: float) -> np.ndarray:
    return np.sqrt(n**2 / tau + 2 * math.log(2) / math.pi * b**2 + k**2 * tau / 3)


def curve(tau: np.ndarray, n: float, b: float, k: float, rel_ci: float = 0.02,
          units: str = "dps") -> dict[str, object]:
    """The published fields of one channel: the model ADEV with +-rel_ci limits."""
    dev = ieee_adev(tau, n, b, k)
    return {"tau_s": tau.tolist(), "dev": dev.tolist(), "ci_low": (dev * (1 - rel_ci)).tolist(),
            "ci_high": (dev * (1 + rel_ci)).tolist(), "units": units}


def terms(c: dict[str, object]) -> dict[str, dict[str, object]]:
    return read_terms(c["tau_s"], c["dev"], c["ci_low"], c["ci_high"])  # type: ignore[arg-type]


def test_full_curve_reads_the_three_terms() -> None:
    r = terms(curve(TAU, N, B, K))
    assert {t: r[t]["kind"] for t in "NBK"} == {"N": "value", "B": "value", "K": "value"}
    assert r["N"]["value"] == pytest.approx(N, rel=0.01)
    # the tangent rule reads the floor with the white and random-walk terms still in it:
    # biased high, by the overlap at the minimum (IEEE 952 C.3)
    assert B < r["B"]["value"] < 1.15 * B
    assert r["K"]["value"] == pytest.approx(K, rel=0.05)
    assert r["N"]["tau_s"] < r["B"]["tau_s"] < r["K"]["tau_s"]


def test_curve_still_falling_gives_upper_b_and_no_k() -> None:
    tau = TAU[TAU <= 4.0]  # white noise dominates everywhere: no floor seen yet
    r = terms(curve(tau, N, B, K))
    assert r["N"]["kind"] == "value"
    assert r["B"]["kind"] == "upper"
    assert r["B"]["value"] > B  # an upper bound is above the truth
    assert r["K"]["kind"] == "none" and r["K"]["value"] is None


def test_no_white_region_refuses_n() -> None:
    tau = TAU[TAU >= 1e4]  # only the random walk rise
    r = terms(curve(tau, N, B, K))
    assert r["N"]["value"] is None and "no -1/2 slope" in r["N"]["note"]
    assert r["B"]["kind"] == "upper"  # minimum at the first tau


def test_a_rise_within_the_confidence_limits_is_not_a_floor() -> None:
    # the same curve as the full one, but limits of +-50 %: the rise after the minimum is
    # not significant until far out, so the noisy end of a young curve gives no B or K
    young = curve(TAU[TAU <= 2e4], N, B, K, rel_ci=0.5)
    r = terms(young)
    assert r["B"]["kind"] == "upper" and "not significantly rising" in r["B"]["note"]
    assert r["K"]["value"] is None
    # without any limits (nulls) nothing is significant either
    bare = dict(curve(TAU, N, B, K), ci_low=[None] * TAU.size, ci_high=[None] * TAU.size)
    r = terms(bare)
    assert r["B"]["kind"] == "upper" and r["K"]["kind"] == "none"
    assert r["N"]["value"] == pytest.approx(N, rel=0.01)


def test_too_few_points_and_nulls() -> None:
    r = read_terms([0.01, 0.02, 0.04], [0.04, None, float("nan")])
    assert all(r[t]["value"] is None for t in "NBK")
    assert "1 tau(s)" in r["N"]["note"]


def test_datasheet_units_by_hand() -> None:
    c = curve(TAU, N, B, K)
    rows = {x["term"]: x for x in channel_readouts("gx", c)}
    r = terms(c)
    n_dps, b_dps, k_dps = (r[t]["value"] for t in "NBK")
    assert rows["N"]["unit"] == "mdps/√Hz"
    assert rows["N"]["value"] == pytest.approx(n_dps * 1000)
    assert f"({n_dps * 60:.3g} °/√h)" in rows["N"]["text"]  # ARW = N * 60
    assert rows["B"]["value"] == pytest.approx(b_dps * 3600)  # deg/h
    assert rows["K"]["value"] == pytest.approx(k_dps * 3600 * 60)  # deg/h/sqrt(h)

    acc = {x["term"]: x for x in channel_readouts("ax", curve(TAU, 8e-5, 3e-5, 1e-7,
                                                              units="g"))}
    assert acc["N"]["unit"] == "µg/√Hz"
    assert acc["N"]["value"] == pytest.approx(80.0, rel=0.01)
    assert "m/s/√h" in acc["N"]["text"]  # VRW = N g0 60
    assert acc["B"]["unit"] == "µg"


def test_unknown_units_stay_native() -> None:
    rows = {x["term"]: x for x in channel_readouts("gx", curve(TAU, N, B, K, units="rad/s"))}
    assert rows["N"]["unit"] == "rad/s/√Hz"
    assert rows["N"]["value"] == pytest.approx(N, rel=0.01)


def test_sensor_readouts_prefers_oadev_and_says_when_absent() -> None:
    c = curve(TAU, N, B, K)
    out = sensor_readouts({"mdev": {"gx": c}, "oadev": {"gx": c}})
    assert out["statistic"] == "oadev" and set(out["channels"]) == {"gx"}
    none = sensor_readouts({"mdev": {"gx": c}})
    assert none["statistic"] is None and "oadev" in none["note"]


def test_an_unestablished_floor_bounds_b_from_above() -> None:
    """White noise plus flicker B = 0.002 dps, 2 h at 100 Hz: while the floor is not
    established the reading is an upper bound, and it must lie above the true B (the
    least point / 0.664 read 0.37-0.75 of B on 9 of 20 seeds of a reviewer's 2 h
    records, 16 of 20 below B here: the lowest of many points lies low by chance)."""
    from lsm6ds_sim.model import NoiseModel
    from lsm6ds_sim.physics import simulate

    from imubench.stats import oadev

    model = NoiseModel.single_term("gx", white=0.004).with_channel("gx", flicker=0.002)
    below, uppers = 0, 0
    for seed in range(8):
        y = simulate(model, 720_000, 100.0, 100 + seed, channels=["gx"])["gx"]
        c = oadev(y, 100.0, "freq", "octave", confidence=0.95)
        b = read_terms(c.tau_s.tolist(), c.dev.tolist(), c.ci_low.tolist(),
                       c.ci_high.tolist(), c.alpha.tolist())["B"]
        if b["kind"] == "upper":
            uppers += 1
            below += b["value"] < 0.002
    assert uppers >= 1 and below == 0, (uppers, below)
