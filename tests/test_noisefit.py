"""Noise fit (issue 7): exact model AVAR, covariance model, round trip, tangent, units."""

from __future__ import annotations

import math
from pathlib import Path

import allantools
import numpy as np
import pytest
from lsm6ds_sim import noise
from lsm6ds_sim.model import ChannelModel, NoiseModel
from lsm6ds_sim.physics import simulate

from imubench.noisefit import ChannelFit, FitError, fit_channel, model_avar
from imubench.noisefit.covariance import oavar_correlation, oavar_edf
from imubench.noisefit.fit import TERM_NAMES, Structure, _cv_error, avar_points
from imubench.noisefit.identify import SLOPE_TABLE, identify
from imubench.noisefit.kernels import (
    apply_filter,
    avar_from_gacv,
    filter_autocorrelation,
    gacv_unit,
    term_avar,
)
from imubench.noisefit.spectral_line import line_test, segment_length
from imubench.noisefit.units import datasheet_units, kalibr_imu, kalibr_yaml
from imubench.stats import oadev

RATE = 100.0
M = np.array([1, 2, 4, 16, 256, 4096, 65536])
TAU = M / RATE


# ------------------------------------------------------------------ model AVAR vs closed forms
@pytest.mark.parametrize(
    ("keys", "analytic", "rtol"),
    [
        ({"white": 0.004}, lambda t: noise.avar_white(t, 0.004), 1e-12),
        ({"random_walk": 2e-4}, lambda t: noise.avar_random_walk(t, 2e-4), 1e-9),
        ({"ramp": 3e-3}, lambda t: noise.avar_ramp(t, 3e-3), 1e-9),
        ({"quantization": 0.01}, lambda t: noise.avar_quantization(t, 0.01), 1e-12),
        ({"sine_amplitude": 1.0, "sine_freq": 0.37},
         lambda t: noise.avar_sine_sampled(t, 1.0, 0.37, 1 / RATE), 1e-9),
    ],
)
def test_model_avar_equals_the_closed_forms(keys: dict[str, float], analytic, rtol: float) -> None:
    got = model_avar(ChannelModel(**keys), TAU, RATE)
    np.testing.assert_allclose(got, analytic(TAU), rtol=rtol)


def test_model_avar_flicker_and_markov_tend_to_the_continuous_forms() -> None:
    fl = model_avar(ChannelModel(flicker=1e-3), TAU, RATE) / noise.avar_flicker(TAU, 1e-3)
    # simulator doc: ADEV +20 % at m = 1, +2 % at m = 4, < 0.5 % from m = 16
    assert fl[0] ** 0.5 == pytest.approx(1.20, abs=0.01)
    assert fl[2] ** 0.5 == pytest.approx(1.02, abs=0.01)
    assert np.all(np.abs(fl[3:] ** 0.5 - 1) < 0.005)
    mk = model_avar(ChannelModel(markov_sigma=0.5, markov_tau=10.0), TAU, RATE)
    ratio = mk / noise.avar_markov(TAU, 0.5, 10.0)
    assert np.all(np.abs(ratio[3:] - 1) < 2e-3)  # simulator doc: < 0.2 % from m = 16
    assert ratio[0] == pytest.approx(1.5, rel=1e-3)  # ~1/(2 m^2) excess at m = 1


def test_model_avar_with_output_filter_matches_a_long_simulation() -> None:
    """Independent estimator: allantools OADEV of the simulator's filtered output."""
    cm = ChannelModel(white=0.004, quantization=2e-4, markov_sigma=0.02, markov_tau=0.5,
                      bandwidth_hz=8.0, filter_order=2, output_white=0.001)
    model = NoiseModel.quiet().with_channel("gx", **cm.to_dict())
    n = 400_000
    m = np.array([1, 2, 4, 8, 16, 64, 256, 1024])
    pred = model_avar(cm, m / RATE, RATE)
    unfiltered = model_avar(cm.replace(bandwidth_hz=0.0), m / RATE, RATE)
    assert pred[0] < 0.2 * unfiltered[0]  # the filter matters at short taus
    est = []
    for seed in (1, 2):
        y = simulate(model, n, RATE, seed, channels=["gx"])["gx"]
        _, dev, _, _ = allantools.oadev(y, rate=RATE, data_type="freq", taus=m / RATE)
        est.append(dev**2)
    ratio = np.mean(est, axis=0) / pred
    assert np.all(np.abs(ratio[:5] - 1) < 0.03), ratio
    assert np.all(np.abs(ratio[5:] - 1) < 0.15), ratio


def test_output_white_key_is_validated_and_round_trips(tmp_path) -> None:
    from lsm6ds_sim.model import load_model

    from imubench.errors import ModelError

    m = NoiseModel.single_term("gx", white=0.004, bandwidth_hz=20.0, output_white=0.002)
    p = tmp_path / "m.toml"
    p.write_text(m.to_toml())
    assert load_model(p)["gx"].output_white == 0.002
    p.write_text("[channels.gx]\noutput_white = -1.0\n")
    with pytest.raises(ModelError, match="output_white"):
        load_model(p)


def test_model_avar_rejects_bad_input() -> None:
    with pytest.raises(FitError, match="rate_hz"):
        model_avar(ChannelModel(white=1.0), [1.0], 0.0)
    with pytest.raises(FitError, match="tau_s"):
        model_avar(ChannelModel(white=1.0), [1.0, -2.0], 100.0)


# ------------------------------------------------------------------ covariance model
def test_oavar_correlation_matches_monte_carlo() -> None:
    """Correlation of OAVAR estimates across taus vs allantools over 300 white-noise runs."""
    rng = np.random.default_rng(7)
    n, ms = 4096, np.array([1, 2, 4, 8])
    est = []
    for _ in range(300):
        _, dev, _, _ = allantools.oadev(rng.standard_normal(n), rate=1.0, data_type="freq",
                                        taus=ms.astype(float))
        est.append(dev**2)
    emp = np.corrcoef(np.array(est).T)
    mod = oavar_correlation(ms, n - 2 * ms, {"white": 1.0}, 1.0)
    off = ~np.eye(ms.size, dtype=bool)
    # standard error of a correlation from 300 runs ~ 0.055
    assert np.all(np.abs(emp[off] - mod[off]) < 0.17), (emp, mod)
    assert mod[0, 1] > 0.1


def test_oavar_edf_matches_monte_carlo_on_a_mixture() -> None:
    """Model EDF 2 A^2 / Var(A) of white + random walk vs the spread of allantools OAVAR."""
    rng = np.random.default_rng(8)
    n, ms, k = 4096, np.array([1, 8, 64, 512]), 0.05
    est = []
    for _ in range(300):
        y = rng.standard_normal(n) + k * np.cumsum(rng.standard_normal(n))
        _, dev, _, _ = allantools.oadev(y, rate=1.0, data_type="freq", taus=ms.astype(float))
        est.append(dev**2)
    est_arr = np.array(est)
    emp_edf = 2.0 * est_arr.mean(0) ** 2 / est_arr.var(0, ddof=1)
    mod = oavar_edf(ms, n - 2 * ms, {"white": 1.0, "random_walk": k**2}, est_arr.mean(0), 1.0)
    # relative standard error of a variance from 300 chi2 runs with EDF >= 3: < 0.15
    assert np.all(np.abs(mod / emp_edf - 1.0) < 0.35), (mod, emp_edf)
    assert emp_edf[-1] < 20.0  # the longest point is far from Gaussian


# ------------------------------------------------------------------ round trip (short)
TRUTH = {"white": 0.002, "flicker": 0.0015, "random_walk": 4e-4}


@pytest.fixture(scope="module")
def short_fits() -> list[ChannelFit]:
    model = NoiseModel.single_term("gx", **TRUTH)
    out = []
    for seed in (11, 12, 13):
        y = simulate(model, 180_000, RATE, seed, channels=["gx"])["gx"]
        out.append(fit_channel(y, RATE, channel="gx"))
    return out


def test_round_trip_recovers_white_flicker_random_walk(short_fits: list[ChannelFit]) -> None:
    covered = 0
    for f in short_fits:
        assert f.params["white"] == pytest.approx(TRUTH["white"], rel=0.02)
        assert f.params["flicker"] == pytest.approx(TRUTH["flicker"], rel=0.4)
        assert f.params["random_walk"] == pytest.approx(TRUTH["random_walk"], rel=0.6)
        for key, v in TRUTH.items():
            lo, hi = f.ci[key]
            covered += lo <= v <= hi
    assert covered >= 7  # of 9 intervals (95 % each; P(<= 6) < 0.1 %)


def test_round_trip_reports_absent_terms_absent(short_fits: list[ChannelFit]) -> None:
    for key in ("ramp", "quantization", "markov_sigma", "sine_amplitude", "bandwidth_hz"):
        absent = [key not in f.present and f.params[key] == 0.0 for f in short_fits]
        assert sum(absent) >= 2, key  # a 5 % test: one false alarm in 3 is tolerated
    for f in short_fits:
        if "ramp" not in f.present:
            lo, hi = f.ci["ramp"]
            assert lo == 0.0 and hi > 0


def test_fit_finds_markov_and_filter() -> None:
    truth = {"white": 0.004, "markov_sigma": 0.01, "markov_tau": 2.0, "bandwidth_hz": 10.0,
             "filter_order": 2}
    y = simulate(NoiseModel.single_term("gx", **truth), 200_000, RATE, 5, channels=["gx"])["gx"]
    f = fit_channel(y, RATE)
    assert "markov_sigma" in f.present and "bandwidth_hz" in f.present
    assert f.params["markov_sigma"] == pytest.approx(0.01, rel=0.25)
    lo, hi = f.ci["markov_tau"]
    assert lo <= 2.0 <= hi
    assert f.params["bandwidth_hz"] == pytest.approx(10.0, rel=0.1)
    assert f.params["filter_order"] == 2
    # the fitted model predicts the measured curve
    ratio = f.model_avar(f.tau_s) / f.avar
    assert np.all(np.abs(np.log(ratio[:10])) < 0.1)


def test_fit_with_a_term_list_keeps_exactly_those_terms() -> None:
    y = simulate(NoiseModel.single_term("gx", white=0.004), 100_000, RATE, 3,
                 channels=["gx"])["gx"]
    f = fit_channel(y, RATE, terms="white,flicker")
    assert set(f.present) <= {"white", "flicker"}
    assert f.params["white"] == pytest.approx(0.004, rel=0.02)
    cm = f.channel_model()
    assert cm.white == f.params["white"] and cm.random_walk == 0.0


def test_fit_bad_input_errors() -> None:
    y = np.random.default_rng(0).standard_normal(10_000)
    with pytest.raises(FitError, match="unknown term"):
        fit_channel(y, RATE, terms="white,pink")
    with pytest.raises(FitError, match="unknown method"):
        fit_channel(y, RATE, method="magic")
    with pytest.raises(FitError, match="at least 64"):
        fit_channel(y[:10], RATE)
    with pytest.raises(FitError, match="constant"):
        fit_channel(np.ones(1000), RATE)
    with pytest.raises(FitError, match="rate_hz"):
        fit_channel(y, -1.0)
    with pytest.raises(FitError, match="1-D"):
        fit_channel(y.reshape(100, 100), RATE)


# ------------------------------------------------------------------ tangent
def test_tangent_method_on_single_terms() -> None:
    n = 200_000
    y = simulate(NoiseModel.single_term("gx", white=0.004), n, RATE, 1, channels=["gx"])["gx"]
    t = fit_channel(y, RATE, method="tangent")
    # pure white: sigma(tau) sqrt(tau) = N at every tau; the minimum is read, so slightly low
    assert t.params["white"] == pytest.approx(0.004, rel=0.02)
    lo, hi = t.ci["white"]
    assert lo < t.params["white"] < hi
    y = simulate(NoiseModel.single_term("gx", flicker=0.002), n, RATE, 2, channels=["gx"])["gx"]
    t = fit_channel(y, RATE, method="tangent")
    # pure flicker: read where the curve rises significantly after its floor, else
    # bounded from above (the live view's rule), the bound above the truth and near it
    assert t.method == "tangent"
    if "flicker" in t.present:
        assert t.params["flicker"] == pytest.approx(0.002, rel=0.25)
    else:
        assert 0.002 <= t.ci["flicker"][1] <= 0.002 * 1.4
    # white noise alone shows neither a floor nor a +1/2 slope: flicker and random walk
    # are absent with upper limits (they were read off the falling curve as present)
    y = simulate(NoiseModel.single_term("gx", white=0.004), 360_000, RATE, 4,
                 channels=["gx"])["gx"]
    t = fit_channel(y, RATE, method="tangent")
    assert t.present == ("white",), t.notes
    assert t.params["flicker"] == 0.0 and t.ci["flicker"][0] == 0.0
    assert t.params["random_walk"] == 0.0 and t.ci["random_walk"][1] > 0.0


# ------------------------------------------------------------------ identification
def test_slope_table_and_identification() -> None:
    rows = {r[1]: r for r in SLOPE_TABLE}
    assert rows["white PM"][3:] == (-1.0, -1.5, -0.5)
    assert rows["random-walk FM"][3:] == (0.5, 0.5, 1.5)
    y = simulate(NoiseModel.single_term("gx", white=0.004), 100_000, RATE, 4,
                 channels=["gx"])["gx"]
    ids = identify(y, RATE)
    assert all(r.alpha == 0 for r in ids[:8])
    assert all(abs(r.adev_slope + 0.5) < 0.1 for r in ids[:8])
    assert ids[2].name == "angle/velocity random walk"
    q = simulate(NoiseModel.single_term("gx", quantization=0.01), 100_000, RATE, 4,
                 channels=["gx"])["gx"]
    assert identify(q, RATE)[3].name == "quantization"


def test_filtered_term_avar_equals_the_direct_convolution() -> None:
    """The short-lag form of term_avar with a filter vs filtering the whole G(k)."""
    m = np.array([1, 3, 10, 100, 1000, 20000])
    for term in ("white", "flicker", "random_walk", "ramp", "markov"):
        for bw, order in ((1.0, 1), (20.0, 2)):
            rho = filter_autocorrelation(bw, order, RATE)
            g = gacv_unit(term, 2 * int(m.max()) + rho.size, 1.0 / RATE, tau_c_s=3.0)
            direct = avar_from_gacv(apply_filter(g, rho, multiplicative=term == "markov"), m)
            fast = term_avar(term, m, RATE, tau_c_s=3.0, bandwidth_hz=bw, filter_order=order)
            np.testing.assert_allclose(fast, direct, rtol=1e-8, err_msg=f"{term} {bw} {order}")


def test_cross_validation_prefers_the_term_the_data_have() -> None:
    """Two-fold CV error: white + random walk data are predicted better with the walk."""
    y = simulate(NoiseModel.single_term("gx", white=0.004, random_walk=1e-3), 200_000, RATE,
                 21, channels=["gx"])["gx"]
    half = y.size // 2
    halves = [avar_points(h, RATE, None, "cv") for h in (y[:half], y[half:])]
    e_white = _cv_error(Structure(("white",)), halves)
    e_both = _cv_error(Structure(("white", "random_walk")), halves)
    assert e_both < 0.5 * e_white, (e_both, e_white)


def test_sinusoid_does_not_bring_a_spurious_flicker() -> None:
    truth = {"white": 0.004, "sine_amplitude": 0.01, "sine_freq": 0.5}
    y = simulate(NoiseModel.single_term("gx", **truth), 100_000, RATE, 9, channels=["gx"])["gx"]
    f = fit_channel(y, RATE)
    assert "sine_amplitude" in f.present and "flicker" not in f.present
    lo, hi = f.ci["sine_freq"]
    assert lo <= 0.5 <= hi


def _adis(reference_dir: Path, rep: int, channel: str) -> np.ndarray:
    """One channel of an ADIS16405 reference replicate in dps or g (skips when absent)."""
    path = reference_dir / "imu-real" / "adis16405" / f"adis16405_rep{rep}.npz"
    if not path.is_file():
        pytest.skip("ADIS16405 reference data not present")
    d = np.load(path)
    axis = "xyz".index(channel[1])
    if channel[0] == "g":
        return d["gyro_counts"][:, axis].astype(float) * float(d["gyro_lsb_dps"])
    return d["accel_counts"][:, axis].astype(float) * float(d["accel_lsb_g"])


def test_a_filtered_markov_column_is_exact_where_its_tail_underflows(reference_dir) -> None:
    """Gauss-Markov tau_c 0.345 s through an order-2 0.2 Hz filter at 10 Hz (the filter's
    autocorrelation is ~200 lags long, phi^J ~ 1e-38): the column was the difference of
    two numbers near 1e38 and came out as -2, 8, 4, -8 (a chi2 that jumped by 9 between
    tau_c values one rounding apart, and a crash of the profile search on the Samsung S5
    gy middle third). It now equals the direct filtered sum."""
    m = 2 ** np.arange(12)
    for tau_c in (0.3451284914746671, 0.3451284914746672, 5.0):
        col = term_avar("markov", m, 10.0, tau_c_s=tau_c, bandwidth_hz=0.2, filter_order=2)
        rho = filter_autocorrelation(0.2, 2, 10.0)
        g = gacv_unit("markov", 2 * int(m.max()) + rho.size, 0.1, tau_c_s=tau_c)
        direct = avar_from_gacv(apply_filter(g, rho, multiplicative=True), m)
        np.testing.assert_allclose(col, direct, rtol=1e-9)
    path = reference_dir / "imu-real" / "samsung-s5-static" / "samsung_galaxy_s5_static.npz"
    if not path.is_file():
        pytest.skip("Samsung S5 reference data not present")
    z = np.load(path)
    gy = np.degrees(z["gyro_measured_rad_s"][:, 1])
    n = gy.size // 3
    f = fit_channel(gy[n:2 * n], float(z["fs_hz"]), channel="gy")
    assert f.present


def test_adis_output_filter_is_found_at_its_bandwidth_and_the_first_octave_fits(
        reference_dir) -> None:
    """ADIS16405 rep 2 gx: an order-1 output filter had fitted alike at any bandwidth from
    the search floor up to ~25 Hz beside a quantization term chosen at the floor's
    bandwidth; dropping the filter left a model 16 % off the measured ADEV at tau0. With
    the bandwidth searched again for each set of base terms it is found at 25 Hz (as on
    every gx and gy of the three replicates, 24-25.3 Hz) with a narrow interval, and the
    model meets the first octaves."""
    y = _adis(reference_dir, 2, "gx")
    f = fit_channel(y, 100.0, channel="gx")
    assert "bandwidth_hz" in f.present, f.reasons["filter"]
    lo, hi = f.ci["bandwidth_hz"]
    assert 20.0 < lo < f.params["bandwidth_hz"] < hi < 30.0, (lo, hi)
    meas = oadev(y, 100.0, "freq", [0.01, 0.02, 0.04])
    np.testing.assert_allclose(meas.dev, np.sqrt(f.model_avar(meas.tau_s)), rtol=0.01)
    # the datasheet density is white before and after the filter together (white alone
    # was 0.028, 30 % below the -1/2 line): ADEV(1 s) less the flicker floor's share
    n = datasheet_units("gx", f.params)["noise_density_mdps_per_sqrt_hz"] / 1000
    one = oadev(y, 100.0, "freq", [1.0]).dev[0]
    floor = 0.664 * f.params["flicker"]
    assert n == pytest.approx(math.sqrt(one**2 - floor**2), rel=0.05)
    lo, hi = f.ci["white_equivalent"]
    assert lo < n < hi and hi / lo < 1.2


def test_losing_an_extension_does_not_inflate_the_discrepancy_floor(reference_dir) -> None:
    """ADIS16405 rep 3 ay: the Markov term fails its tau_c check after the base terms are
    chosen. Re-estimating the discrepancy floor for the model without it gave 0.26 (from
    0.037), after which white, the filter and the 0.54 Hz line all fell out and the model
    was 23 % off at tau0. The reference's floor is kept: the model follows the curve."""
    y = _adis(reference_dir, 3, "ay")
    f = fit_channel(y, 100.0, channel="ay")
    assert {"white", "bandwidth_hz", "sine_amplitude"} <= set(f.present), f.reasons
    meas = oadev(y, 100.0, "freq", "octave")
    keep = meas.tau_s <= 350.0
    ratio = meas.dev[keep] / np.sqrt(f.model_avar(meas.tau_s[keep]))
    assert np.all(np.abs(np.log(ratio)) < 0.08), ratio


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="issue 14: with the stricter model selection the rep1 "
                   "model beats rep1's raw curve on 8/12 cases (was 10/12; 7/12 before the "
                   "resonance term held gz's 20 Hz peak): the gyros' weak long-tau rise (gx, "
                   "gy) is not modelled and rep 3's gz long-tau level is below rep 1's; "
                   "bench/bench_fit_acceptance.py --part 3, docs/benchmarks.md")
def test_adis16405_model_generalises_to_replicates_2_and_3(reference_dir) -> None:
    """Acceptance item 2: the rep1 model predicts reps 2/3 as well as rep1's raw OADEV."""
    folder = reference_dir / "imu-real" / "adis16405"
    if not folder.is_dir():
        pytest.skip("ADIS16405 reference data not present")
    reps = {}
    for r in (1, 2, 3):
        d = np.load(folder / f"adis16405_rep{r}.npz")
        g = d["gyro_counts"].astype(float) * float(d["gyro_lsb_dps"])
        a = d["accel_counts"].astype(float) * float(d["accel_lsb_g"])
        reps[r] = dict(zip(("gx", "gy", "gz", "ax", "ay", "az"), np.column_stack([g, a]).T,
                           strict=True))
    passed = total = 0
    for ch in ("gx", "gy", "gz", "ax", "ay", "az"):
        f = fit_channel(reps[1][ch], 100.0, channel=ch)
        r1 = oadev(reps[1][ch], 100.0, "freq", "octave")
        keep = r1.tau_s <= reps[1][ch].size / 100.0 / 10
        pred = np.sqrt(f.model_avar(r1.tau_s[keep]))
        for r in (2, 3):
            meas = oadev(reps[r][ch], 100.0, "freq", list(r1.tau_s[keep])).dev
            e_model = np.sqrt(np.mean(np.log(meas / pred) ** 2))
            e_raw = np.sqrt(np.mean(np.log(meas / r1.dev[keep]) ** 2))
            passed += e_model <= 1.1 * e_raw
            total += 1
    assert passed >= 0.8 * total, f"{passed}/{total}"


# ------------------------------------------------------------------ units
def test_datasheet_units_hand_computed() -> None:
    g = datasheet_units("gx", {"white": 0.004, "flicker": 0.001, "random_walk": 1e-4})
    assert g["arw_deg_per_sqrt_h"] == pytest.approx(0.24)  # 0.004 deg/sqrt(s) * 60
    assert g["noise_density_mdps_per_sqrt_hz"] == pytest.approx(4.0)
    assert g["bias_instability_deg_per_h"] == pytest.approx(3.6)
    assert g["adev_floor_deg_per_h"] == pytest.approx(3.6 * 0.664282, rel=1e-5)
    assert g["rrw_deg_per_h_per_sqrt_h"] == pytest.approx(21.6)  # 1e-4 * 3600 * 60
    a = datasheet_units("az", {"white": 8e-5, "flicker": 3e-5, "random_walk": 2e-6})
    assert a["noise_density_ug_per_sqrt_hz"] == pytest.approx(80.0)
    assert a["vrw_m_per_s_per_sqrt_h"] == pytest.approx(8e-5 * 9.80665 * 60)  # 0.0470719
    assert a["bias_instability_ug"] == pytest.approx(30.0)
    assert a["random_walk_ug_per_sqrt_s"] == pytest.approx(2.0)
    with pytest.raises(FitError, match="unknown channel"):
        datasheet_units("temp", {})


def test_kalibr_values_hand_computed() -> None:
    params = {"gx": {"white": 0.004, "random_walk": 1e-4},
              "gy": {"white": 0.005, "random_walk": 2e-5},
              "az": {"white": 8e-5, "random_walk": 2e-6}}
    k = kalibr_imu(params, 104.0)
    assert k["gyroscope_noise_density"] == pytest.approx(0.005 * math.pi / 180)  # 8.7266e-5
    assert k["gyroscope_random_walk"] == pytest.approx(1e-4 * math.pi / 180)
    assert k["accelerometer_noise_density"] == pytest.approx(7.84532e-4)
    assert k["accelerometer_random_walk"] == pytest.approx(1.96133e-5)
    assert k["update_rate"] == 104.0
    text = kalibr_yaml(k)
    assert "gyroscope_noise_density: 8.726646e-05" in text
    assert "update_rate: 1.040000e+02" in text
    assert k["markov_folded"] == {}


def test_kalibr_folds_a_slow_markov_term_into_the_random_walk() -> None:
    """Kalibr has no Gauss-Markov term: one too slow to count in N (tau_c 30 s) enters the
    bias random walk as sigma sqrt(2 / tau_c), the walk it is over short times, whose
    spectrum bounds it; the density stays the white level (folded into it as
    sigma sqrt(2 tau_c) it was 10-27x the measured white level)."""
    params = {"gx": {"white": 0.004, "random_walk": 1e-4, "markov_sigma": 0.04,
                     "markov_tau": 30.0},
              "gy": {"white": 0.005, "random_walk": 2e-5},
              "az": {"white": 8e-5, "random_walk": 2e-6}}
    k = kalibr_imu(params, 10.0)
    assert k["gyroscope_noise_density"] == pytest.approx(0.005 * math.pi / 180)
    walk = math.hypot(1e-4, 0.04 * math.sqrt(2 / 30.0))
    assert k["gyroscope_random_walk"] == pytest.approx(walk * math.pi / 180)
    assert k["markov_folded"] == {"gyroscope_random_walk": ["gx"]}
    assert "holds the Gauss-Markov term of gx" in kalibr_yaml(k)
    # the folded walk's spectrum bounds the Markov term's at every frequency
    f = np.geomspace(1e-5, 5.0, 200)
    markov = 2 * 0.04**2 * 30.0 / (1 + (2 * math.pi * f * 30.0) ** 2)
    assert np.all((0.04 * math.sqrt(2 / 30.0)) ** 2 / (2 * math.pi * f) ** 2 >= markov)


# ------------------------------------------------------------------ model selection (issue 14)
def test_line_test_ratio_matches_the_hann_line_formula() -> None:
    """A line of amplitude A at a bin centre over white noise N: ratio 1 + A^2 L/(6 N^2 fs)
    (one-sided white PSD 2 N^2, line power A^2/2 over the Hann ENBW 1.5 fs / L)."""
    rate, n, white = 100.0, 2**18, 0.004
    length = segment_length(n, rate, 1.0)
    assert length is not None
    f0 = 40 * rate / length  # bin centre
    amp = 0.002
    t = np.arange(n) / rate
    y = simulate(NoiseModel.single_term("gx", white=white), n, rate, 31, channels=["gx"])["gx"]
    res = line_test(y + amp * np.sin(2 * np.pi * f0 * t), rate, f0, f0)
    expected = 1 + amp**2 * length / (6 * white**2 * rate)
    assert res.present and res.freq_hz == pytest.approx(f0)
    assert res.ratio == pytest.approx(expected, rel=0.35)  # one chi2_2K bin, K = 8..32
    null = line_test(y, rate, f0, f0)
    assert not null.present and null.ratio < null.threshold
    assert "no spectral line at" in null.describe()


def test_no_sine_on_white_and_flicker_but_a_real_line_is_found() -> None:
    wf = {"white": 0.004, "flicker": 0.0015}
    for seed in (41, 42):
        y = simulate(NoiseModel.single_term("gx", **wf), 120_000, RATE, seed,
                     channels=["gx"])["gx"]
        f = fit_channel(y, RATE)
        assert "sine_amplitude" not in f.present, f.reasons["sine"]
        assert f.reasons["sine"].startswith("dropped")
    y = simulate(NoiseModel.single_term("gx", **wf, sine_amplitude=0.004, sine_freq=3.0),
                 120_000, RATE, 43, channels=["gx"])["gx"]
    f = fit_channel(y, RATE)
    assert "sine_amplitude" in f.present, f.reasons["sine"]
    assert f.params["sine_freq"] == pytest.approx(3.0, rel=0.02)
    assert "spectral line at" in f.reasons["sine"] and f.reasons["sine"].startswith("kept")


def test_a_term_whose_interval_includes_zero_is_not_reported() -> None:
    """Quantization far below detection: absent, with a reason and an upper limit; every
    term reported has a 95 % interval that excludes 0."""
    y = simulate(NoiseModel.single_term("gx", white=0.004, flicker=0.001, quantization=2e-6),
                 120_000, RATE, 44, channels=["gx"])["gx"]
    f = fit_channel(y, RATE)
    assert "quantization" not in f.present
    assert f.reasons["quantization"].startswith("dropped")
    lo, hi = f.ci["quantization"]
    assert lo == 0.0 and hi > 2e-6
    for key in f.present:
        if key in ("white", "flicker", "random_walk", "ramp", "quantization",
                   "markov_sigma", "sine_amplitude"):
            assert f.ci[key][0] > 0, (key, f.ci[key])


def test_reasons_cover_every_term_and_reach_the_json() -> None:
    y = simulate(NoiseModel.single_term("gx", white=0.004, random_walk=5e-4), 120_000, RATE,
                 45, channels=["gx"])["gx"]
    f = fit_channel(y, RATE)
    assert set(f.reasons) == set(TERM_NAMES)
    assert f.reasons["white"].startswith("kept") and f.reasons["random_walk"].startswith("kept")
    assert all(w.startswith(("kept", "dropped")) for w in f.reasons.values())
    assert f.to_dict()["reasons"] == f.reasons
    explicit = fit_channel(y, RATE, terms="white,random_walk")
    assert set(explicit.reasons) == {"white", "random_walk"}


def _sim_recording(tmp_path):
    import subprocess
    import sys

    src = tmp_path / "a.imbr"
    subprocess.run([sys.executable, "-m", "imubench", "sim", "--chip", "lsm6dsl",
                    "--duration-s", "300", "--model", "datasheet:lsm6dsl", "--out", str(src)],
                   check=True, capture_output=True)
    return src


@pytest.mark.parametrize("channels", [
    ("gz",), pytest.param(("gy", "az"), marks=pytest.mark.slow)])
def test_fit_does_not_depend_on_last_bits_or_format(tmp_path, channels):
    """1-ulp changes of the samples (and the CSV round trip) leave the fit unchanged to
    1e-6: the filtered Gauss-Markov column of the model search used to divide FFT
    round-off by G(k1) ~ 1e-90, a column ~1e60 off that made chi2 jump between settings.
    (gz by default; gy and az, the other channels whose fits moved, with -m slow.)"""
    from imubench.recording import convert, load_recording

    src = _sim_recording(tmp_path)
    convert(src, tmp_path / "a.csv")
    rec = load_recording(src)
    csv = load_recording(tmp_path / "a.csv")
    for ch in channels:  # the channels whose fits moved by 0.1-1 % before
        y = rec.channel(ch)
        variants = (np.nextafter(y, np.inf), csv.channel(ch))
        ref = fit_channel(y, rec.rate_hz, channel=ch)
        for other in variants:
            got = fit_channel(other, rec.rate_hz, channel=ch)
            assert got.present == ref.present, ch
            for key, value in ref.params.items():
                assert got.params[key] == pytest.approx(value, rel=1e-6, abs=1e-300), (ch, key)


def test_filtered_markov_column_is_exact_far_beyond_the_filter():
    """term_avar of a filtered Gauss-Markov term equals the direct convolution even where
    G(k) = phi^k is far below round-off (tau_c of a few samples, long filter)."""
    rho = filter_autocorrelation(46.8, 2, 104.0)
    m = np.array([1, 4, 64, 1024, 4096])
    for tc in (0.0323, 0.0338, 0.3):
        g = gacv_unit("markov", 2 * 4096 + rho.size + 1, 1 / 104.0, tau_c_s=tc)
        direct = avar_from_gacv(apply_filter(g, rho, multiplicative=True), m)
        # the exact convolution at every lag (no tail rule)
        j = rho.size - 1
        full = np.convolve(np.concatenate([g[j:0:-1], g]),
                           np.concatenate([rho[:0:-1], rho]), mode="valid")
        exact = avar_from_gacv(full, m)
        got = term_avar("markov", m, 104.0, tau_c_s=tc, bandwidth_hz=46.8, filter_order=2)
        np.testing.assert_allclose(direct, exact, rtol=1e-9)
        np.testing.assert_allclose(got, exact, rtol=1e-9)


def test_kalibr_mixed_detection_names_the_axes_and_units() -> None:
    """ay detected the accelerometer random walk, ax and az did not: the value written is
    the largest over the axes (here az's upper limit), and the note names the axes, says
    which value was written and carries Kalibr's unit; the file ends with a newline."""
    from imubench.noisefit.units import kalibr_limit_message

    params = {"gx": {"white": 0.004, "random_walk": 1e-4},
              "ax": {"white": 8e-5}, "ay": {"white": 8e-5, "random_walk": 1e-6},
              "az": {"white": 8e-5}}
    limits = {"ax": {"random_walk": 2e-6}, "ay": {}, "az": {"random_walk": 3e-6}}
    k = kalibr_imu(params, 104.0, upper_limits=limits)
    assert k["upper_limits"] == ["accelerometer_random_walk"]
    assert k["not_detected"] == {"accelerometer_random_walk": ["ax", "az"]}
    assert k["detected"] == {"accelerometer_random_walk": ["ay"]}
    assert k["accelerometer_random_walk"] == pytest.approx(3e-6 * 9.80665)
    msg = kalibr_limit_message("imu.yaml", k, "accelerometer_random_walk")
    assert "not detected on ax, az (detected on ay)" in msg
    assert "largest value over the axes, the upper 95 % confidence limit of az" in msg
    assert "m/s^3/sqrt(Hz)" in msg and "\n" not in msg
    assert kalibr_yaml(k).endswith("\n")
    gyro = kalibr_imu({"gx": {"white": 0.004}, "ax": {"white": 8e-5, "random_walk": 1e-6}},
                      104.0, upper_limits={"gx": {"random_walk": 5e-5}})
    assert "rad/s^2/sqrt(Hz)" in kalibr_limit_message("k.yaml", gyro, "gyroscope_random_walk")


def test_kalibr_refuses_one_sensor_only() -> None:
    with pytest.raises(FitError, match="accelerometer_noise_density, accelerometer_random_walk"):
        kalibr_imu({"gx": {"white": 0.004, "random_walk": 1e-4}}, 104.0)
    with pytest.raises(FitError, match=r"no gyro \(gx gy gz\) axis was fitted"):
        kalibr_imu({"az": {"white": 8e-5, "random_walk": 1e-6}}, 104.0)


def test_peak_test_finds_a_resonance_and_not_a_filter_roll_off() -> None:
    """A 2 Hz wide band-pass resonance at 20 Hz (scipy's iirpeak on white noise, 100 Hz)
    is a peak, not a line; white noise and a first-order 15 Hz low-pass roll-off are
    neither."""
    from scipy.signal import butter, iirpeak, lfilter

    from imubench.noisefit.spectral_line import peak_test

    rng = np.random.default_rng(5)
    n, fs = 360_000, 100.0
    white = rng.standard_normal(n)
    b, a = iirpeak(20.0, 20.0 / 2.0, fs)
    res = white + 3.0 * lfilter(b, a, rng.standard_normal(n))
    found = peak_test(res, fs, 16.0, 25.0)
    assert found is not None and found.present, found
    assert abs(found.freq_hz - 20.0) < 0.3 and 0.5 < found.width_hz < 4.0
    assert not line_test(res, fs, 16.0, 25.0).present
    for y in (white, lfilter(*butter(1, 15.0, fs=fs), white)):
        null = peak_test(y, fs, 16.0, 25.0)
        assert null is not None and not null.present, null


def test_a_resonance_is_fitted_where_the_sine_has_no_line(reference_dir) -> None:
    """ADIS16405 rep 1 gz has a ~1.6 Hz wide resonance near 20 Hz (ADEV at 0.02 s above
    that at 0.01 s). It is no sine (no spectral line there): the resonance term holds it,
    and its reason names the peak it was tried at (tests/test_resonance.py checks the
    misfit it leaves)."""
    y = _adis(reference_dir, 1, "gz")
    f = fit_channel(y, 100.0, channel="gz")
    assert "sine_amplitude" not in f.present
    assert "resonance_height" in f.present, f.reasons["resonance"]
    why = f.reasons["resonance"]
    assert why.startswith("kept") and ("narrowband peak at 2" in why
                                       or "narrowband peak at 19" in why), why


def test_white_equivalent_density_hand_computed() -> None:
    """N = sqrt(white^2 + output_white^2 + 2 sigma^2 tau_c) for a Markov term with
    tau_c <= 10 s (IEEE 952 C.6: its AVAR tends to 2 sigma^2 tau_c / tau)."""
    from imubench.noisefit.units import white_equivalent

    assert white_equivalent({"white": 0.03, "output_white": 0.04}) == pytest.approx(0.05)
    fast = {"white": 0.03, "markov_sigma": 0.1, "markov_tau": 0.05}
    assert white_equivalent(fast) == pytest.approx(math.sqrt(0.0009 + 2 * 0.01 * 0.05))
    slow = {"white": 0.03, "markov_sigma": 0.1, "markov_tau": 50.0}
    assert white_equivalent(slow) == pytest.approx(0.03)
    filtered = {"markov_sigma": 0.036, "markov_tau": 1.4}  # a phone's low-passed gyro
    assert white_equivalent(filtered) == pytest.approx(0.036 * math.sqrt(2.8))
    assert datasheet_units("gx", {"white": 0.03, "output_white": 0.04})[
        "arw_deg_per_sqrt_h"] == pytest.approx(3.0)
    # a Markov term at tau_c = 0.05 s really is white at tau >= 1 s: its exact AVAR
    tau = np.array([1.0, 4.0, 16.0])
    cm = NoiseModel.single_term("gx", **fast)["gx"]
    np.testing.assert_allclose(np.sqrt(model_avar(cm, tau, 100.0) * tau),
                               white_equivalent(fast), rtol=0.03)


def test_fit_of_a_real_record_whose_model_correlation_is_not_positive_definite(
        reference_dir) -> None:
    """Samsung S5 accelerometer y, second 1.99 h segment (10 Hz): the OAVAR correlation of
    a Markov + random-walk structure had an eigenvalue of -0.018 (pairs beyond MAX_RATIO
    left at zero, the 0.999 clip), and `fit` ended in numpy's LinAlgError. The
    correlation is now made positive definite, and the fit finds the Markov term of its
    neighbouring segments (tau_c ~1.2 s there)."""
    path = reference_dir / "imu-real" / "samsung-s5-static" / "samsung_galaxy_s5_static.npz"
    if not path.is_file():
        pytest.skip("Samsung S5 reference data not present")
    z = np.load(path)
    ay = z["accel_m_s2"][:, 1] / 9.80665
    n = len(ay) // 3
    f = fit_channel(ay[n:2 * n], float(z["fs_hz"]), terms="auto", channel="ay")
    assert "markov_sigma" in f.present
    assert 0.5 < f.params["markov_tau"] < 3.0


@pytest.mark.parametrize("axis", [0, 1])
def test_a_markov_term_is_not_excluded_for_a_filter_pinned_beside_it(
        reference_dir, axis: int) -> None:
    """Samsung S5 gyro x and y, first 1.99 h segment (10 Hz): the extension search put a
    Gauss-Markov term (chi2 drop 487 on x) beside an output filter pinned at its lowest
    bandwidth (0.2 Hz); the Markov tau_c's profile was degenerate there (0.404 s
    [0.404, 0.404]), the term was excluded first, then the filter, and the model was
    flicker alone, 89 % (rms) from the Allan curve. The pinned filter is now searched
    above its floor first; the model keeps the Markov term of z's (tau_c ~1.3 s) and
    fits within half the old discrepancy."""
    path = reference_dir / "imu-real" / "samsung-s5-static" / "samsung_galaxy_s5_static.npz"
    if not path.is_file():
        pytest.skip("Samsung S5 reference data not present")
    z = np.load(path)
    g = np.degrees(z["gyro_measured_rad_s"][:, axis])
    f = fit_channel(g[:len(g) // 3], float(z["fs_hz"]), terms="auto", channel=("gx", "gy")[axis])
    assert "markov_sigma" in f.present
    assert 0.5 < f.params["markov_tau"] < 3.0
    assert not any("misses the Allan curve broadly" in n for n in f.notes)
    # the filter's reason is the search above the floor's, not the refusal at the floor
    # that this search replaced ("0.2 Hz is the lowest searched")
    assert f.reasons["filter"].startswith("dropped, chi2 drop"), f.reasons["filter"]


def test_model_correlation_is_a_positive_definite_correlation_matrix() -> None:
    """Whatever the structure, oavar_correlation returns unit diagonal, symmetric, and
    eigenvalues >= its floor. The structure the S5 ay fit tried (10 Hz, octave taus, white
    + flicker + Markov + a narrow resonance at 0.195 Hz) gave -0.018 before."""
    from imubench.noisefit.covariance import CORR_EIG_FLOOR

    m = 2 ** np.arange(15)
    n_terms = 71601 - 2 * m
    amp2 = {"white": 4.78e-9, "flicker": 2.75e-8, "markov": 3.88e-7, "resonance": 7.97e-6}
    c = oavar_correlation(m, n_terms, amp2, 10.0, tau_c_s=2.0,
                          resonance=(0.1953, 0.009766))
    assert np.allclose(np.diag(c), 1.0) and np.allclose(c, c.T)
    assert np.linalg.eigvalsh(c).min() >= 0.5 * CORR_EIG_FLOOR


def test_block_increment_covariance_matches_closed_forms() -> None:
    """Increments of m-sample block means: white noise (variance s^2 per sample) has
    variance 2 s^2 / m, lag-1 covariance -s^2 / m and nothing beyond; a random walk of
    density K has K^2 m tau0 (2/3, 1/6, 0) (the continuous-time block averages); lag 0
    is twice the model's AVAR at m for any model (a resonance's included)."""
    from lsm6ds_sim.model import ChannelModel

    from imubench.noisefit.model_avar import block_increment_acv, model_avar_m

    fs, m = 104.0, 500
    white = block_increment_acv(ChannelModel().replace(white=0.004), m, 4, fs)
    s2 = 0.004**2 * fs
    np.testing.assert_allclose(white, [2 * s2 / m, -s2 / m, 0.0, 0.0], atol=1e-15)
    rw = block_increment_acv(ChannelModel().replace(random_walk=1e-4), m, 4, fs)
    q = 1e-8 * m / fs
    np.testing.assert_allclose(rw, [2 * q / 3, q / 6, 0.0, 0.0], rtol=1e-5, atol=1e-9 * q)
    full = ChannelModel().replace(white=0.004, flicker=0.0008, random_walk=1e-4,
                                  markov_sigma=0.002, markov_tau=5.0, output_white=2e-4,
                                  bandwidth_hz=20.0, filter_order=2, resonance_height=3e-4,
                                  resonance_freq_hz=5.0, resonance_width_hz=1.0)
    lag0 = block_increment_acv(full, m, 3, fs)[0]
    np.testing.assert_allclose(lag0, 2 * model_avar_m(full, np.array([m]), fs)[0], rtol=1e-6)
    with pytest.raises(FitError, match="n_lags 0"):
        block_increment_acv(full, m, 0, fs)


def test_terms_the_data_do_not_split_are_named() -> None:
    """Estimates that correlate beyond 0.9 get a note that only their joint effect is
    fixed; moderately correlated ones do not."""
    from imubench.noisefit.fit import entangled_terms

    cov = np.array([[1.0, -0.95, 0.2], [-0.95, 1.0, 0.1], [0.2, 0.1, 4.0]])
    notes = entangled_terms(("white", "output_white", "random_walk"), cov)
    assert len(notes) == 1 and notes[0].startswith("white and output_white are not "
                                                   "separately identified (their "
                                                   "estimates correlate -0.95)")


def test_an_unidentified_filter_bandwidth_is_named_on_a_real_record(reference_dir) -> None:
    """ADIS16405 rep 1 gx, first hour, fitted with white, flicker, quantization and a
    filter asked for (the terms the automatic selection chose before it searched the
    bandwidth again per set of base terms): the bandwidth interval spans 0.008-49 Hz, and
    the white / quantization split moved beyond its intervals when one sample was lost;
    the fit says that its intervals are linearised about the fitted bandwidth only."""
    path = reference_dir / "imu-real" / "adis16405" / "adis16405_rep1.npz"
    if not path.is_file():
        pytest.skip("ADIS16405 reference data not present")
    d = np.load(path)
    y = d["gyro_counts"][:360_000, 0] * float(d["gyro_lsb_dps"])
    fit = fit_channel(y, float(d["fs_hz"]), channel="gx",
                      terms="white,flicker,quantization,filter")
    assert "bandwidth_hz" in fit.present
    lo, hi = fit.ci["bandwidth_hz"]
    assert hi / lo > 10
    assert any(n.startswith("the output filter's bandwidth is not identified")
               for n in fit.notes), fit.notes


def test_a_degenerate_profile_does_not_identify_a_setting() -> None:
    """A profile interval of zero width ([1.991, 1.991] s for tau_c on the whole,
    non-stationary CATS record) is the optimiser's, not the data's: the term is dropped
    with that reason, not kept as perfectly identified; a real interval inside the
    data's taus keeps it."""
    from types import SimpleNamespace
    from typing import Any, cast

    from imubench.noisefit.fit import _extension_verdict

    st = cast(Any, SimpleNamespace(tau_c_s=1.991))
    pts = cast(Any, SimpleNamespace(tau_s=np.geomspace(1.0, 6.5e4, 17), rate_hz=1.0))
    ok, why, _ = _extension_verdict("markov", st, cast(Any, None),
                                    {"markov_tau": (1.9905, 1.9915)}, pts,
                                    np.zeros(0), 50.0, 0.0)
    assert not ok and "a profile this narrow is the optimiser's" in why
    # (at 1 Hz a tau_c of 3 s: 1.991 s is within two samples, a low-pass's, not a bias's)
    ok, why, _ = _extension_verdict("markov", cast(Any, SimpleNamespace(tau_c_s=3.0)),
                                    cast(Any, None), {"markov_tau": (2.4, 3.9)}, pts,
                                    np.zeros(0), 50.0, 0.0)
    assert ok and why.startswith("kept")


def test_a_markov_term_within_two_samples_is_not_a_bias_process(reference_dir) -> None:
    """ADIS16405 gz, first hour of replicate 1 (100 Hz): a Gauss-Markov term of tau_c
    0.0118 s (1.2 samples) was kept beside quantization and an output white term (their
    amplitudes correlated at -0.99 and -1.00) and no white term, where the second hour,
    whose short-tau Allan curve agrees within 4 %, fits white + flicker (an outside
    reviewer). Such a tau_c is white noise through a low-pass, not a correlated bias."""
    from types import SimpleNamespace
    from typing import Any, cast

    from imubench.noisefit.fit import _extension_verdict

    st = cast(Any, SimpleNamespace(tau_c_s=0.0118))
    pts = cast(Any, SimpleNamespace(tau_s=np.geomspace(0.01, 655.0, 17), rate_hz=100.0))
    ok, why, _ = _extension_verdict("markov", st, cast(Any, None),
                                    {"markov_tau": (0.011, 0.013)}, pts, np.zeros(0), 50.0, 0.0)
    assert not ok and "within 2 sample periods (0.02 s)" in why
    path = reference_dir / "imu-real" / "adis16405" / "adis16405_rep1.npz"
    if not path.is_file():
        pytest.skip("ADIS16405 reference data not present")
    z = np.load(path)
    gz = z["gyro_counts"][:, 2].astype(float) * float(z["gyro_lsb_dps"])
    f = fit_channel(gz[: len(gz) // 2], float(z["fs_hz"]), terms="auto", channel="gz")
    assert "markov_sigma" not in f.present
    assert "white" in f.present or "output_white" in f.present, f.present


def test_an_undetected_random_walk_is_bounded_above_its_truth() -> None:
    """White 0.003 + flicker 0.001 + K = 1e-4, 2 h at 100 Hz: K is at the edge of
    detection. Where it is not kept, its upper 95 % limit must lie above the truth: weighted
    by the reduced model's variances every undetected K's limit lay below 1e-4 (an
    outside reviewer: 4 of 5; 11 of 11 in a 20-seed run here). Seeds 0-7 of that run
    hold 5 undetected; the limit covers the truth in at least 3 (6 of 11 over the 20)."""
    m = NoiseModel.single_term("gx", white=0.003).with_channel("gx", flicker=0.001,
                                                              random_walk=1e-4)
    undetected = covered = 0
    for seed in range(8):
        y = simulate(m, 720_000, 100.0, seed, channels=["gx"])["gx"]
        f = fit_channel(y, 100.0, channel="gx")
        if "random_walk" not in f.present:
            undetected += 1
            covered += f.ci["random_walk"][1] >= 1e-4
    assert undetected >= 2 and covered >= undetected - 2, (undetected, covered)


def test_quantization_fitted_through_a_filter_says_it_is_not_ieee_q() -> None:
    """Quantization at the input of an order-2 8 Hz output filter (1 h at 104 Hz): Q is
    found, and sqrt(3) Q / tau0 is then several times the measured ADEV at tau0; the fit
    says that it is the quantization at the filter's input, not IEEE 952's Q read off the
    curve."""
    m = NoiseModel.single_term("gx", white=0.002).with_channel(
        "gx", quantization=6e-4, bandwidth_hz=8.0, filter_order=2)
    y = simulate(m, 374_400, 104.0, 1001, channels=["gx"])["gx"]
    f = fit_channel(y, 104.0, channel="gx")
    assert {"quantization", "bandwidth_hz"} <= set(f.present), f.reasons
    q = f.params["quantization"]
    adev_tau0 = oadev(y, 104.0, "freq", [1 / 104.0]).dev[0]
    assert math.sqrt(3.0) * q * 104.0 > 2.0 * adev_tau0  # not the curve's Q
    assert any("not the IEEE 952 Q" in n for n in f.notes), f.notes


def test_amplitude_intervals_beside_a_filter_are_stated_with_its_bandwidth_free() -> None:
    """Quantization 6e-4 dps s at the input of an order-2 8 Hz filter, white 0.002, 1 h at
    104 Hz, six seeds: at the fitted bandwidth the Q interval was +-0.5 % and held the
    truth on 1 of the first 4 seeds (5.80e-4 [5.77e-4, 5.83e-4]); with the bandwidth a
    nuisance parameter it is +-3 % and holds it on at least 4 of 6 (measured 4)."""
    m = NoiseModel.single_term("gx", white=0.002).with_channel(
        "gx", quantization=6e-4, bandwidth_hz=8.0, filter_order=2)
    covered = 0
    for seed in range(1001, 1007):
        y = simulate(m, 374_400, 104.0, seed, channels=["gx"])["gx"]
        f = fit_channel(y, 104.0, channel="gx", terms="white,quantization,filter")
        lo, hi = f.ci["quantization"]
        assert hi / lo > 1.04, (seed, lo, hi)
        covered += lo <= 6e-4 <= hi
    assert covered >= 4, covered


def test_a_base_term_is_judged_with_the_filter_searched_again_without_it() -> None:
    """White + random walk + white after a 15 Hz filter, no quantization (1 h at 104 Hz):
    with the bandwidth chosen while every base term was present, 4 of 8 seeds kept a
    quantization term (6.6e-5 to 1.2e-4 dps s, "chi2 drop" at that bandwidth) that the same
    filter at its own best bandwidth makes unnecessary. The seeds here are four of those."""
    m = NoiseModel.single_term("gx", white=0.003).with_channel(
        "gx", random_walk=1e-4, output_white=0.002, bandwidth_hz=15.0)
    for seed in (1000, 1001, 1006, 1007):
        y = simulate(m, 374_400, 104.0, seed, channels=["gx"])["gx"]
        f = fit_channel(y, 104.0, channel="gx")
        assert "quantization" not in f.present, (seed, f.reasons["quantization"])
        assert {"white", "random_walk", "bandwidth_hz"} <= set(f.present), (seed, f.reasons)
        assert 12.0 < f.params["bandwidth_hz"] < 18.0, (seed, f.params["bandwidth_hz"])


def test_no_extension_stands_in_for_a_filter_judged_at_the_wrong_bandwidth() -> None:
    """White (+ flicker) + quantization behind an output filter, nothing else (1 h at 104
    Hz): the extensions were compared on the reference covariance with each subset's
    bandwidth as searched under the coarse 2 % floor, and a Markov term ("chi2 drop 43"),
    a sine (24.5) or a resonance at the broad hump that quantization makes behind the
    filter (~30 Hz) took up the misplacement: 5 of 40 such fits named one. The filter is
    now searched again for each subset on that covariance."""
    cases = ((dict(flicker=8e-4, quantization=1e-4, bandwidth_hz=20.0), 0.003, (1003, 1006)),
             (dict(flicker=8e-4, quantization=2e-4, bandwidth_hz=10.0), 0.003, (1002,)),
             (dict(quantization=3e-4, bandwidth_hz=8.0, filter_order=2), 0.002, (1003,)))
    for extra, white, seeds in cases:
        m = NoiseModel.single_term("gx", white=white).with_channel("gx", **extra)
        for seed in seeds:
            y = simulate(m, 374_400, 104.0, seed, channels=["gx"])["gx"]
            f = fit_channel(y, 104.0, channel="gx")
            named = {"markov_sigma", "sine_amplitude", "resonance_height"} & set(f.present)
            assert not named, (extra, seed, {k: f.reasons[k] for k in
                                             ("markov", "sine", "resonance")})
            assert "bandwidth_hz" in f.present


def test_adis_gyro_subsets_agree_once_the_filter_is_searched_per_term_set(
        reference_dir: Path) -> None:
    """ADIS16405 rep 1 gy (a gyro with a ~25 Hz output filter, 2.8 h at 100 Hz): the whole
    record and its halves were each fitted with a phantom quantization beside a filter at
    5-7 Hz, and their white intervals were mutually disjoint ([0.0295, 0.0301] whole vs
    [0.0285, 0.0312] and [0.0293, 0.0302] halves, Q [0.00871, 0.00886] vs [0.00596,
    0.00719] and [0.00739, 0.00758]). With the bandwidth searched for each set of base
    terms none keeps quantization, and the white and bandwidth intervals of the three
    overlap."""
    y = _adis(reference_dir, 1, "gy")
    fits = [fit_channel(part, 100.0, channel="gy")
            for part in (y, y[: y.size // 2], y[y.size // 2:])]
    for f in fits:
        assert "quantization" not in f.present, f.reasons["quantization"]
        assert 15.0 < f.params["bandwidth_hz"] < 35.0, f.params["bandwidth_hz"]
    for key in ("white", "bandwidth_hz"):
        lo = max(f.ci[key][0] for f in fits)
        hi = min(f.ci[key][1] for f in fits)
        assert lo <= hi, (key, [f.ci[key] for f in fits])


def test_a_resonance_adds_its_zero_frequency_floor_to_the_white_equivalent_density(
        reference_dir: Path) -> None:
    """A resonance's spectrum has a floor at 0 Hz that follows the -1/2 line: its AVAR
    tends to S(0) / tau, S the two-sided spectrum of the sampled process (about H / (1 +
    (2 f0 / w)^2) in continuous time; checked against the fit's own column at long taus,
    near Nyquist too, where aliasing doubles it). The ADIS16405 gz peak at 20 Hz carries a
    third of the line at 1-4 s: N was 0.0315 where ADEV x sqrt(tau) read 0.039; now within
    5 % of the measured curve less its flicker floor."""
    from imubench.noisefit.units import resonance_floor, white_equivalent

    m = np.array([10**6])
    for f0, w in ((2.0, 1.0), (5.0, 0.5), (20.0, 2.0), (45.0, 5.0), (1.0, 4.0)):
        col = term_avar("resonance", m, 100.0, f0_hz=f0, width_hz=w)
        np.testing.assert_allclose(col * m / 100.0, resonance_floor(f0, w, 100.0), rtol=2e-3)
    assert resonance_floor(5.0, 0.01, 100.0) == 0.0  # decays over 32 s: not on the line
    with pytest.raises(FitError, match="sample rate is needed"):
        white_equivalent({"resonance_height": 1.0, "resonance_freq_hz": 5.0,
                          "resonance_width_hz": 1.0})
    y = _adis(reference_dir, 1, "gz")
    f = fit_channel(y, 100.0, channel="gz")
    assert "resonance_height" in f.present
    n = datasheet_units("gz", f.params, 100.0)["noise_density_mdps_per_sqrt_hz"] / 1000
    one = oadev(y, 100.0, "freq", [1.0]).dev[0]
    assert n == pytest.approx(math.sqrt(one**2 - (0.664 * f.params["flicker"]) ** 2),
                              rel=0.03)
