"""imubench gap (issue 15): whole-record tests, new candidates, real backgrounds, forward
selection with the held-out check, and detection limits.

Records are made here from textbook definitions (numpy), not by the simulator the
diagnosis uses, except where a model's realisation is the point.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any, cast

import numpy as np
import pytest
from lsm6ds_sim.model import NoiseModel
from lsm6ds_sim.physics import simulate
from scipy.signal import lfilter

from imubench.gap import GapOptions, Series, diagnose, diagnose_channel
from imubench.gap.background import Background, from_halves, from_replicates, within
from imubench.gap.candidates import (
    MARKOV_DESCENT,
    MARKOV_SPAN,
    MARKOV_SPAN_SHOWN,
    Candidate,
)
from imubench.gap.curves import (
    LINE_CONTINUUM_BINS,
    Z_LINE,
    Z_LINE_FAMILY,
    Comparison,
    Region,
    line_peaks,
    line_segment,
    t_threshold,
    welch_psd,
    wilson_hilferty_z,
)
from imubench.gap.diagnose import LOOK_ALIKE_SCORE, _held_out_prefers, _peak_not_held_out
from imubench.gap.evidence import (
    drift_statistic,
    fit_bias_step,
    fit_resonance,
    fit_temperature,
    step_statistic,
)
from imubench.gap.explain import explain_channel
from imubench.gap.extras import increment
from imubench.gap.limits import detection_limits, inject, injection_sign, start_sizes
from imubench.gap.parts import (
    PartSetup,
    RecordTemperature,
    difference_kurtosis,
    seeds_of,
    simulate_channel,
)
from imubench.gap.step import Step
from imubench.gap.two_level import detrend_span, two_level_llr

RATE = 104.0
WHITE = 0.004
MODEL = NoiseModel.single_term("gx", white=WHITE)


def white(rng: np.random.Generator, n: int) -> np.ndarray:
    return WHITE * math.sqrt(RATE) * rng.standard_normal(n)


def white_flicker(rng: np.random.Generator, n: int, fs: float, white_d: float,
                  flicker: float) -> np.ndarray:
    """White noise of density ``white_d`` plus flicker ``flicker`` by FFT shaping (one-sided
    S(f) = B^2 / (pi f), NIST SP 1065 Table 3): a textbook generator, not the simulator."""
    freq = np.fft.rfftfreq(n, 1.0 / fs)
    s_fl = np.zeros_like(freq)
    s_fl[1:] = flicker**2 / (math.pi * freq[1:])
    sd = np.sqrt(s_fl * fs * n / 4.0)
    x = sd * (rng.standard_normal(sd.size) + 1j * rng.standard_normal(sd.size))
    return white_d * math.sqrt(fs) * rng.standard_normal(n) + np.fft.irfft(x, n)


# ------------------------------------------------------------------ whole-record tests
def test_drift_t_tells_a_ramp_from_a_random_walk() -> None:
    """A random walk K 5e-4 dps/sqrt(s) over 30 min, with and without a ramp R = 1e-4 dps/s:
    the drift's power against the walk is R sqrt(T) / K = 8.5."""
    n = int(1800 * RATE)
    thr = t_threshold(3.5, 30)
    rw_hits = 0
    for seed in range(5):
        rng = np.random.default_rng(seed)
        rw = np.cumsum(5e-4 / math.sqrt(RATE) * rng.standard_normal(n)) + white(rng, n)
        t_rw, _ = drift_statistic(rw, RATE)
        rw_hits += abs(t_rw) > thr
        t_ramp, _ = drift_statistic(rw + 1e-4 * np.arange(n) / RATE, RATE)
        assert t_ramp > thr
    assert rw_hits <= 1


def test_bias_step_is_located_and_sized() -> None:
    rng = np.random.default_rng(3)
    n = int(1200 * RATE)
    y = white(rng, n) + np.cumsum(1e-4 / math.sqrt(RATE) * rng.standard_normal(n))
    y0, _ = step_statistic(y)
    y = y + np.where(np.arange(n) / RATE >= 437.0, 0.02, 0.0)
    y1, _ = step_statistic(y)
    assert y0 < 5.0 < y1
    st = fit_bias_step(y, RATE)
    assert st.step_time_s == pytest.approx(437.0, abs=2.0)
    assert st.step_size == pytest.approx(0.02, rel=0.15)


def test_telegraph_is_two_level_and_gaussian_markov_is_not() -> None:
    rng = np.random.default_rng(4)
    n = int(3600 * RATE)
    tel = increment("telegraph", {"telegraph_step": 0.05, "telegraph_dwell_s": 10.0}, n,
                    RATE, 11)
    assert set(np.unique(tel)) == {0.0, 0.05}
    switches = np.count_nonzero(np.diff(tel))
    assert switches == pytest.approx(3600 / 10.0, rel=0.2)
    phi = math.exp(-1.0 / (RATE * 5.0))
    ar = np.zeros(n)
    w = 0.025 * math.sqrt(1 - phi * phi) * rng.standard_normal(n)
    for i in range(1, n):
        ar[i] = phi * ar[i - 1] + w[i]
    # the same autocovariance, so only the level distribution can tell them apart
    llr_tel = two_level_llr(tel + white(rng, n), RATE, 0.05, 10.0, 3600.0)
    llr_ar = two_level_llr(ar + white(rng, n), RATE, 0.05, 10.0, 3600.0)
    assert llr_tel > 1000.0 and llr_ar < -1000.0


def test_two_level_ratio_refers_the_levels_to_a_local_mean_under_a_wandering_background(
) -> None:
    """Under a random walk the levels are referred to a moving mean a few dwells long
    (the span :func:`detrend_span` picks from the background's Allan variance); over
    white noise alone, to the record's mean. The ratio keeps telegraph and Markov far
    apart both ways."""
    tau = 2.0 ** np.arange(-6, 11)
    avar_white = WHITE**2 / tau
    avar_walk = avar_white + (2e-3) ** 2 * tau / 3.0  # IEEE 952 random walk K^2 tau / 3
    assert detrend_span(0.05, 10.0, tau, avar_white, 3600.0) == 3600.0
    span = detrend_span(0.05, 10.0, tau, avar_walk, 3600.0)
    assert 20.0 <= span <= 200.0
    rng = np.random.default_rng(5)
    n = int(3600 * RATE)
    walk = np.cumsum(2e-3 / math.sqrt(RATE) * rng.standard_normal(n))
    tel = increment("telegraph", {"telegraph_step": 0.05, "telegraph_dwell_s": 10.0}, n,
                    RATE, 12)
    phi = math.exp(-1.0 / (RATE * 5.0))
    ar = lfilter([math.sqrt(1 - phi * phi) * 0.025], [1.0, -phi], rng.standard_normal(n))
    local = [two_level_llr(x + walk + white(rng, n), RATE, 0.05, 10.0, span)
             for x in (tel, ar)]
    whole = [two_level_llr(x + walk + white(rng, n), RATE, 0.05, 10.0, 3600.0)
             for x in (tel, ar)]
    assert local[0] - local[1] > 10000.0
    assert local[0] - local[1] > whole[0] - whole[1]
    assert math.isnan(two_level_llr(np.zeros(10), RATE, 0.05, 10.0, 100.0))


def test_telegraph_is_named_only_when_the_amplitudes_favour_two_levels() -> None:
    """Markov and telegraph share their Allan curve and spectrum; the telegraph is refused
    (with a reason) unless its shape fits better than the Markov's by TWO_LEVEL_MARGIN in
    shape_z^2, whatever the rest of the scores say."""
    from imubench.gap.candidates import Candidate
    from imubench.gap.diagnose import TWO_LEVEL_MARGIN, _shape_scores

    def pair(z_markov: float, z_tel: float) -> tuple[Candidate, Candidate]:
        m = Candidate("markov", {"markov_sigma": 1e-3, "markov_tau": 5.0}, 2, score=40.0,
                      shape_z=z_markov)
        t = Candidate("telegraph", {"telegraph_step": 2e-3, "telegraph_dwell_s": 10.0}, 2,
                      score=38.0, shape_z=z_tel)
        _shape_scores([m, t])
        return m, t

    m, t = pair(-0.3, 0.5)  # near the limit: the telegraph's lower score is chance
    assert t.refusal.startswith("two levels are not shown") and not m.refusal
    assert m.score == pytest.approx(40.0) and t.score == pytest.approx(38.0 + 0.5**2 - 0.3**2)
    m, t = pair(-3.1, 0.5)  # two levels fit clearly better (a clear blind telegraph)
    assert not t.refusal and t.score < m.score
    assert pair(-0.8, 0.6)[1].refusal  # slightly better is not enough (a random walk)
    assert pair(0.4, -0.4)[1].refusal  # a tie goes to the Gaussian process
    assert pytest.approx(3.84, abs=0.01) == TWO_LEVEL_MARGIN


def test_resonance_fit_finds_centre_width_height() -> None:
    rng = np.random.default_rng(5)
    n = int(1800 * RATE)
    res = increment("resonance", {"resonance_freq_hz": 12.0, "resonance_width_hz": 1.0,
                                  "resonance_height": 1e-3}, n, RATE, 5)
    from imubench.gap.curves import welch_psd

    f, p = welch_psd(white(rng, n) + res, RATE, 8192)
    rf = fit_resonance(f, p, np.full_like(p, 2 * WHITE**2))
    assert rf is not None
    assert rf.resonance_freq_hz == pytest.approx(12.0, abs=0.3)
    assert rf.resonance_width_hz == pytest.approx(1.0, rel=0.5)
    assert rf.resonance_height == pytest.approx(1e-3, rel=0.4)


def test_resonance_width_of_a_weak_peak_is_not_cut_by_noisy_bins() -> None:
    """A peak twice the continuum (1 Hz wide at 8 Hz, 30 min, the diagnosis' own Welch
    segment): the half-maximum run alone stopped at the first noisy dip (0.04-0.23 Hz
    over 12 seeds); the Lorentzian fit gets the width within 40 % on every seed here and
    ignores a low-frequency excess below the scan floor (1 % of the rate)."""
    from imubench.gap.curves import psd_segment, welch_psd

    n = int(1800 * RATE)
    widths = []
    for seed in range(4):
        rng = np.random.default_rng(seed)
        res = increment("resonance", {"resonance_freq_hz": 8.0, "resonance_width_hz": 1.0,
                                      "resonance_height": 6.4e-5}, n, RATE, seed)
        f, p = welch_psd(white(rng, n) + res, RATE, psd_segment(n))
        p = p + np.where(f < 0.5, 1e-3, 0.0)  # a strong low-frequency wander
        rf = fit_resonance(f, p, np.full_like(p, 2 * WHITE**2), 0.01 * RATE)
        assert rf is not None and rf.resonance_freq_hz == pytest.approx(8.0, abs=0.2)
        widths.append(rf.resonance_width_hz)
    assert np.all(np.abs(np.array(widths) - 1.0) < 0.4), widths


# ------------------------------------------------------------------ real backgrounds
def _cmp(z: list[float], regions: list[tuple[float, float]] = ()) -> Comparison:
    n = len(z)
    one = np.ones(n)
    zz = np.asarray(z, dtype=float)
    return Comparison(
        tau_s=2.0 ** np.arange(n), adev_real=one, adev_sim=one, adev_sim_lo=one,
        adev_sim_hi=one, d=0.1 * zz, z=zz, sigma=0.1 * one, band_f_hz=np.array([0.1, 1.0]),
        band_z=np.zeros(2), band_sigma=np.ones(2),
        line_z=0.0, line_f_hz=1.0, tail_z=0.0, temp_z=0.0, trend_z=0.0,
        level_z=0.0, realisations=10,
        regions=[Region(a, b, "real_above", 0.5, 6.0) for a, b in regions])


def test_replicates_absorb_a_departure_they_do_not_share() -> None:
    this = _cmp([0.0, 6.0, 5.0, 0.0], [(2.0, 4.0)])
    other = _cmp([0.0, -1.0, 0.5, 0.0])  # the replicate sits on the model there
    bg = from_replicates(this, [other])
    assert bg is not None and within(this, bg)
    shared = _cmp([0.0, 6.5, 4.5, 0.0])  # the replicate departs the same way: an effect
    bg = from_replicates(this, [shared])
    assert bg is not None and not within(this, bg)


def test_halves_of_a_stationary_record_add_no_background() -> None:
    fit = _cmp([0.5, 6.0, 5.0, -0.3], [(2.0, 4.0)])
    hold = _cmp([0.2, 5.5, 5.3, 0.1])
    bg = from_halves(fit, hold)
    assert np.all(bg.v_tau == 0.0)
    assert not within(fit, bg)
    assert within(fit, Background("halves", np.full(4, 4.0), np.zeros(2)))


def test_a_fired_statistic_is_never_background() -> None:
    c = _cmp([0.0, 0.0, 0.0, 0.0])
    c.temp_z = 9.0
    assert not within(c, Background("halves", np.full(4, 10.0), np.full(2, 10.0)))


# ------------------------------------------------------------------ spectral line
def _line_record(f_hz: float, amp: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """30 min of white noise and a random walk (K 3e-4 dps/sqrt(s)) with a sine."""
    n = int(1800 * RATE)
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    y = (white(rng, n) + np.cumsum(3e-4 / math.sqrt(RATE) * rng.standard_normal(n))
         + amp * np.sin(2 * math.pi * f_hz * t + 0.7))
    return welch_psd(y, RATE, line_segment(n))


def test_line_peaks_finds_a_slow_sine_in_the_first_block_and_a_fast_one_above_it() -> None:
    """A 0.015 Hz sine (27 cycles in 30 min, inside the first 64 bins, where the random
    walk's continuum rises by decades) in the first family; a 5 Hz sine in the second.
    Without a sine neither family's peak stands out (the local power law keeps the walk's
    steep continuum from reading as a peak)."""
    f, p = _line_record(0.015, 0.01, 1)
    (il, low), (ih, high) = line_peaks(p)
    assert il < LINE_CONTINUUM_BINS <= ih
    assert f[il] == pytest.approx(0.015, abs=2 * (f[1] - f[0])) and low > 5.0
    f, p = _line_record(5.0, 0.004, 2)
    (il, low), (ih, high) = line_peaks(p)
    assert f[ih] == pytest.approx(5.0, abs=2 * (f[1] - f[0])) and high > 5.0
    f, p = _line_record(5.0, 0.0, 3)
    (_, low), (_, high) = line_peaks(p)
    assert low < 4.0 and high < 4.0


def test_the_two_line_families_keep_one_test_s_false_alarm_rate() -> None:
    from scipy.stats import norm
    p = norm.sf(Z_LINE)
    assert 1 - (1 - norm.sf(Z_LINE_FAMILY)) ** 2 == pytest.approx(p, rel=1e-9)
    assert Z_LINE < Z_LINE_FAMILY < Z_LINE + 0.25


# ------------------------------------------------------------------ selection and held out
def _temp_profile(n: int) -> np.ndarray:
    t = np.arange(n) / RATE
    return 25.0 + 4.0 * np.sin(2 * math.pi * t / 500.0) + 1.0 * np.sin(2 * math.pi * t / 170.0)


def test_two_effects_are_both_kept_and_close_the_held_out_gap() -> None:
    n = int(900 * RATE)
    rng = np.random.default_rng(21)
    temp = _temp_profile(n)
    t = np.arange(n) / RATE
    y = (white(rng, n) + 0.004 * (temp - 25.0)
         + 0.01 * np.sin(2 * math.pi * 3.3 * t + 0.4))
    d = diagnose_channel(MODEL, "gx", Series(y, temp, RATE, "two"),
                         GapOptions(seed=2, realisations=5))
    kept = [c.effect for c in d.kept]
    assert set(kept) >= {"temperature", "sine"}, kept
    out = d.to_dict()
    assert [k["effect"] for k in out["kept"]] == kept
    assert out["verdict"] == kept[0]
    h = out["holdout"]
    assert h["gap_excess_after"] < 0.2 * h["gap_excess_before"]
    assert all("holdout_gap_after" in k for k in out["kept"])


def test_a_rival_the_fit_part_does_not_tell_apart_is_reported_as_a_look_alike(
        reference_dir: Path) -> None:
    """ADIS16405 rep 2 gy, second hour, with a Gauss-Markov process added (sigma 0.02 dps,
    tau_c 10 s, the acceptance bench's case): flicker and the Markov process score 39.6
    and 40.4 on the fit part (measured 2026-12-06), closer than the 2 that BIC calls
    evidence. The held-out part decides, and the verdict says that the fit part does not
    tell the two apart."""
    z = np.load(reference_dir / "imu-real" / "adis16405" / "adis16405_rep2.npz")
    fs = float(z["fs_hz"])
    n = int(3600 * fs)
    y = z["gyro_counts"][n:2 * n, 1].astype(float) * float(z["gyro_lsb_dps"])
    rng = np.random.default_rng(2015)  # the bench's draw (bench_gap_acceptance.py)
    phi = math.exp(-1.0 / (fs * 10.0))
    w = 0.02 * math.sqrt(1 - phi * phi) * rng.standard_normal(n)
    y += lfilter([1.0], [1.0, -phi], w, zi=[phi * 0.02 * rng.standard_normal()])[0]
    # the fitted model of the first hour (imubench fit, terms auto)
    model = NoiseModel.single_term("gy", white=0.0299993, flicker=0.0130051,
                                   bandwidth_hz=25.1245, filter_order=1,
                                   output_white=0.0298952)
    d = diagnose_channel(model, "gy", Series(y, _bench_temperature(n, fs), fs, "rep2"),
                         GapOptions(seed=7, realisations=10))
    out = d.to_dict()
    look = out["look_alike"]
    assert look is not None, [(e["effect"], e["score"]) for e in out["effects"]]
    # the held-out part decides: its chi-squared falls by 64.5 with the Markov process,
    # 52.4 with flicker (the truth is the Markov process)
    assert (out["verdict"], look["effect"]) == ("markov", "flicker")
    assert 0.0 < look["score_verdict"] - look["score"] < LOOK_ALIKE_SCORE
    assert look["holdout_chi2_drop_verdict"] > look["holdout_chi2_drop"]
    assert look["effect"] not in [k["effect"] for k in out["kept"]]
    rival = next(e for e in out["effects"] if e["effect"] == look["effect"])
    assert "rejected_because" not in rival and rival["holdout_chi2_drop"] > 3.84
    assert "the held-out part decided" in explain_channel(out, 10)[0]


def test_a_resonance_needs_its_peak_on_the_held_out_part_too() -> None:
    """A narrowband peak on the fit part only (the Samsung S5 gx 0.13 Hz bump: 2.4x its
    flanks there, 1.6x and z 0.1 on the held-out part) is no resonance: the held-out
    check had passed it through the Allan curve it widened, and it was named the verdict
    beside injected temperature responses and bias steps."""
    n = int(1800 * RATE)
    rng = np.random.default_rng(31)
    params = {"resonance_freq_hz": 12.0, "resonance_width_hz": 1.0, "resonance_height": 4e-4}
    res = increment("resonance", params, n, RATE, 31)
    y = white(rng, n)
    c = Candidate("resonance", params, 3)

    def step(residual: np.ndarray) -> Any:
        return SimpleNamespace(series_parts=(SimpleNamespace(y=residual[:n // 2]),
                                             SimpleNamespace()),
                               residual=residual, rate_hz=RATE)

    assert _peak_not_held_out(c, step(y + res)) == ""
    res[n // 2:] = 0.0
    assert _peak_not_held_out(c, step(y + res)).startswith(
        "the held-out part shows no narrowband peak there: a narrowband peak at")


def test_the_base_model_refit_beside_a_line_leaves_the_line_s_allan_variance_alone() -> None:
    """White 7e-5 /sqrt(Hz) at 10 Hz against a model of half that, with a 1e-4 sine at
    1.02 Hz (numpy generators): the base model's refit is kept first and fitted again
    beside the sine, whose Allan variance the realisations carry outside the simulator's
    terms. It was scaled with the white level (white 6.41e-5; on two hours 6.28e-5 and
    the sine, raising the chi-squared, was never kept; on the Samsung S5 az segment, 2.7e-5
    for 7.6e-5)."""
    rate, n = 10.0, 36_000
    rng = np.random.default_rng(5)
    t = np.arange(n) / rate
    y = 7e-5 * math.sqrt(rate) * rng.standard_normal(n) + 1e-4 * np.sin(
        2 * math.pi * 1.02 * t + 0.3)
    d = diagnose_channel(NoiseModel.single_term("ax", white=3.5e-5), "ax",
                         Series(y, None, rate, "white+sine"), GapOptions(seed=3, realisations=10))
    kept = {c.effect: c.params for c in d.kept}
    assert set(kept) == {"base_model", "sine"}, kept
    assert kept["base_model"]["white"] == pytest.approx(7e-5, rel=0.03)
    assert kept["sine"]["sine_amplitude"] == pytest.approx(1e-4, rel=0.05)


def test_a_line_behind_the_model_s_filter_is_realised_as_the_record_shows_it() -> None:
    """A sine candidate's model-file amplitude is before the output filter (1/|H| larger
    than seen, :func:`filter_power_gain`), and the gap realises it as an increment of the
    output: at the model-file size, a 14.6 Hz line behind a 17.4 Hz two-pole filter came
    out 1/|H| too large, and the base model's refit beside it bent its filter to make up
    for that (the blind pair filter + sine: the sine raised the chi-squared and was not
    kept, 3 of 3). Checked by a least-squares fit of the realisations."""
    from imubench.gap.candidates import filter_power_gain
    from imubench.gap.diagnose import Variant

    model = NoiseModel.single_term("gx", white=1e-6, bandwidth_hz=17.4, filter_order=2)
    g2 = filter_power_gain(14.6, model["gx"], RATE)
    assert g2 < 0.9
    c = Candidate("sine", {"sine_amplitude": 0.003 / math.sqrt(g2), "sine_freq": 14.6}, 2,
                  output_gain2=g2)
    n = int(60 * RATE)
    sims = Variant(model).add("gx", c).realise("gx", Series(np.zeros(n), None, RATE, "z"),
                                               [1, 2])
    t = np.arange(n) / RATE
    basis = np.column_stack([np.sin(2 * math.pi * 14.6 * t), np.cos(2 * math.pi * 14.6 * t)])
    for y in sims:
        coef, *_ = np.linalg.lstsq(basis, y, rcond=None)
        assert math.hypot(*coef) == pytest.approx(0.003, rel=0.01)


def test_a_noise_process_kept_first_does_not_take_a_line_s_allan_variance() -> None:
    """White + a Gauss-Markov process (0.01 dps, 1 s) + a 15 mdps sine at 0.9 Hz, numpy
    generators: the Markov process, fitted first to the Allan curve with the line in it,
    took the line's variance (sigma 0.0157, tau_c 0.29 s), the sine then raised the
    chi-squared and a flicker was kept instead (the Samsung S5 gx sine injections, 1 of 3
    lost at every size). The noise processes are fitted to the curve less the line."""
    n = int(1800 * RATE)
    rng = np.random.default_rng(41)
    t = np.arange(n) / RATE
    phi = math.exp(-1 / RATE)
    y = (white(rng, n) + lfilter([0.01 * math.sqrt(1 - phi * phi)], [1, -phi],
                                  rng.standard_normal(n))
         + 0.015 * np.sin(2 * math.pi * 0.9 * t + 0.3))
    d = diagnose_channel(MODEL, "gx", Series(y, None, RATE, "markov+sine"),
                         GapOptions(seed=3, realisations=10))
    kept = {c.effect: c.params for c in d.kept}
    assert set(kept) == {"markov", "sine"}, kept
    assert kept["markov"]["markov_sigma"] == pytest.approx(0.01, rel=0.15)
    assert kept["markov"]["markov_tau"] == pytest.approx(1.0, rel=0.3)
    assert kept["sine"]["sine_amplitude"] == pytest.approx(0.015, rel=0.05)


def test_the_held_out_part_decides_a_look_alike_only_where_it_is_independent() -> None:
    """Between look-alikes the lower fit-part score less held-out chi-squared drop wins,
    but never for an effect fitted on the whole record (the held-out part included)."""
    def cand(effect: str, score: float, drop: float, whole: bool = False) -> Candidate:
        c = Candidate(effect, {}, 1)
        c.score, c.holdout_dparts, c.whole_record = score, {"allan": drop}, whole
        c.holdout = cast(Any, object())
        return c

    chosen, rival = cand("flicker", 39.6, 52.4), cand("markov", 40.4, 64.5)
    assert _held_out_prefers(chosen, rival) and not _held_out_prefers(rival, chosen)
    assert not _held_out_prefers(cand("random_walk", 90.0, 10.0),
                                 cand("temperature", 90.8, 70.0, whole=True))
    assert not _held_out_prefers(cand("random_walk", 90.0, 10.0), cand("bias_step", 90.8, 70.0))


def test_the_gls_temperature_slope_is_not_biased_by_a_ramp() -> None:
    """A response of 1e-3 dps/degC beside a ramp of 2e-5 dps/s on a temperature that
    drifts 2 degC/h: least squares of the levels takes part of the ramp (it is the
    temperature candidate's other linear form); the model-GLS slope of the increments
    beside a trend does not (seeds 0-4: 0.80-1.10x the truth, least squares 2.3-2.5x)."""
    n = int(1800 * RATE)
    t = np.arange(n) / RATE
    temp = (25.0 + 2.0 * t / 3600 + np.sin(2 * math.pi * t / 1500 + 0.3)
            + 0.4 * np.sin(2 * math.pi * t / 430))
    series = Series(np.zeros(n), temp, RATE, "t")
    rt = RecordTemperature(MODEL["gx"], series)
    ols_off = 0
    for seed in range(5):
        y = white(np.random.default_rng(seed), n) + 1e-3 * (temp - 25.0) + 2e-5 * t
        assert rt.slopes(y[None, :])[0] == pytest.approx(1e-3, rel=0.25)
        tf = fit_temperature(y, temp, RATE, 25.0)
        assert tf is not None
        ols_off += tf.temp_coeff_linear > 2e-3  # 2.3-2.5x the truth here
    assert ols_off == 5


def test_fired_deterministic_tests_first_is_a_second_start_of_the_selection(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A ramp beside a temperature response: a random walk takes both long-tau excesses
    in the first step and the forward selection keeps it (with the ramp); the second
    start, the effects whose whole-record tests fired first, keeps the ramp and the
    temperature response, which score better on the fit part and hold on the held-out
    part, and the walk is reported as replaced."""
    n = int(1800 * RATE)
    rng = np.random.default_rng(1)
    t = np.arange(n) / RATE
    temp = (25.0 + 2.0 * t / 3600 + np.sin(2 * math.pi * t / 1500 + 0.3)
            + 0.4 * np.sin(2 * math.pi * t / 430))
    y = white(rng, n) + 0.002 * (temp - 25.0) + 2e-5 * t
    series = Series(y, temp, RATE, "temperature+ramp")
    opt = GapOptions(seed=1, realisations=5)
    monkeypatch.setattr(diagnose, "_fired_effects", lambda st: ())
    one = diagnose_channel(MODEL, "gx", series, opt)
    assert [c.effect for c in one.kept] == ["random_walk", "ramp"]
    monkeypatch.undo()
    d = diagnose_channel(MODEL, "gx", series, opt)
    assert {c.effect for c in d.kept} == {"ramp", "temperature"}, d.kept
    assert d.verdict in ("ramp", "temperature")
    ramp = next(c for c in d.kept if c.effect == "ramp")
    assert ramp.params["ramp"] == pytest.approx(2e-5, rel=0.25)
    # kept after the ramp and refitted on the record less it (backfitting): 0.0011 before
    temp = next(c for c in d.kept if c.effect == "temperature")
    assert temp.params["temp_coeff"] == pytest.approx(0.002, rel=0.3)
    walk = next(c for c in d.pruned if c.effect == "random_walk")
    assert walk.note.startswith("replaced by ") and not walk.accepted
    out = d.to_dict()
    assert "random_walk" in {x["effect"] for x in out["dropped"]}
    # the ramp, kept by both starts, is not also listed as replaced (by itself)
    assert not {x["effect"] for x in out["dropped"]} & {k["effect"] for k in out["kept"]}


def test_an_effect_fitted_beside_an_unmodelled_one_is_replaced_once_that_is_kept(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A telegraph beside a ramp: the ramp's Allan rise stretches the fitted dwell, the
    two-level test then refuses the telegraph and the forward selection keeps `markov`
    and the ramp. The sequential replacement fits the first effect again beside the ramp
    and the telegraph takes its place (the second start, the ramp's fired drift test
    first, is switched off here: it finds the pair on its own)."""
    n = int(1800 * RATE)
    rng = np.random.default_rng(1)
    y = (white(rng, n) + 3e-5 * np.arange(n) / RATE
         + increment("telegraph", {"telegraph_step": 0.008, "telegraph_dwell_s": 10.0}, n,
                     RATE, 101))
    series = Series(y, None, RATE, "telegraph+ramp")
    opt = GapOptions(seed=1, realisations=5)
    monkeypatch.setattr(diagnose, "_fired_effects", lambda st: ())
    monkeypatch.setattr(diagnose, "EXCHANGE_PASSES", 0)
    forward = diagnose_channel(MODEL, "gx", series, opt)
    assert [c.effect for c in forward.kept] == ["markov", "ramp"]
    monkeypatch.setattr(diagnose, "EXCHANGE_PASSES", 2)
    d = diagnose_channel(MODEL, "gx", series, opt)
    assert d.verdict == "telegraph" and {c.effect for c in d.kept} == {"telegraph", "ramp"}
    assert d.kept[-1].params["telegraph_dwell_s"] == pytest.approx(10.0, rel=0.5)
    gone = [c for c in d.pruned if c.effect == "markov"]
    assert gone and gone[0].note.startswith("replaced by telegraph")
    assert "markov" in [x["effect"] for x in d.to_dict()["dropped"]]


def test_a_response_that_silences_its_own_record_test_passes_the_first_rule() -> None:
    """Beside a base-model mismatch the share of the significant excess and the fit
    part's likelihood ratio weigh a temperature response (or a ramp) against the mismatch;
    silencing its own whole-record test that fired is the third way through rule 1."""
    st = cast(Any, SimpleNamespace(temp_fired=True, drift_fired=True, drift_dof=40))
    temp = Candidate("temperature", {"temp_coeff": 0.0087}, 1, temp_record_z=0.46)
    assert diagnose._explains_own_test(temp, st)
    temp.temp_record_z = 3.9  # fitted, but the record still correlates with temperature
    assert not diagnose._explains_own_test(temp, st)
    ramp = Candidate("ramp", {"ramp": 1e-5}, 1, drift_t=0.8)
    assert diagnose._explains_own_test(ramp, st)
    quiet = cast(Any, SimpleNamespace(temp_fired=False, drift_fired=False, drift_dof=40))
    assert not diagnose._explains_own_test(ramp, quiet)  # no test fired: rule 1 as before
    flick = Candidate("flicker", {"flicker": 0.002}, 1, temp_record_z=0.0, drift_t=0.0)
    assert not diagnose._explains_own_test(flick, st)
    # a sine at the line the held-out part found at the fit part's peak
    sine = Candidate("sine", {"sine_amplitude": 0.001, "sine_freq": 4.1}, 2)
    assert not diagnose._explains_own_test(sine, quiet)
    sine.held_out_line_z = 5.2
    assert diagnose._explains_own_test(sine, quiet)


def test_bias_step_at_the_split_point_is_named() -> None:
    """Each part alone is stationary; only the whole record shows the step."""
    n = int(600 * RATE)
    rng = np.random.default_rng(8)
    y = white(rng, n) + np.where(np.arange(n) >= n // 2, 0.03, 0.0)  # 8 sigma of a jump
    d = diagnose_channel(MODEL, "gx", Series(y, None, RATE, "step"),
                         GapOptions(seed=1, realisations=5))
    assert d.verdict == "bias_step"
    assert d.kept[0].params["step_time_s"] == pytest.approx(300.0, abs=2.0)


@pytest.mark.parametrize("at_s", [12.0, 588.0])
def test_a_bias_step_near_either_end_of_the_record_is_named(at_s: float) -> None:
    """Issue 15, acceptance 4, "a bias step anywhere in the record": 2 % from the start and
    from the end (a few hundred samples on one side), located on the whole record."""
    n = int(600 * RATE)
    rng = np.random.default_rng(21)
    y = white(rng, n) + np.where(np.arange(n) / RATE >= at_s, 0.03, 0.0)
    d = diagnose_channel(MODEL, "gx", Series(y, None, RATE, "edge step"),
                         GapOptions(seed=1, realisations=5))
    assert d.verdict == "bias_step"
    assert d.kept[0].params["step_time_s"] == pytest.approx(at_s, abs=2.0)
    assert d.kept[0].params["step_size"] == pytest.approx(0.03, rel=0.25)


def test_null_is_none_and_its_reason_says_so() -> None:
    n = int(600 * RATE)
    y = white(np.random.default_rng(9), n)
    d = diagnose_channel(MODEL, "gx", Series(y, None, RATE, "null"),
                         GapOptions(seed=1, realisations=5))
    out = d.to_dict()
    assert out["verdict"] == "none" and out["kept"] == []
    assert explain_channel(out, 5)[0].startswith("No unmodelled effect")


def test_a_candidate_the_held_out_part_contradicts_is_not_kept() -> None:
    """A temperature response only in the fit part (the sensor settles): fitted on the fit
    part, it does not hold on the held-out part, so it must not be kept."""
    n = int(900 * RATE)
    rng = np.random.default_rng(13)
    temp = _temp_profile(n)
    y = white(rng, n)
    y[: n // 2] += 0.004 * (temp[: n // 2] - 25.0)
    d = diagnose_channel(MODEL, "gx", Series(y, temp, RATE, "settle"),
                         GapOptions(seed=4, realisations=5))
    assert "temperature" not in [c.effect for c in d.kept]
    rejected = [c for c in d.candidates if c.effect == "temperature"]
    assert rejected and "held-out" in rejected[0].note


def test_the_candidates_refused_after_a_kept_effect_are_reported() -> None:
    """A sine throughout and a temperature response only in the fit part: the sine is
    kept, then the temperature is fitted and refused by the held-out part. The JSON's
    ``not_kept`` and the explanation say what was tried next and why it was not kept
    (it only said "a significant departure remains")."""
    n = int(900 * RATE)
    rng = np.random.default_rng(13)
    temp = _temp_profile(n)
    y = white(rng, n) + 0.01 * np.sin(2 * np.pi * 3.3 * np.arange(n) / RATE + 0.4)
    y[: n // 2] += 0.004 * (temp[: n // 2] - 25.0)
    d = diagnose_channel(MODEL, "gx", Series(y, temp, RATE, "settle"),
                         GapOptions(seed=4, realisations=5))
    out = d.to_dict()
    assert [k["effect"] for k in out["kept"]] == ["sine"]
    assert out["residual_significant"]
    tried = {x["effect"]: x["reason"] for x in out["not_kept"]}
    assert "held-out" in tried["temperature"], tried
    assert all(tried.values())
    text = "\n".join(explain_channel(out, 5))
    assert "tried next and not kept: " in text and "temperature (temp_coeff = " in text


def test_a_noise_term_that_makes_its_own_fit_part_depart_more_is_not_kept() -> None:
    """An outside reviewer's record (1 h at 104 Hz; white 0.004 dps/sqrt(Hz), FFT flicker
    0.0005 dps, white force through a mass-spring-damper of f0 5 Hz, Q 2.5 (scipy
    bilinear), 8.75 mdps LSB). The resonator's plateau below the line is twice the floor
    of the Lorentzian the resonance candidate fits; a flicker term then took that
    white-like excess: it lowered the held-out chi-squared at mid taus by 42 and was
    kept, while it raised the fit part's own systematic gap 0.128 -> 0.358 and the
    held-out gap 0.152 -> 0.197. A noise process must not make the fit part, where it
    was fitted, depart more than its scatter."""
    from scipy.signal import bilinear, lfilter

    n = int(3600 * RATE)
    rng = np.random.default_rng(3)
    f = np.fft.rfftfreq(n, 1.0 / RATE)
    y = WHITE * math.sqrt(RATE) * rng.standard_normal(n)
    amp = np.sqrt(np.where(f > 0, 0.0005**2 / (math.pi * np.maximum(f, 1e-12)), 0.0)
                  * n * RATE / 2.0)
    x = amp * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) / math.sqrt(2)
    x[0], x[-1] = 0.0, amp[-1] * rng.standard_normal()
    y += np.fft.irfft(x, n)
    wp = 2 * RATE * math.tan(math.pi * 5.0 / RATE)
    b, a = bilinear([wp**2], [1.0, wp / 2.5, wp**2], fs=RATE)
    grid = np.linspace(0.0, RATE / 2, 400001)
    gain2 = np.abs(np.polyval(b, np.exp(1j * 2 * np.pi * grid / RATE))
                   / np.polyval(a, np.exp(1j * 2 * np.pi * grid / RATE))) ** 2
    y += lfilter(b * math.sqrt(3e-4 / gain2.max()), a,
                 rng.standard_normal(n + 20000) * math.sqrt(RATE / 2))[20000:]
    y = np.round(y / 0.00875) * 0.00875
    temp = 25 + 0.5 * np.sin(2 * np.pi * np.arange(n) / RATE / 3000) + 0.01 * rng.standard_normal(n)
    model = NoiseModel.single_term("gx", white=WHITE, flicker=0.0005, output_white=2.477e-4)
    out = diagnose_channel(model, "gx", Series(y, np.round(temp, 3), RATE, "mech"),
                           GapOptions(seed=0)).to_dict()
    assert [k["effect"] for k in out["kept"]] == ["resonance"]
    tried = {x["effect"]: x["reason"] for x in out["not_kept"]}
    assert tried["flicker"].startswith("makes the fit part's Allan curve"), tried


# ------------------------------------------------------------------ plain words
def test_headline_is_plain_words_with_the_held_out_closure() -> None:
    c: dict[str, Any] = {
        "verdict": "temperature", "reason": "effect", "gap_before": 0.5, "gap_after": 0.1,
        "regions": [], "bands": [], "line": {"f_hz": 1.0, "z": 0.0}, "impulses_z": 0.0,
        "temperature_slope_z": 9.0, "trend_z": 0.0, "effects": [],
        "kept": [{"effect": "temperature", "params": {"temp_coeff": 0.0101},
                  "gap_after": 0.1, "holdout_gap_after": 0.06,
                  "holdout_gap_excess_after": 0.06}],
        "holdout": {"gap_before": 0.45, "gap_after": 0.06, "gap_excess_before": 0.43,
                    "gap_excess_after": 0.06},
    }
    first = explain_channel(c, 10)[0]
    assert first == ("The rate drifts with temperature, 0.0101; modelling it "
                     "closes 86% of the systematic Allan-curve gap on the held-out part.")
    units = {"temp_coeff": "dps/degC"}  # the JSON's units.params.<channel>
    assert explain_channel(c, 10, units)[0].startswith(
        "The rate drifts with temperature, 0.0101 dps/degC; modelling it")


# ------------------------------------------------------------------ detection limits
def test_start_sizes_scale_with_the_noise() -> None:
    rng = np.random.default_rng(6)
    n = int(600 * RATE)
    y = white(rng, n)
    a = start_sizes(Series(y, None, RATE), 0.5)
    b = start_sizes(Series(3.0 * y, None, RATE), 0.5)
    for k in ("sine", "ramp", "random_walk", "flicker", "bias_step"):
        assert b[k] == pytest.approx(3.0 * a[k], rel=1e-6)
    assert "temperature" not in a
    inj = inject(Series(y, None, RATE), "bias_step", 0.5, np.random.default_rng(0))
    assert np.ptp(inj - y) == pytest.approx(0.5)


@pytest.mark.slow
def test_detection_limits_of_a_sine_on_white_noise() -> None:
    n = int(300 * RATE)
    y = white(np.random.default_rng(10), n)
    lim = detection_limits(MODEL, "gx", Series(y, None, RATE), GapOptions(seed=0),
                           ("sine",))
    e = lim["effects"]["sine"]
    assert e["smallest_identified"] is not None
    # the weakest line seen: periodogram peak ~30x the continuum within a factor 4
    assert e["smallest_identified"] / start_sizes(Series(y, None, RATE), 0.5)["sine"] > 0.25
    assert lim["injections_per_size"] == 3


@pytest.mark.parametrize(("identified_at", "limit", "tried"), [
    # 3 of 3 at 1x, then 0 of 2 more: 2x (5 of 5) is the limit
    ({4.0: 5, 2.0: 5, 1.0: 3, 0.5: 0}, 2.0,
     [(4.0, 3, 3), (2.0, 5, 5), (1.0, 3, 5), (0.5, 0, 3)]),
    # every size down to 0.5x passes 3 of 3 and 0.5x is confirmed: an upper bound
    ({4.0: 5, 2.0: 5, 1.0: 5, 0.5: 5}, 0.5,
     [(4.0, 3, 3), (2.0, 3, 3), (1.0, 3, 3), (0.5, 5, 5)]),
    # 4x missed; 8x passes the screen, not the confirmation; 16x is confirmed
    ({4.0: 1, 8.0: 3, 16.0: 5}, 16.0, [(4.0, 1, 3), (8.0, 3, 5), (16.0, 5, 5)]),
])
def test_a_limit_is_a_size_identified_in_5_of_5_injections(
        monkeypatch: pytest.MonkeyPatch, identified_at: dict[float, int], limit: float,
        tried: list[tuple[float, int, int]]) -> None:
    """The search screens each size with 3 injections and confirms the size that would be
    the limit with 2 more: 3 of 3 alone is passed once in 4.6 by an effect identified 60 %
    of the time. Here the diagnosis of injection ``i`` at ``factor`` times the starting
    size is replaced by a table (injections ``i < identified_at[factor]`` are
    identified): only the search's rule is under test."""
    import imubench.gap.limits as limits

    s = Series(white(np.random.default_rng(4), int(600 * RATE)), None, RATE, "w")
    start = start_sizes(s, 0.5)["ramp"]

    def table(*args: Any) -> int:
        size, first, count = args[5], args[7], args[8]
        ok = identified_at[round(size / start, 6)]
        return sum(i < ok for i in range(first, first + count))

    monkeypatch.setattr(limits, "_hits", table)
    lim = detection_limits(MODEL, "gx", s, GapOptions(seed=0), ("ramp",))
    e = lim["effects"]["ramp"]
    assert e["smallest_identified"] == pytest.approx(limit * start)
    assert [(round(t["size"] / start, 6), t["identified"], t["of"]) for t in e["tried"]] \
        == tried
    assert e["smallest_tried_identified"] == (limit == min(f for f, _, _ in tried))
    assert (lim["injections_per_size"], lim["confirmations"]) == (3, 2)


def test_an_allan_fit_never_gains_from_a_prediction_that_is_not_positive() -> None:
    """The weighted ln-AVAR misfit (``avarfit._loss``) left out every tau whose residual
    was not finite, so a candidate predicting a negative variance at a tau lost that
    tau's misfit and scored better (the Markov AVAR went negative far below tau_c). Such
    a prediction is now scored as the smallest positive double, worse than any positive
    prediction (finite, so that the Brent searches minimising the loss do not run into
    NaN arithmetic); a tau the record or the realisations cannot measure is still left
    out for every candidate alike."""
    from imubench.gap.avarfit import _loss

    real = np.array([4.0, 2.0, 1.0, 0.5])
    model = np.array([1.0, 1.0, 1.0, 1.0])
    sig = np.full(4, 0.1)
    good = _loss(real, model, np.zeros(4), sig)
    assert good == pytest.approx(100.0 * sum((0.5 * math.log(r)) ** 2 for r in real))
    worst_positive = _loss(real, np.array([1.0, 1.0, 1e-300, 1.0]), np.zeros(4), sig)
    for add in (-2.0, -1.0):  # a negative and a zero variance at the third tau
        bad = _loss(real, model, np.array([0.0, 0.0, add, 0.0]), sig)
        assert math.isfinite(bad) and bad > worst_positive > 1e4 * good
    # taus without a measurement: the same for every candidate
    real_gap = np.array([4.0, 0.0, np.nan, 0.5])
    assert _loss(real_gap, model, np.zeros(4), sig) == pytest.approx(
        100.0 * ((0.5 * math.log(4.0)) ** 2 + (0.5 * math.log(0.5)) ** 2))
    model_gap = np.array([1.0, np.nan, 1.0, 1.0])
    assert math.isfinite(_loss(real, model_gap, np.zeros(4), sig))


def test_detection_limit_is_not_below_a_response_the_record_holds_unseen() -> None:
    """A temperature response of 1.5e-4 dps/degC in 10 min of white noise, below what the
    diagnosis keeps (whole-record z ~3): the stated limit must not say that it would have
    been seen. With injections of one sign each injected record held the record's own
    response too, and 1.4e-4 more (2.9e-4 in all) was identified 3 of 3 times: a limit
    of 1.4e-4 below the response the record holds. Alternating signs (+, -, +): the
    negative injection cancels it, and the limit holds for either sign."""
    n = int(600 * RATE)
    t = np.arange(n) / RATE
    temp = 25.0 + 3.0 * np.sin(2 * np.pi * t / 180.0) + np.sin(2 * np.pi * t / 47.0 + 1.0)
    c = 1.5e-4
    y = white(np.random.default_rng(1), n) + c * (temp - 25.0)
    s = Series(y, temp, RATE, "warm")
    assert not diagnose_channel(MODEL, "gx", s, GapOptions(seed=1)).kept
    lim = detection_limits(MODEL, "gx", s, GapOptions(seed=0), ("temperature",))
    e = lim["effects"]["temperature"]
    assert e["smallest_identified"] is not None and e["smallest_identified"] > c
    assert [injection_sign(i) for i in range(3)] == [1.0, -1.0, 1.0]


def test_limits_say_what_they_are_and_skip_a_temperature_that_only_drifts() -> None:
    """A temperature that drifts at a constant rate cannot show a response: its limit is
    not searched, with the reason (an outside reviewer: 9 injections spent, then "not
    identified up to 0.0144"). The text gives each limit with its unit, says "at most"
    where the smallest size tried was identified, and how coarse the limits are."""
    n = int(600 * RATE)
    temp = 25.0 + np.arange(n) / RATE / 3600.0
    s = Series(white(np.random.default_rng(2), n), temp, RATE, "drift")
    lim = detection_limits(MODEL, "gx", s, GapOptions(seed=0), ("temperature",))
    e = lim["effects"]["temperature"]
    assert e["smallest_identified"] is None and e["tried"] == []
    assert "only drifts" in e["not_searched"]
    lim["effects"]["sine"] = {"key": "sine_amplitude", "smallest_identified": 0.002,
                              "smallest_tried_identified": True,
                              "tried": [{"size": 0.004, "identified": 3, "of": 3},
                                        {"size": 0.002, "identified": 3, "of": 3}]}
    lim["effects"]["ramp"] = {"key": "ramp", "smallest_identified": 2e-5,
                              "smallest_tried_identified": False,
                              "tried": [{"size": 4e-5, "identified": 3, "of": 3},
                                        {"size": 2e-5, "identified": 3, "of": 3},
                                        {"size": 1e-5, "identified": 1, "of": 3}]}
    entry = diagnose_channel(MODEL, "gx", s, GapOptions(seed=0)).to_dict()
    entry["limits"] = lim
    text = " ".join(explain_channel(entry, 10, {"sine_amplitude": "dps",
                                                "ramp": "dps/s"}))
    assert "temperature not searched (the temperature only drifts" in text
    assert "sine (sine_amplitude) at most 0.002 dps (tried 0.004 3/3, 0.002 3/3)" in text
    assert "ramp 2e-05 dps/s (tried 4e-05 3/3, 2e-05 3/3, 1e-05 1/3)" in text
    assert "kept (named or not) in 5 of 5 injections, 3 per size and 2 more" in text
    assert "a limit may be off by a factor of 2 either way" in text


def test_each_fired_band_run_is_read_again_after_the_kept_effects() -> None:
    """JSON ``bands[].z_max_after``: the largest |z| of a band run that fired, over the
    same bands, against the model with the kept effects (a random walk here)."""
    n = int(1800 * RATE)
    rng = np.random.default_rng(3)
    y = white(rng, n) + np.cumsum(1e-3 * math.sqrt(1.0 / RATE) * rng.standard_normal(n))
    d = diagnose_channel(MODEL, "gx", Series(y, None, RATE, "walk"),
                         GapOptions(seed=2, realisations=5))
    assert [c.effect for c in d.kept] == ["random_walk"]
    bands = d.to_dict()["bands"]
    assert bands and all(b["z_max"] > 5.0 > 2.0 > b["z_max_after"] for b in bands), bands


def test_realise_matches_the_simulator_for_model_terms() -> None:
    """A kept simulator term is realised by the simulator; sanity of the variant path."""
    from imubench.gap.diagnose import Variant

    m = NoiseModel.single_term("gx", white=WHITE)
    n = 2000
    s = Series(np.zeros(n), None, RATE)
    v = Variant(m)
    a = v.realise("gx", s, [1, 2])
    b = np.stack([simulate(m, n, RATE, sd, channels=["gx"])["gx"] for sd in (1, 2)])
    assert np.allclose(a, b)


def test_outliers_after_the_output_filter_close_the_tail_excess() -> None:
    """Impulses added after a 10 Hz output filter (as a bus glitch appears in a record):
    the candidate realises them after the filter too, so the tail excess closes."""
    n = int(300 * RATE)
    model = NoiseModel.single_term("gx", white=WHITE, bandwidth_hz=10.0, filter_order=2)
    y = simulate(model, n, RATE, 77, channels=["gx"])["gx"]
    rng = np.random.default_rng(14)
    hit = rng.random(n) < 0.2 / RATE
    y[hit] += 0.3 * rng.standard_normal(int(hit.sum()))
    d = diagnose_channel(model, "gx", Series(y, None, RATE, "glitch"),
                         GapOptions(seed=3, realisations=5))
    assert d.verdict == "outliers"
    w = d.winner
    assert w is not None and w.fit is not None
    assert w.fit.tail_z < 0.2 * d.before.tail_z
    assert w.params["outlier_rate"] == pytest.approx(0.2, rel=0.35)


def test_difference_kurtosis_is_zero_for_gaussian_noise_and_measures_impulses() -> None:
    """The excess kurtosis of the m-sample mean differences: 0 for white Gaussian noise
    (below three standard errors), and for Bernoulli-Gaussian impulses (rate p, N(0, a^2))
    on white noise of variance s^2 at m = 1 half the samples' 3 p (1 - p) a^4 / (s^2 +
    p a^2)^2 (a difference of two independent samples has twice their fourth cumulant
    and twice their variance), falling as 1 / m."""
    rng = np.random.default_rng(5)
    n = 400_000
    afs = np.array([1, 2, 4, 8, 16, 64, 4096])
    assert not difference_kurtosis(rng.standard_normal(n), afs).any()
    p, a = 1e-3, 15.0
    y = rng.standard_normal(n)
    hit = rng.random(n) < p
    y[hit] += a * rng.standard_normal(int(hit.sum()))
    g = difference_kurtosis(y, afs)
    theory = 0.5 * 3 * p * (1 - p) * a**4 / (1 + p * a * a) ** 2
    assert g[0] == pytest.approx(theory, rel=0.3)
    assert g[3] == pytest.approx(g[0] / 8, rel=0.4)
    assert g[-1] == pytest.approx(g[-2] * 64 / 4096)  # 96 differences: extrapolated
    # a bias step (the blind set's clear one: 0.73 of a sample's sigma) is not a tail:
    # at most a chance 3-sigma reading of the Gaussian part, which widens nothing
    step = rng.standard_normal(n) + np.where(np.arange(n) >= n // 2, 0.73, 0.0)
    assert np.sqrt(1.0 + 0.5 * difference_kurtosis(step, afs)).max() < 1.01


def test_impulses_weaker_on_the_held_out_half_are_still_kept() -> None:
    """Impulses on white noise whose held-out half has them 15 % smaller (28 % less of
    their power, about one standard error of that power over some 60 impulses): the
    held-out short-tau Allan variance is below the realisations' by about one spread of
    the impulsive record's estimate, which its Gaussian equivalent degrees of freedom put
    at many (an outside reviewer's telegraph + outliers: refused, and the white level
    refitted instead); the spread widened by the record's kurtosis keeps them."""
    rng = np.random.default_rng(0)
    n = int(1200 * RATE)
    sd = 0.006 * math.sqrt(RATE)
    y = sd * rng.standard_normal(n)
    hit = rng.random(n) < 1e-3
    amp = 15.0 * sd * rng.standard_normal(n)
    amp[n // 2:] *= 0.85
    y[hit] += amp[hit]
    d = diagnose_channel(NoiseModel.single_term("gz", white=0.006), "gz",
                         Series(y, None, RATE, "impulses"), GapOptions(seed=1, realisations=5))
    assert d.verdict == "outliers"
    assert [c.effect for c in d.kept] == ["outliers"]


# ------------------------------------------------------------------ blind set (issue 15)
def test_holdout_chi2_counts_correlated_taus_once() -> None:
    """Five long taus that share most of their data (correlation 0.95) all at z = -2.4, as
    a held-out half whose random walk was weaker than the fitted one: the plain sum of
    z^2 counts that one excursion five times (28.8); the held-out check's Allan part is
    the whole-curve Mahalanobis statistic, about once (z^2 / mean correlation ~ 6)."""
    from imubench.gap.curves import global_chi2

    z = [0.0, 0.0, 0.0, -2.4, -2.4, -2.4, -2.4, -2.4]
    c = _cmp(z)
    n = len(z)
    corr = np.eye(n)
    corr[3:, 3:] = 0.95 + 0.05 * np.eye(5)
    c.chi2_global, c.dof_global, c.chi2_smooth = global_chi2(c.z, corr, c.tau_s)
    parts = c.chi2_parts()
    assert parts["allan"] < 8.0
    assert float(np.sum(c.z**2)) == pytest.approx(28.8)
    assert parts["bands"] == pytest.approx(0.0)
    assert c.chi2_check == pytest.approx(sum(parts.values()))
    # without a correlation model, the plain sum
    plain = _cmp(z)
    assert plain.chi2_parts()["allan"] == pytest.approx(28.8)
    assert plain.chi2_parts()["statistics"] == pytest.approx(plain.chi2 - 28.8)


def test_holdout_chi2_on_the_band_of_the_model_without_the_candidate() -> None:
    """A candidate that quadruples the realisations' spread and moves the curve away (d
    0.1 -> 0.25 at every tau) has a SMALLER Allan chi-squared on its own band (z 1.1 ->
    0.95); measured on the band of the model without it (``spread``), its Allan term
    rises, as the curve moved away. The spectral bands and statistics keep their own
    spread; without ``spread`` the comparison's own band applies throughout."""
    before = _cmp([1.0, 1.0, 1.0, 1.0])  # d 0.1, sigma 0.1
    wide = _cmp([1.0, 1.0, 1.0, 1.0])
    wide.d, wide.sigma = np.full(4, 0.25), np.full(4, 0.4)
    wide.z = wilson_hilferty_z(wide.d, wide.sigma)
    wide.band_z = np.array([1.5, -0.5])
    own, fixed, ref = wide.chi2_parts(), wide.chi2_parts(before), before.chi2_parts(before)
    assert own["allan"] < ref["allan"] < fixed["allan"]
    assert fixed["allan"] == pytest.approx(
        float(np.sum(wilson_hilferty_z(wide.d, before.sigma) ** 2)))
    assert ref["allan"] == pytest.approx(
        float(np.sum(wilson_hilferty_z(before.d, before.sigma) ** 2)))
    assert fixed["bands"] == own["bands"] == pytest.approx(2.5)
    assert fixed["statistics"] == own["statistics"]
    # the same comparison as the one before drops by exactly nothing, not by rounding
    first, same = _cmp([1.0, 2.0, -1.0, 0.5]), _cmp([1.0, 2.0, -1.0, 0.5])
    first.z = wilson_hilferty_z(first.d, first.sigma)
    same.d = first.d * (1.0 + 1e-15)
    same.z = wilson_hilferty_z(same.d, same.sigma)
    assert first.chi2_drop(same) == {"allan": 0.0, "bands": 0.0, "statistics": 0.0}
    assert first.chi2_drop(wide)["allan"] != 0.0


def test_tail_threshold_is_normal_not_student_t() -> None:
    """The impulse count's spread is Poisson-floored, not a standard deviation of K
    realisations: a tail z of 8 fires at K = 10 (the Student-t threshold would be 12.4),
    while a line or temperature z of 5 (K-sample spreads) still needs the t threshold
    5.3."""
    c = _cmp([0.0] * 6)
    assert not c.significant
    c.tail_z = 8.0
    assert c.significant
    c.tail_z = 0.0
    for name in ("line_z", "temp_z"):
        setattr(c, name, 5.0)
        assert not c.significant
        setattr(c, name, 0.0)


def test_model_gls_level_test_sees_a_smooth_temperature_response_the_increments_miss(
) -> None:
    """White plus flicker noise with a response to a smooth temperature (periods of 25
    and 7 min): the increments' correlation weighs the flicker-heavy slow increments
    like the others and keeps little of the response; the GLS slope under the model's
    exact covariance keeps it. On the null its z is N(0, 1): 40 null records stay within
    the normal range, with a spread near 1."""
    from lsm6ds_sim.model import ChannelModel

    from imubench.gap.curves import (
        FISHER_SD_FLOOR,
        features,
        stack,
        temp_level_against,
        z_against,
    )
    from imubench.gap.parts import RecordTemperature, Series

    fs, n = 10.0, 18000
    t = np.arange(n) / fs
    temp = 26.0 + 3.0 * np.sin(2 * math.pi * t / 1500.0) + 1.2 * np.sin(
        2 * math.pi * t / 420.0)
    afs = np.array([1, 2, 4])
    edges = np.array([0.01, 0.1, 1.0, 5.0])
    rng = np.random.default_rng(8)
    white, flicker = 0.004 * 4.0, 0.0008 * 4.0  # noisier than the LSM6DSL: a weak response
    cm = ChannelModel().replace(white=white, flicker=flicker)

    def noise() -> np.ndarray:
        return white_flicker(rng, n, fs, white, flicker)

    def feats(y: np.ndarray) -> Any:
        return features(y, fs, afs, edges, 256, temp)

    sims = stack([feats(noise()) for _ in range(10)])
    real = feats(noise() + 3e-3 * (temp - 25.0))
    chol = RecordTemperature(cm, Series(np.zeros(n), temp, fs)).chol
    assert chol is not None
    level = temp_level_against(real, sims, chol)
    incr = z_against(real.temp_corr, sims.temp_corr, FISHER_SD_FLOOR)
    assert level > 3.5  # the normal threshold: the model's exact error
    assert abs(incr) < t_threshold(3.5, 9)  # K = 10 realisations estimate its spread
    nulls = np.array([temp_level_against(feats(noise()), sims, chol) for _ in range(40)])
    assert np.all(np.abs(nulls) < 3.5)
    assert 0.6 < nulls.std() < 1.4
    assert temp_level_against(real, sims, None) != temp_level_against(real, sims, None)


def test_resonance_candidate_needs_a_peak_over_the_model() -> None:
    """A resonance stands at least RESONANCE_MIN_RATIO above the model's PSD at its
    centre: a 20 % band excess (replicate differences on ADIS gy) is not one."""
    import numpy as np

    from imubench.gap.candidates import RESONANCE_MIN_RATIO, is_peak
    from imubench.gap.evidence import fit_resonance

    f = np.linspace(0.0, 50.0, 501)
    model = np.full(f.size, 3.2e-5)
    bump = np.exp(-0.5 * ((f - 20.0) / 1.0) ** 2)
    for height, want in ((0.2, False), (RESONANCE_MIN_RATIO + 1.0, True)):
        real = model * (1.0 + height * bump)
        rf = fit_resonance(f, real, model)
        assert rf is not None and abs(rf.resonance_freq_hz - 20.0) < 0.2
        assert is_peak(rf, f, model) is want


def test_tail_statistic_weighs_at_most_its_cap_in_chi_squared() -> None:
    """A heavy-tailed real sensor puts the impulse count thousands of sigmas off (S5 gyro:
    tail z 2425); uncapped, a candidate's side effect on it (2425 -> 2400) moved the total
    by 1.2e5 and decided the ranking. Capped at TAIL_Z_CAP: the tail weighs 100, side
    effects beyond the cap nothing, and an outliers fit that removes it gains the 100."""
    from dataclasses import replace

    from imubench.gap.curves import TAIL_Z_CAP

    base = _cmp([0.0, 1.0, -1.0])
    far, farther = replace(base, tail_z=2400.0), replace(base, tail_z=2425.0)
    assert farther.chi2 == pytest.approx(far.chi2)
    assert far.chi2 - base.chi2 == pytest.approx(TAIL_Z_CAP**2) == pytest.approx(100.0)
    assert replace(base, tail_z=4.0).chi2 - base.chi2 == pytest.approx(16.0)


def test_quantization_is_refused_where_the_short_taus_do_not_follow_its_law() -> None:
    """Quantization (3 Q^2 / tau^2, IEEE 952 C.2) over a changed white level fits the
    short-tau excess; the Samsung S5 gyro's departure (decimation filter: real / model
    AVAR 1.77, 1.03, 0.74, 0.78 at 1, 2, 4, 8 tau0, measured) does not, and was named
    `quantization` on a null. Excess drawn with noise at the stated one-sigma."""
    from scipy.stats import chi2

    from imubench.gap.avarfit import quantization_law
    from imubench.gap.candidates import QUANTIZATION_LAW_ALPHA

    tau = np.array([1, 2, 4, 8]) / RATE
    model = WHITE**2 / tau
    s = np.full(4, 0.01)  # one sigma of ln ADEV: 2 % in AVAR
    rng = np.random.default_rng(5)
    need = chi2.isf(QUANTIZATION_LAW_ALPHA, 2)
    misfits = []
    for _ in range(200):  # quantization +20 % at tau0, white 3 % lower
        real = model * (0.97 + 0.2 / (tau * RATE)) * (1 + 2 * s * rng.standard_normal(4))
        misfits.append(quantization_law(tau, real, model, s)[0])
    assert np.mean(np.array(misfits) > need) < 0.01
    assert np.mean(misfits) == pytest.approx(2.0, rel=0.3)  # chi-squared, 2 dof
    s5 = model * np.array([1.77, 1.03, 0.74, 0.78])
    c2, dof, _ = quantization_law(tau, s5, model, s)
    assert dof == 2 and c2 > 5 * need


def test_quantization_needs_its_own_part_beyond_a_white_level_change() -> None:
    """A white level 5 % higher follows the law with b = 0: its quantization part adds
    nothing (chi-squared 1 dof); a real 3 Q^2 / tau^2 (+20 % at tau0) adds a lot."""
    from scipy.stats import chi2

    from imubench.gap.avarfit import quantization_law
    from imubench.gap.candidates import QUANTIZATION_LAW_ALPHA

    tau = np.array([1, 2, 4, 8]) / RATE
    model = WHITE**2 / tau
    s = np.full(4, 0.01)
    rng = np.random.default_rng(6)
    need = chi2.isf(QUANTIZATION_LAW_ALPHA, 1)
    white = [quantization_law(tau, model * 1.05 * (1 + 2 * s * rng.standard_normal(4)),
                              model, s)[2] for _ in range(300)]
    assert np.mean(np.array(white) > need) < 0.01
    quant = [quantization_law(tau, model * (1 + 0.2 / (tau * RATE))
                              * (1 + 2 * s * rng.standard_normal(4)), model, s)[2]
             for _ in range(50)]
    assert min(quant) > need


def test_base_model_refit_adds_white_to_a_model_without_it() -> None:
    """A fit that took a decimated record's white noise for a short Markov process has no
    white term; the base model's refit must still be able to add one (it kept 0)."""
    from imubench.gap.avarfit import fit_base_model
    from imubench.noisefit import model_avar

    cm = NoiseModel.single_term("gx", markov_sigma=0.04, markov_tau=1.2)["gx"]
    tau = np.geomspace(0.1, 100.0, 13)
    real = model_avar(cm.replace(white=0.0025), tau, 10.0)
    _, _, w = fit_base_model(cm, tau, 10.0, real, model_avar(cm, tau, 10.0),
                             np.full(tau.size, 0.02))
    assert w == pytest.approx(0.0025, rel=0.02)
    _, _, w0 = fit_base_model(cm, tau, 10.0, model_avar(cm, tau, 10.0),
                              model_avar(cm, tau, 10.0), np.full(tau.size, 0.02))
    assert w0 < 0.0025 / 30


def test_a_transient_excursion_is_not_a_bias_step() -> None:
    """A step shifts every later level; a ten-minute excursion that comes back (Samsung S5
    gy, -50 mdps, named `bias_step` on a null) does not."""
    from imubench.gap.evidence import STEP_PERSISTENCE, fit_bias_step, step_persistence

    rng = np.random.default_rng(21)
    n = int(3600 * RATE)
    t = np.arange(n) / RATE
    step = white(rng, n) + np.where(t > 1000.0, 0.02, 0.0)
    fit = fit_bias_step(step, RATE)
    assert fit.step_time_s == pytest.approx(1000.0, abs=5.0)
    assert step_persistence(step, RATE, fit) == pytest.approx(1.0, abs=0.1)
    bump = white(rng, n) + np.where((t > 1000.0) & (t < 1600.0), 0.02, 0.0)
    fit = fit_bias_step(bump, RATE)
    assert abs(fit.step_size) > 0.015  # locally it looks like a step
    assert step_persistence(bump, RATE, fit) < STEP_PERSISTENCE


def _step_record(seed: int, walk: float, bump_s: float | None) -> Series:
    """1 h at 52 Hz of white 0.004 dps/sqrt(Hz), a random walk ``walk`` (dps/sqrt(s)) and
    +0.02 dps from t = 1104 s on (for ``bump_s`` seconds only, when given), quantised to
    8.75 mdps (an outside reviewer's bias step beside a random walk)."""
    fs = 52.0
    n = int(3600 * fs)
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    on = (t >= 1104.0) if bump_s is None else (t >= 1104.0) & (t < 1104.0 + bump_s)
    y = (0.004 * math.sqrt(fs) * rng.standard_normal(n)
         + np.cumsum(rng.standard_normal(n)) * walk / math.sqrt(fs) + np.where(on, 0.02, 0.0))
    return Series(np.round(y / 0.00875) * 0.00875, None, fs, f"step record {seed}")


_STEP_MODEL = NoiseModel.single_term("gx", white=0.004,
                                     output_white=0.00875 / math.sqrt(12 * 52.0))


def test_a_bias_step_on_a_wandering_background_is_kept_beside_the_walk() -> None:
    """A random walk of 4e-4 dps/sqrt(s) moves the far levels of an hour by about as much
    as a 0.02 dps step, so the step kept 15 % of its size far from it and was refused as
    "not a bias step"; the walk took it (6.4e-4). The share is now judged against the
    spread the model's realisations give it, and both are kept, each near its truth."""
    d = diagnose_channel(_STEP_MODEL, "gx", _step_record(1, 4e-4, None),
                         GapOptions(seed=3, standard_errors=False))
    kept = {c.effect: c.params for c in d.kept}
    assert set(kept) == {"random_walk", "bias_step"}
    assert kept["random_walk"]["random_walk"] == pytest.approx(4e-4, rel=0.15)
    assert kept["bias_step"]["step_time_s"] == pytest.approx(1104.0, abs=1.0)
    assert kept["bias_step"]["step_size"] == pytest.approx(0.02, abs=0.005)
    walk = next(k for k in d.to_dict()["kept"] if k["effect"] == "random_walk")
    assert walk["model_params"] == {"random_walk": 0.0}  # the model lacks it


def test_an_excursion_on_a_quiet_background_is_still_not_a_bias_step() -> None:
    """Without a wander in the model, a ten-minute excursion that comes back keeps far
    less of its size than the realisations' spread allows: refused, and said why."""
    d = diagnose_channel(_STEP_MODEL, "gx", _step_record(2, 0.0, 600.0),
                         GapOptions(seed=3, standard_errors=False))
    assert "bias_step" not in {c.effect for c in d.kept}
    step = next(c for c in d.candidates if c.effect == "bias_step")
    assert step.refusal is not None and "the model's own wander" in step.refusal


def test_evidence_plot_draws_the_kept_resonance() -> None:
    """The evidence panel of a resonance verdict overlays model + the fitted line at its
    centre (it showed the real and model spectra only)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from imubench.gap.report import _evidence

    rng = np.random.default_rng(8)
    n = int(1200 * RATE)
    res = increment("resonance", {"resonance_freq_hz": 12.0, "resonance_width_hz": 1.0,
                                  "resonance_height": 3e-4}, n, RATE, 8)
    d = diagnose_channel(MODEL, "gx", Series(white(rng, n) + res, None, RATE, "res"),
                         GapOptions(seed=3, realisations=4, effects=("resonance",)))
    assert d.verdict == "resonance"
    fig, ax = plt.subplots()
    _evidence(ax, d)
    overlay = [ln for ln in ax.get_lines() if ln.get_label().startswith("model + resonance")]
    assert len(overlay) == 1
    f, y = overlay[0].get_data()
    model = next(ln for ln in ax.get_lines() if ln.get_label().startswith("model (mean"))
    top = float(f[np.argmax(np.asarray(y) / np.asarray(model.get_data()[1]))])
    assert top == pytest.approx(12.0, abs=0.3)
    plt.close(fig)


def test_heavy_tailed_noise_is_not_called_outliers() -> None:
    """Outliers are rare impulses. White noise with Student-t (3 dof) samples has heavy
    tails everywhere; the impulse fit then calls a large share of the samples impulses
    (Samsung S5 gyro: 22 %) and that candidate is refused with its reason, while sparse
    impulses (0.1/s of 0.5 dps at 104 Hz) are kept."""
    rng = np.random.default_rng(12)
    n = int(1200 * RATE)
    t3 = rng.standard_t(3, n) / math.sqrt(3.0)  # unit variance
    heavy = WHITE * math.sqrt(RATE) * t3
    d = diagnose_channel(MODEL, "gx", Series(heavy, None, RATE, "t3"),
                         GapOptions(seed=2, realisations=4, effects=("outliers",)))
    cand = next(c for c in d.candidates if c.effect == "outliers")
    assert cand.params["outlier_rate"] / RATE > 0.01
    assert cand.note.startswith("the tail is not sparse impulses")
    assert d.verdict != "outliers"
    sparse = white(rng, n)
    hit = rng.random(n) < 0.1 / RATE
    sparse[hit] += 0.5 * rng.standard_normal(int(hit.sum()))
    d = diagnose_channel(MODEL, "gx", Series(sparse, None, RATE, "sparse"),
                         GapOptions(seed=2, realisations=4, effects=("outliers",)))
    assert d.verdict == "outliers"


def test_a_sine_is_not_called_a_resonance() -> None:
    """The resonance's Lorentzian fit of a pure line comes out about one Welch bin wide;
    narrower than PEAK_MIN_BINS bins it is refused as a line, and the sine is named."""
    rng = np.random.default_rng(13)
    n = int(1200 * RATE)
    t = np.arange(n) / RATE
    y = white(rng, n) + 0.01 * np.sin(2 * math.pi * 7.3 * t + 0.4)
    d = diagnose_channel(MODEL, "gx", Series(y, None, RATE, "sine"),
                         GapOptions(seed=2, realisations=4, effects=("resonance", "sine")))
    assert d.verdict == "sine"
    res = [c for c in d.candidates if c.effect == "resonance"]
    assert res and all("a spectral line's width (the sine candidate's shape)" in c.refusal
                       for c in res)


def test_a_model_channel_without_noise_is_a_clear_error() -> None:
    """`fit` of an accel-only file leaves the gyro channels empty; `gap` on gyro data with
    that model ended in a TypeError (exit 70)."""
    from imubench.gap.errors import GapError

    rng = np.random.default_rng(1)
    with pytest.raises(GapError, match=r"\[channels.gx\] has no noise term"):
        diagnose_channel(NoiseModel(), "gx", Series(white(rng, 4096), None, RATE, "r"))


def _s5_ax_second_segment(reference_dir: Path) -> tuple[np.ndarray, float, NoiseModel]:
    """The Samsung S5 accelerometer x's second 1.99 h segment (g), its rate (Hz) and the
    noise fit of the first segment as a model (``imubench fit``'s engine, terms auto)."""
    from imubench.noisefit import fit_channel

    path = reference_dir / "imu-real" / "samsung-s5-static" / "samsung_galaxy_s5_static.npz"
    if not path.is_file():
        pytest.skip("Samsung S5 reference data not present")
    z = np.load(path)
    ax = z["accel_m_s2"][:, 0] / 9.80665
    fs = float(z["fs_hz"])
    n = len(ax) // 3
    fit = fit_channel(ax[:n], fs, terms="auto", channel="ax")
    return ax[n:2 * n], fs, NoiseModel.single_term(
        "ax", **{k: v for k, v in fit.params.items() if v})


def _bench_temperature(n: int, fs: float) -> np.ndarray:
    """The acceptance benches' temperature history (degC, 0.0625 degC steps:
    bench_gap_acceptance.temperature_history)."""
    t = np.arange(n) / fs
    return np.round((24.0 + 3.0 * np.sin(2 * math.pi * t / 1300.0 + 0.7)
                     + 1.5 * np.sin(2 * math.pi * t / 410.0) + t / 3600.0) / 0.0625) * 0.0625


def test_a_temperature_response_is_checked_on_the_held_out_bands_at_the_noise_s_spread(
        ) -> None:
    """An outside reviewer's Markov process (4 mdps, 30 s) beside a temperature response
    of 4e-3 dps/degC (textbook generators, half an hour of the held-out part): the model
    with the response fitted 10 % low is closer to the record in the spectrum, but the
    response is the same in every realisation, so where it dominates the lowest bands
    their ln PSD spreads only by its cross term with the noise; on that yardstick the
    bands' chi-squared rose (here by 19; 822.6 on the reviewer's record, where the
    response was refused and a random walk kept alone). On the wider of that spread and
    the model's without the response, the bands' chi-squared falls (``wide_bands``, for
    an effect with a deterministic part; a noise process keeps its own spread)."""
    model = NoiseModel.single_term("gx", white=WHITE).with_channel("gx", flicker=0.0008)
    n = int(1800 * RATE)
    t = np.arange(n) / RATE + 1800.0
    rng = np.random.default_rng(2)
    phi = math.exp(-1.0 / (RATE * 30.0))
    e = 0.004 * math.sqrt(1.0 - phi * phi) * rng.standard_normal(n)
    markov = lfilter([1.0], [1.0, -phi], e, zi=[phi * 0.004 * rng.standard_normal()])[0]
    temp = (25.0 + 3.0 * t / 3600.0 + 2.0 * np.sin(2 * math.pi * t / 1500.0)
            + 0.8 * np.sin(2 * math.pi * t / 420.0 + 1.0))
    y = white_flicker(rng, n, RATE, WHITE, 0.0008) + markov + 4e-3 * (temp - 25.0)
    series = Series(y, temp, RATE, "held-out half")
    part = PartSetup(series, model["gx"])
    sims = simulate_channel(model, "gx", series, seeds_of(0, 10))
    before = part.compare(part.sim_features(sims), model["gx"])
    after = part.compare(part.sim_features(sims + 0.0036 * (temp - 25.0)), model["gx"])
    own_drop = before.chi2_parts()["bands"] - after.chi2_parts()["bands"]
    assert own_drop < -5.0  # the narrow yardstick: the closer model scores worse
    assert after.chi2_parts(before, None, True)["bands"] < after.chi2_parts()["bands"]
    assert after.chi2_parts(before)["bands"] == after.chi2_parts()["bands"]  # noise: own
    drop = before.chi2_drop(after, None, True)  # a deterministic part added
    assert drop["bands"] > 50.0, drop
    assert drop["allan"] > 100.0, drop


def test_real_null_does_not_keep_an_effect_that_moves_the_held_out_curve_away(
        reference_dir: Any) -> None:
    """Samsung S5 accelerometer x, second 1.99 h segment against the first segment's
    fitted model (a reviewer's null): a random walk was kept after the base model's
    refit although the held-out systematic Allan gap rose 0 -> 0.24 (its wider spread
    lowered the chi-squared). No effect is named now."""
    ax, fs, model = _s5_ax_second_segment(reference_dir)
    d = diagnose_channel(model, "ax", Series(ax, None, fs, "s5:ax:2"),
                         GapOptions(seed=7, realisations=10))
    assert d.verdict in ("none", "base_model", "unexplained"), (d.verdict, d.reason)
    h = d.to_dict()["holdout"]
    assert h["gap_excess_after"] <= h["gap_excess_before"] + h["gap_null"]


def test_look_alikes_on_a_far_off_base_model_are_decided_by_the_held_out_part(
        reference_dir: Any) -> None:
    """Samsung S5 accelerometer x, second segment against the first's model, with a random
    walk of 2.09e-5 g/sqrt(s) added (acceptance 2's draw): after the base model's refit
    the fit's chi-squared is ~147 per term, and a ramp beat the walk by 7.2 (4712.4
    against 4719.6), a difference that is no evidence at that misfit; the held-out part,
    whose chi-squared falls by 113.6 with the walk and 76.9 with the ramp, was not asked,
    and the ramp was named. Score differences are weighed in units of the overdispersion
    (chi-squared per term), at every step and in the sequential replacement."""
    ax, fs, model = _s5_ax_second_segment(reference_dir)
    n = len(ax)
    rng = np.random.default_rng([20261127, 3, 1, 2])  # bench_gap_limits_real's draw
    y = ax + np.cumsum(2.09e-5 * math.sqrt(1.0 / fs) * rng.standard_normal(n))
    d = diagnose_channel(model, "ax", Series(y, _bench_temperature(n, fs), fs, "s5:ax:2+rw"),
                         GapOptions(seed=139, realisations=10))
    out = d.to_dict()
    assert [k["effect"] for k in out["kept"]] == ["base_model", "random_walk"], out["kept"]
    assert out["kept"][1]["params"]["random_walk"] == pytest.approx(2.09e-5, rel=0.3)
    look = out["look_alike"]
    assert look is not None and look["effect"] == "ramp" and look["step"] == 2
    assert look["overdispersion"] > 50.0
    assert look["score"] < look["score_verdict"] < look["score"] + 2 * look["overdispersion"]
    assert look["holdout_chi2_drop_verdict"] > look["holdout_chi2_drop"]
    assert "the held-out part decided" in explain_channel(out, 10)[0]


def test_a_noise_process_the_replicate_does_not_share_is_not_kept() -> None:
    """A random walk in this recording only (its own held-out half confirms it) is kept
    without replicates and refused when a replicate of the sensor does not show it (its
    systematic gap would rise beyond its scatter): recording-to-recording variation, not
    a property of the sensor (Samsung S5 gy, segment 2 with segment 3 as --holdout)."""
    rng = np.random.default_rng(31)
    n = int(1800 * RATE)
    walk = np.cumsum(3e-4 * math.sqrt(1.0 / RATE) * rng.standard_normal(n))
    rec = Series(white(rng, n) + walk, None, RATE, "rec")
    rep = Series(white(rng, n), None, RATE, "rep")
    opt = GapOptions(seed=4, realisations=6, effects=("random_walk", "flicker"))
    alone = diagnose_channel(MODEL, "gx", rec, opt)
    assert alone.verdict == "random_walk"
    checked = diagnose_channel(MODEL, "gx", rec, opt, [rep])
    assert checked.verdict != "random_walk"
    shared = diagnose_channel(MODEL, "gx", rec, opt, [Series(
        white(rng, n) + np.cumsum(3e-4 * math.sqrt(1.0 / RATE) * rng.standard_normal(n)),
        None, RATE, "rep2")])
    assert shared.verdict == "random_walk"


# ------------------------------------------------------------------ backward step
def _realiser(y: np.ndarray, model: NoiseModel = MODEL) -> Any:
    from imubench.gap.diagnose import _Realiser
    from imubench.gap.parts import PartSetup, RecordTemperature, seeds_of
    s = Series(y, None, RATE, "prune")
    n_fit = len(y) // 2
    cm = model["gx"]
    return _Realiser(model, "gx", s, seeds_of(3, 5), PartSetup(s.part(0, n_fit), cm),
                     PartSetup(s.part(n_fit, len(y)), cm), RecordTemperature(cm, s))


def test_backward_step_drops_an_effect_a_later_one_made_redundant() -> None:
    """A weak flicker kept before a ramp (the look-alike taking part of the ramp's excess
    first) adds nothing once the ramp is in: the backward step drops it and says why."""
    from imubench.gap.candidates import Candidate
    from imubench.gap.diagnose import PRUNE_REASON, _prune
    n = int(900 * RATE)
    y = white(np.random.default_rng(31), n) + 1e-4 * np.arange(n) / RATE
    r = _realiser(y)
    flicker = Candidate("flicker", {"flicker": 1e-4}, 1, accepted=True)
    ramp = Candidate("ramp", {"ramp": 1e-4}, 1, accepted=True)
    kept, dropped = _prune(r, [flicker, ramp])
    assert kept == [ramp] and dropped == [flicker]
    assert flicker.note.startswith(PRUNE_REASON) and not flicker.accepted
    assert ramp.fit is not None and ramp.holdout is not None  # re-scored as the first
    alone = r.step([]).before
    assert ramp.fit.gap_excess < 0.5 * alone.gap_excess


def test_backward_step_keeps_two_real_effects() -> None:
    from imubench.gap.candidates import Candidate
    from imubench.gap.diagnose import _prune
    n = int(900 * RATE)
    t = np.arange(n) / RATE
    y = (white(np.random.default_rng(32), n) + 1e-4 * t
         + 0.01 * np.sin(2 * math.pi * 3.3 * t + 0.4))
    sine = Candidate("sine", {"sine_amplitude": 0.01, "sine_freq": 3.3}, 2, accepted=True)
    ramp = Candidate("ramp", {"ramp": 1e-4}, 1, accepted=True)
    kept, dropped = _prune(_realiser(y), [sine, ramp])
    assert kept == [sine, ramp] and dropped == []


def test_backward_step_refits_the_base_model_of_the_reduced_set() -> None:
    """The reduced model of the drop-one test is refitted: a base-model refit that was
    made beside another term (here a white level set too low) is fitted again."""
    from imubench.gap.candidates import Candidate
    low = NoiseModel.single_term("gx", white=WHITE / 2)
    n = int(900 * RATE)
    y = white(np.random.default_rng(33), n) + 1e-4 * np.arange(n) / RATE
    r = _realiser(y, low)
    ramp = Candidate("ramp", {"ramp": 1e-4}, 1, accepted=True)
    base = Candidate("base_model", {"bandwidth_hz": 0.0, "filter_order": 1,
                                    "white": WHITE / 4}, 3, accepted=True)
    out = r.refit_base([base, ramp])
    assert out[1] is ramp and out[0] is not base and out[0].effect == "base_model"
    assert out[0].params["white"] == pytest.approx(WHITE, rel=0.1)
    assert r.refit_base([ramp]) == [ramp]


def test_verdict_is_the_kept_effect_whose_removal_costs_most() -> None:
    from imubench.gap.candidates import Candidate
    from imubench.gap.diagnose import _main_effect
    fl = Candidate("flicker", {"flicker": 1e-4}, 1, unique_chi2=60.0)
    ramp = Candidate("ramp", {"ramp": 1e-6}, 1, unique_chi2=1350.0)
    base = Candidate("base_model", {"white": 1e-3}, 3, unique_chi2=4500.0)
    assert _main_effect([fl, ramp, base]) is ramp  # the base model's refit is not a verdict
    assert _main_effect([base, fl]) is fl
    assert _main_effect([base]) is None
    # the p-value decides between different dof: 14 on 1 dof beats 16 on 3
    sine = Candidate("sine", {"sine_amplitude": 0.01, "sine_freq": 2.0}, 3, unique_chi2=16.0)
    fl.unique_chi2 = 14.0
    assert _main_effect([sine, fl]) is fl
    # an effect that only trims a huge refit of the base model is not the verdict (a
    # blind 15 Hz low-pass: refit 1.3e6, a quantization term 15, verdict was quantization)
    q = Candidate("quantization", {"quantization": 7e-6}, 1, unique_chi2=15.2)
    big = Candidate("base_model", {"white": 4e-3, "bandwidth_hz": 15.2}, 3,
                    unique_chi2=1.34e6)
    assert _main_effect([big, q]) is None
    q.unique_chi2 = 2000.0  # a real share of the gap: the effect stays the verdict
    assert _main_effect([big, q]) is q
    # a line is never a trim of the refit, however small beside it (a reviewer's filter +
    # sine: the verdict flipped between seeds at 1.4e-3 and 2.8e-4 of the refit)
    line = Candidate("sine", {"sine_amplitude": 0.003, "sine_freq": 21.2}, 2,
                     unique_chi2=274.0)
    big.unique_chi2 = 9.7e5
    assert _main_effect([big, line]) is line


def test_a_curvature_far_from_temp_ref_is_not_offered() -> None:
    """Temperatures 5.2-5.7 degC against temp_ref 25: the quadratic's coefficients at 25
    degC are an extrapolation (a reviewer read -39.3 dps/degC); the linear one stays."""
    from imubench.gap.candidates import _curvature_refusal
    cold = np.linspace(5.15, 5.72, 50)
    assert "too narrow and too far from temp_ref 25" in _curvature_refusal(cold, 25.0, -39.3)
    assert _curvature_refusal(np.linspace(20.0, 30.0, 50), 25.0, 0.01) == ""
    assert _curvature_refusal(np.linspace(15.0, 20.0, 50), 25.0, 0.01) == ""  # one span away
    n = int(900 * RATE)
    t = np.arange(n) / RATE
    temp = 5.4 + 0.28 * np.sin(2 * math.pi * t / 300.0)
    y = white(np.random.default_rng(41), n) + 0.02 * (temp - 5.4)
    d = diagnose_channel(MODEL, "gx", Series(y, temp, RATE, "cold"),
                         GapOptions(seed=3, realisations=5))
    assert d.verdict == "temperature"
    assert d.kept[0].params["temp_coeff2"] == 0.0
    assert d.kept[0].params["temp_coeff"] == pytest.approx(0.02, rel=0.1)


def test_evidence_plot_marks_a_sine_kept_after_the_verdict() -> None:
    """A reviewer's ramp + sine: verdict ramp, sine kept second; nothing showed the ramp
    and the spectrum panel did not mark the line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from imubench.gap.report import _evidence

    n = int(900 * RATE)
    t = np.arange(n) / RATE
    y = (1.15 * white(np.random.default_rng(51), n) + 2e-4 * t  # white 15 % above the
         + 0.008 * np.sin(2 * math.pi * 3.3 * t + 0.4))              # model's: bands fire
    d = diagnose_channel(MODEL, "gx", Series(y, None, RATE, "ramp+sine"),
                         GapOptions(seed=2, realisations=5))
    kept = [c.effect for c in d.kept]
    assert "sine" in kept and d.verdict == "ramp" and d.before.bands, (d.verdict, kept)
    fig, ax = plt.subplots()
    assert _evidence(ax, d) == "block means over time (fit part)"  # the ramp's own evidence
    fitted = next(ln for ln in ax.get_lines() if ln.get_label().startswith("ramp "))
    tt, yy = fitted.get_data()
    assert (yy[-1] - yy[0]) / (tt[-1] - tt[0]) == pytest.approx(2e-4, rel=0.1)
    plt.close(fig)
    d.verdict = "base_model"  # a verdict whose panel is the spectrum: the kept sine is marked
    fig, ax = plt.subplots()
    assert _evidence(ax, d) == "Welch spectrum (fit part)"
    assert any(ln.get_label() == "line 3.3 Hz" for ln in ax.get_lines())
    plt.close(fig)


def test_temperature_candidate_adds_only_what_the_model_lacks() -> None:
    """A model that already has 0.01 dps/degC, a record with 0.02: the candidate is the
    total 0.02, not 0.01 + 0.02 (the regression runs on the record less the model's own
    response; before, the model's coefficient was counted twice and the verdict was
    random_walk)."""
    rng = np.random.default_rng(21)
    n = int(3600 * RATE)
    t = np.arange(n) / RATE
    temp = 25.0 + 3.0 * np.sin(2 * np.pi * t / 1600) + np.sin(2 * np.pi * t / 470) + t / 3600
    y = white(rng, n) + 0.02 * (temp - 25.0)
    model = NoiseModel.single_term("gx", white=WHITE, temp_coeff=0.01)
    d = diagnose_channel(model, "gx", Series(y, temp, RATE, "t"),
                         GapOptions(seed=1, realisations=10))
    assert d.verdict == "temperature"
    assert d.kept[0].params["temp_coeff"] == pytest.approx(0.02, rel=0.05)


def test_two_level_ratio_stays_finite_far_from_both_levels() -> None:
    """A sample many noise sigmas from both levels (an impulse) gives a finite ratio,
    not -inf from an underflowed emission."""
    rng = np.random.default_rng(6)
    n = int(600 * RATE)
    tel = increment("telegraph", {"telegraph_step": 1.0, "telegraph_dwell_s": 10.0}, n,
                    RATE, 13)
    y = tel + 1e-4 * rng.standard_normal(n)
    y[n // 2] = 50.0  # exp(-(50 - 1)^2 / (2 noise_var)) underflows
    assert math.isfinite(two_level_llr(y, RATE, 1.0, 10.0, 600.0))


def _hour_at_10_hz() -> tuple[float, int, np.ndarray, np.ndarray, Any,
                             Callable[[], np.ndarray]]:
    """One hour at 10 Hz: (rate, samples, time s, temperature degC: +-3 degC at 25 min and
    +-1.2 at 7 min, the model (white 0.016 + flicker 0.0032, 4x the LSM6DSL's), a
    textbook generator of that noise, white plus FFT-shaped 1/f)."""
    from lsm6ds_sim.model import ChannelModel

    fs, n = 10.0, 36000
    t = np.arange(n) / fs
    temp = 26.0 + 3.0 * np.sin(2 * math.pi * t / 1500.0) + 1.2 * np.sin(
        2 * math.pi * t / 420.0)
    rng = np.random.default_rng(21)
    white, flicker = 0.016, 0.0032
    cm = ChannelModel().replace(white=white, flicker=flicker)
    freq = np.fft.rfftfreq(n, 1.0 / fs)
    s_fl = np.zeros_like(freq)
    s_fl[1:] = flicker**2 / (math.pi * freq[1:])

    def noise() -> np.ndarray:
        sd = np.sqrt(s_fl * fs * n / 4.0)
        x = sd * (rng.standard_normal(sd.size) + 1j * rng.standard_normal(sd.size))
        return white * math.sqrt(fs) * rng.standard_normal(n) + np.fft.irfft(x, n)

    return fs, n, t, temp, cm, noise


def test_record_temperature_test_uses_the_whole_record() -> None:
    """The whole-record temperature z (parts.RecordTemperature) against realisations of
    the model (textbook white + flicker generator): a response of 2.4e-3 dps/degC over
    noise 4x the LSM6DSL's is beyond Z_SLOPE on the record; 30 nulls stay within it; a
    response the realisations carry is not counted; the kept deterministic parts
    (det_sum) come off the realisations as the caller takes them off the record; without
    temperature the test is NaN; a ramp beside a drifting temperature is no response."""
    from imubench.gap.curves import Z_SLOPE
    from imubench.gap.parts import RecordTemperature, Series

    fs, n, t, temp, cm, noise = _hour_at_10_hz()

    rec = RecordTemperature(cm, Series(np.zeros(n), temp, fs))
    sims = np.array([noise() for _ in range(10)])
    response = 2.4e-3 * (temp - 25.0)
    assert rec.z(noise() + response, sims, 0.0) > Z_SLOPE
    nulls = np.array([rec.z(noise(), sims, 0.0) for _ in range(30)])
    assert np.all(np.abs(nulls) < Z_SLOPE)
    y = noise() + response
    kept = rec.z(y, sims + response, 0.0)
    assert abs(kept) < Z_SLOPE  # the realisations carry the response: nothing left
    # as a kept deterministic part: the record less it against the realisations less it
    assert abs(rec.z(y - response, sims + response, response) - rec.z(y - response, sims,
                                                                        0.0)) < 1e-9
    assert math.isnan(RecordTemperature(cm, Series(np.zeros(n), None, fs)).z(
        noise(), sims, 0.0))
    # a temperature that drifts (3 degC/h) and a level that trends (a ramp the model
    # lacks): the trend is fitted beside the slope, so the drift is no evidence
    warming = temp + 3.0 * t / 3600.0
    rec_w = RecordTemperature(cm, Series(np.zeros(n), warming, fs))
    assert abs(rec_w.z(noise() + 4e-6 * t, sims, 0.0)) < Z_SLOPE
    assert rec_w.z(noise() + 2.4e-3 * (warming - 25.0), sims, 0.0) > Z_SLOPE
    assert rec_w.note == ""
    # a temperature that only drifts, rounded as a logger does: no test, and why
    drift_only = np.round((26.0 + 2.0 * t / 3600.0) * 256.0) / 256.0
    rec_d = RecordTemperature(cm, Series(np.zeros(n), drift_only, fs))
    assert math.isnan(rec_d.z(noise() + 2.4e-3 * (drift_only - 25.0), sims, 0.0))
    assert "cannot be told from a ramp" in rec_d.note


def test_step_test_sees_through_a_temperature_response() -> None:
    """A temperature response of 0.06 dps/degC (+-3 degC at 25 min, +-1.2 at 7 min) widens
XX
    step test (statistic 2.8-4.0 against STEP_SIGMAS 5; 4.8-7.0 without the response).
    The record less its own GLS temperature response (parts.RecordTemperature.
    less_response) shows the step as without the response, and the slope it takes off
    is the response's; a record without a step stays at the null's level."""
    from imubench.gap.parts import RecordTemperature, Series
    from imubench.gap.step import STEP_SIGMAS

    fs, n, t, temp, cm, noise = _hour_at_10_hz()

    rec = RecordTemperature(cm, Series(np.zeros(n), temp, fs))
    response = 0.06 * (temp - 25.0)
    step = np.where(t >= 1234.0, 0.05, 0.0)
    hidden = seen = 0
    for _ in range(5):
        y = noise() + response + step
        raw = step_statistic(y)[0]
        less = step_statistic(rec.less_response(y[None, :])[0])[0]
        hidden += raw < STEP_SIGMAS
        seen += less > STEP_SIGMAS
        null = rec.less_response((noise() + response)[None, :])[0]
        assert step_statistic(null)[0] < 4.5
    assert hidden == 5 and seen == 5
    y = noise() + response
    taken = y - rec.less_response(y[None, :])[0]
    assert np.polyfit(temp, taken, 1)[0] == pytest.approx(0.06, rel=0.05)
    # without a usable temperature the rows come back unchanged
    flat = RecordTemperature(cm, Series(np.zeros(n), np.full(n, 25.0), fs))
    assert np.array_equal(flat.less_response(y[None, :]), y[None, :])


def test_a_located_step_is_fitted_beside_the_temperature_response() -> None:
    """Under a temperature that rises and levels off (5 -> 8 degC, no response at all), a
    permanent step took part of the temperature slope, and the record less that response
    kept a fraction of the step (an outside reviewer's CATS segment: a -0.92 dps step
    refused as a transient). Fitted beside it, the step stays whole."""
    from imubench.gap import evidence
    from imubench.gap.parts import RecordTemperature, Series

    fs, n, t, _, cm, noise = _hour_at_10_hz()
    warming = 5.0 + 3.0 * (1.0 - np.exp(-t / 1200.0))
    rec = RecordTemperature(cm, Series(np.zeros(n), warming, fs))
    assert rec.note == ""
    at = int(0.8 * n)
    y = noise() + np.where(np.arange(n) >= at, -0.5, 0.0)
    step = evidence.StepFit(at / fs, -0.5)
    plain = rec.less_response(y[None, :])[0]
    joint = rec.less_response(y[None, :], step_at=at)[0]
    assert abs(evidence.step_persistence(plain, fs, step) - 1.0) > 0.3  # bent by it
    assert evidence.step_persistence(joint, fs, step) == pytest.approx(1.0, abs=0.1)


def test_curvature_of_a_linear_response_on_a_slow_temperature_is_not_significant() -> None:
    """A linear response (1e-3 dps/degC) on a slow temperature (+-1.5 and +-0.8 degC at
    periods of 27 and 19 min) over white plus flicker: the flicker's wander gave the
    least-squares quadratic a curvature, and its coefficient at temp_ref 25 degC read
    -5.2e-4 dps/degC. The GLS curvature z under the model's covariance stays within the
    normal range on 30 such records (N(0, 1) under the null: spread near 1) and is large
    for a curvature well above its standard error (1.8e-3 dps/degC^2 here: on +-2 degC
    the squared temperature's increments follow the temperature's, r 0.95)."""
    from lsm6ds_sim.model import ChannelModel

    from imubench.gap.candidates import Z_CURVATURE, _flat_curvature

    fs, n = 10.0, 18000
    t = np.arange(n) / fs
    temp = (26.0 + 1.5 * np.sin(2 * math.pi * t / 1592.0 + 0.3)
            + 0.8 * np.sin(2 * math.pi * t / 1139.0 + 2.0) + t / 3600.0)
    rng = np.random.default_rng(17)
    white_d, flicker = 0.004 * 4.0, 0.0008 * 2.0
    cm = ChannelModel().replace(white=white_d, flicker=flicker)

    def noise() -> np.ndarray:
        return white_flicker(rng, n, fs, white_d, flicker)

    rt = RecordTemperature(cm, Series(np.zeros(n), temp, fs))
    linear = 1e-3 * (temp - 25.0)
    zs = np.array([rt.curvature_z(noise() + linear, 25.0) for _ in range(30)])
    assert np.all(np.abs(zs) < Z_CURVATURE), zs
    assert 0.5 < zs.std() < 1.5
    curved = noise() + linear + 0.02 * (temp - 25.0) ** 2
    assert rt.curvature_z(curved, 25.0) > 2 * Z_CURVATURE
    assert "not significant" in _flat_curvature(rt, noise() + linear, 25.0)
    assert _flat_curvature(rt, curved, 25.0) == ""
    assert _flat_curvature(None, curved, 25.0) == ""  # no covariance: the score decides


def test_a_curved_temperature_response_is_stated_at_the_records_mean() -> None:
    """The model file states temp_coeff at temp_ref; with a curvature the words and the
    JSON give the slope at the record's mean temperature (a reviewer read -5.2e-4
    dps/degC for a response of +1.3e-3 at 26.5 degC)."""
    from imubench.gap.explain import describe
    from imubench.gap.result import ChannelDiagnosis

    d = ChannelDiagnosis("gx", cast(Any, None), None, [], "temperature", {},
                         temp_mean_c=26.5, temp_ref_c=25.0)
    entry: dict[str, Any] = {"effect": "temperature",
                             "params": {"temp_coeff": -5.2e-4, "temp_coeff2": 6e-4}}
    d._slope_at_mean(entry)
    assert entry["temp_mean_c"] == 26.5
    assert entry["temp_slope_at_mean"] == pytest.approx(-5.2e-4 + 2 * 6e-4 * 1.5)
    units = {"temp_coeff": "dps/degC", "temp_coeff2": "dps/degC^2"}
    text = describe("temperature", entry["params"], units, entry)
    assert "0.00128 dps/degC at the record's mean 26.5 degC" in text, text
    assert "temp_coeff -0.00052 dps/degC" in text
    lin = {"effect": "temperature", "params": {"temp_coeff": 1e-3, "temp_coeff2": 0.0}}
    d._slope_at_mean(lin)
    assert lin["temp_slope_at_mean"] == pytest.approx(1e-3)
    assert describe("temperature", lin["params"], units, lin) == (
        "the rate drifts with temperature, 0.001 dps/degC")


def test_a_line_seen_at_the_output_is_simulated_at_its_seen_amplitude() -> None:
    """The model's sine is added before the output filter; a line fitted at the output is
    scaled back by |H(f)| (a resonance's height by |H(f)|^2), so that the model's
    realisations show the line as seen (a 14 Hz line after a 17.4 Hz filter came out 14 %
    small). Checked by a least-squares fit of the simulated output, not by the filter
    formula; the JSON and the words give both amplitudes."""
    from lsm6ds_sim.model import ChannelModel

    from imubench.gap.candidates import filter_power_gain
    from imubench.gap.explain import describe

    cm = ChannelModel().replace(white=1e-6, bandwidth_hz=17.4, filter_order=2)
    g2 = filter_power_gain(14.0, cm, RATE)
    a = 0.003 / math.sqrt(g2)
    assert a > 0.003 * 1.1
    n = int(200 * RATE)
    m = NoiseModel.single_term("gx", white=1e-6, bandwidth_hz=17.4, filter_order=2,
                               sine_amplitude=a, sine_freq=14.0)
    y = simulate(m, n, RATE, 5, channels=["gx"])["gx"][n // 4:]
    t = np.arange(n)[n // 4:] / RATE
    basis = np.column_stack([np.sin(2 * math.pi * 14.0 * t), np.cos(2 * math.pi * 14.0 * t)])
    c, *_ = np.linalg.lstsq(basis, y, rcond=None)
    assert math.hypot(*c) == pytest.approx(0.003, rel=0.01)
    assert filter_power_gain(14.0, ChannelModel(), RATE) == 1.0  # no filter
    deep = ChannelModel().replace(bandwidth_hz=2.0, filter_order=2)  # stop band: as seen
    assert filter_power_gain(40.0, deep, RATE) == 1.0
    sine = Candidate("sine", {"sine_amplitude": a, "sine_freq": 14.0}, 2, output_gain2=g2)
    seen = sine.at_output()
    assert seen["sine_amplitude_at_output"] == pytest.approx(0.003)
    entry = {"effect": "sine", "params": sine.params, **seen}
    text = describe("sine", sine.params, {"sine_amplitude": "dps"}, entry)
    assert text.startswith("a sinusoidal disturbance of amplitude 0.003 dps at 14 Hz as "
                           "recorded"), text
    assert Candidate("sine", sine.params, 2).at_output() == {}
    assert sine.as_recorded()["sine_amplitude"] == pytest.approx(0.003)
    assert sine.params["sine_amplitude"] == a  # the model file's stays


def test_the_held_out_check_leaves_a_sines_band_to_the_line_statistic() -> None:
    """The band holding a sine's line counts its power a second time beside the line
    statistic; the held-out check's drop leaves that band out for a sine candidate (blind
    pair filter + sine: that band's z went -17 -> -22 next to a refitted filter's
    continuum and outweighed the line's drop), and only for a sine."""
    import dataclasses

    from imubench.gap.curves import line_bands
    from imubench.gap.parts import PartSetup

    n = int(600 * RATE)
    rng = np.random.default_rng(3)
    part = PartSetup(Series(white(rng, n), None, RATE, "w"))
    before = part.compare(part.sim_features(np.array([white(rng, n) for _ in range(5)])))
    mask = line_bands("sine", {"sine_amplitude": 0.003, "sine_freq": 14.0}, part.edges)
    assert mask is not None and mask.sum() == 1
    i = int(np.flatnonzero(mask)[0])
    assert part.edges[i] <= 14.0 < part.edges[i + 1]
    assert line_bands("flicker", {"flicker": 1e-3}, part.edges) is None
    bz = before.band_z.copy()
    bz[i] -= 5.0  # the line's band moves away, the other bands do not move
    after = dataclasses.replace(before, band_z=bz)
    every = before.chi2_drop(after)["bands"]
    assert every == pytest.approx(before.band_z[i] ** 2 - bz[i] ** 2)
    assert before.chi2_drop(after, mask)["bands"] == pytest.approx(0.0, abs=1e-9)
    # the statistics part is the same either way (the band is not moved into it)
    assert before.chi2_drop(after, mask)["statistics"] == pytest.approx(
        before.chi2_drop(after)["statistics"])


def test_a_ramp_whose_held_out_part_drifts_otherwise_is_refused() -> None:
    """A response curved in temperature on a linear sweep is a parabola in time: the fit
    half drifts down, the held-out half up. A ramp fitted on the first half was kept
    after a random walk on the held-out Allan curve, which cannot see a drift's sign (an
    outside reviewer: ramp -1.16e-4 dps/s where the held-out half drifts +3.3e-4). The
    ramp is refused when the held-out part's own drift test points the other way; the
    temperature note says a curved response cannot be told from a drift curving in
    time."""
    model = NoiseModel.single_term("gx", white=0.004, flicker=0.0008)
    n = int(3600 * RATE)
    t = np.arange(n) / RATE
    temp = 10.0 + 40.0 * t / t[-1]
    y = (white_flicker(np.random.default_rng(2), n, RATE, 0.004, 0.0008)
         + 1e-3 * (temp - 25.0) ** 2)
    d = diagnose_channel(model, "gx", Series(y, temp, RATE, "sweep"),
                         GapOptions(seed=4, realisations=5))
    assert "ramp" not in [k.effect for k in d.kept]
    notes = [c.note for c in d.not_kept + d.pruned + d.candidates if c.effect == "ramp"]
    assert any("the held-out part drifts the other way" in x for x in notes), notes
    assert "nor a curved response from a drift that curves in time" in d.to_dict()[
        "temperature_note"]


def test_a_ramp_is_refused_where_the_held_out_part_drifts_the_other_way() -> None:
    """The held-out drift rule on its own: the second half of the sweep above, its
    parabola rising, drifts up at t > 7, which refuses a falling ramp fitted on the first
    half and not a rising one; a flat white half refuses neither."""
    from imubench.gap.diagnose import _drifts_the_other_way
    from imubench.gap.evidence import drift_statistic

    n = int(1800 * RATE)
    t = np.arange(n) / RATE
    temp = 32.5 + 17.5 * t / t[-1]
    rng = np.random.default_rng(3)
    rising = white_flicker(rng, n, RATE, 0.004, 0.0008) + 1e-3 * (temp - 25.0) ** 2
    t_hold, dof = drift_statistic(rising, RATE)
    assert t_hold > 7.0
    note = _drifts_the_other_way(-1.3e-4, t_hold, dof)
    assert note.startswith("the held-out part drifts the other way (drift t"), note
    assert _drifts_the_other_way(1.3e-4, t_hold, dof) == ""
    flat = white_flicker(rng, n, RATE, 0.004, 0.0)
    assert _drifts_the_other_way(-1.3e-4, *drift_statistic(flat, RATE)) == ""
    assert _drifts_the_other_way(-1.3e-4, math.nan, 1) == ""


def test_a_split_too_unequal_in_temperature_is_named_with_its_spans() -> None:
    """A warm-up that ends in the fit part leaves the held-out part at one temperature (an
    outside reviewer's 20 -> 30 degC, 600 s time constant: held-out part 29.5-30.0
    degC); one that starts in the held-out part leaves the fit part nothing to fit; a
    temperature that steps between the parts leaves each at one temperature. Each part
    is measured against the record's span (:func:`temperature_spans`); parts that both
    move are not too narrow, nor is a record without a temperature or a held-out part."""
    from imubench.gap.diagnose import temperature_spans

    y = np.zeros(100)
    warm = Series(y, np.linspace(20.0, 29.5, 100), RATE, "fit")
    flat = Series(y, np.linspace(29.5, 30.0, 100), RATE, "hold")
    assert temperature_spans(warm, flat) == pytest.approx((9.5, 0.5, 10.0))
    assert temperature_spans(flat, warm) == pytest.approx((0.5, 9.5, 10.0))
    stepped = (Series(y, np.full(100, 20.0), RATE, "f"), Series(y, np.full(100, 30.0), RATE, "h"))
    assert temperature_spans(*stepped) == pytest.approx((0.0, 0.0, 10.0))
    assert temperature_spans(warm, Series(y, np.linspace(25.0, 30.0, 100), RATE, "h")) is None
    assert temperature_spans(*(Series(y, np.full(100, 20.0), RATE, p) for p in "fh")) is None
    assert temperature_spans(warm, None) is None
    assert temperature_spans(Series(y, None, RATE, "f"), flat) is None


WARM_RATE = 20.0


def _warm_up_record(seed: int, coeff: float, start_s: float, walk: float = 0.0,
                    tau_s: float = 600.0) -> Series:
    """1 h at WARM_RATE of white 0.004 dps/sqrt(Hz) + flicker 0.0008 dps (+ a random walk
    ``walk`` dps/sqrt(s)) and a response ``coeff`` dps/degC to a warm-up from 20 to 30
    degC with a time constant ``tau_s`` that starts at ``start_s`` (0: in the fit part;
    1800: at the start of the held-out part), 0.01 degC steps."""
    rng = np.random.default_rng(seed)
    n = int(3600 * WARM_RATE)
    t = np.arange(n) / WARM_RATE
    temp = 20.0 + 10.0 * np.where(t > start_s, 1.0 - np.exp(-(t - start_s) / tau_s), 0.0)
    temp = np.round(temp / 0.01) * 0.01
    y = white_flicker(rng, n, WARM_RATE, 0.004, 0.0008) + coeff * (temp - 25.0)
    if walk:
        y += np.cumsum(rng.standard_normal(n)) * walk / math.sqrt(WARM_RATE)
    return Series(y, temp, WARM_RATE, "warm-up")


WARM_MODEL = NoiseModel.single_term("gx", white=0.004, flicker=0.0008)


@pytest.mark.parametrize("start_s", [0.0, 1800.0])
def test_a_response_to_a_warm_up_in_one_part_is_fitted_and_tested_on_the_whole_record(
        start_s: float) -> None:
    """A response of 1e-3 dps/degC to a warm-up in one half only: fitted on the fit part
    and checked on the held-out part, one of the two has nothing to work with, and the
    verdict was ``unexplained`` (or ``random_walk``) whichever half held it, up to 3e-3
    dps/degC (whole-record temperature z 14-16). Fitted on the whole record and tested by
    the whole-record temperature test, it is named, with its value within 20 % and three
    standard errors, and the text says why the held-out part is not its test."""
    series = _warm_up_record(1, 1e-3, start_s)
    d = diagnose_channel(WARM_MODEL, "gx", series, GapOptions(seed=3))
    out = d.to_dict()
    assert d.verdict == "temperature", out["reason"]
    k = out["kept"][0]
    assert k["fitted_on"] == "whole_record"
    assert k["holdout_check_applied"] is False
    coeff, se = k["params"]["temp_coeff"], k["params_se"]["temp_coeff"]
    assert abs(coeff - 1e-3) < min(0.2e-3, 3.0 * se), (coeff, se)
    spans = out["temperature_spans_c"]
    assert min(spans["fit_part"], spans["held_out"]) < 0.25 * spans["record"], spans
    text = "\n".join(explain_channel(out, 10))
    assert "Held-out check of temperature: not applied (the fit part's temperature spans" \
        in text, text
    assert ("the response is fitted on the whole record, so the held-out part is not its "
            "test" in text or "the temperature response is fitted on the whole record, the "
            "held-out part included, so for it this is not an independent check" in text), text


@pytest.mark.parametrize(("start_s", "seed", "walk", "tau_s"),
                         [(0.0, 1, 0.0, 600.0), (1800.0, 2, 0.0, 600.0),
                          (0.0, 103, 3e-4, 600.0), (0.0, 19, 3e-4, 300.0)])
def test_a_warm_up_without_a_response_is_not_named(start_s: float, seed: int,
                                                   walk: float, tau_s: float) -> None:
    """No response to the warm-up: no temperature is named, on the model's own noise nor
    beside an unmodelled random walk 3e-4 dps/sqrt(s) whose level follows the warm-up by
    chance (seed 103: whole-record temperature z -4.8 under the base model, named
    ``random_walk``). Seed 19 (300 s time constant, z 6.2 under the base model): the
    response, fitted on the whole record and kept first, stayed beside the walk (2.9e-3
    dps/degC) until the backward step dropped it, its whole-record test no longer firing
    under the walk's covariance."""
    series = _warm_up_record(seed, 0.0, start_s, walk, tau_s)
    d = diagnose_channel(WARM_MODEL, "gx", series, GapOptions(seed=3))
    assert "temperature" not in {c.effect for c in d.kept}, d.to_dict()["reason"]
    assert d.verdict == ("random_walk" if walk else "none")


def _cats_segments(reference_dir: Any, ch: str, orientation: int = 0
                   ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The CATS tag's static segment ``orientation`` (0: gravity on -z, 25.6 h at 1 Hz;
    1: on -x) of axis ``ch`` (accelerometer in g) cut into three equal parts, and their
    real temperatures."""
    rec = reference_dir / "imu-real" / "cats-tag-temperature"
    z = np.load(rec / "cats_temperature_calib.npz")
    rows = (rec / "events.csv").read_text().splitlines()
    first = [r.split(",") for r in rows[1:] if r.startswith("static")][orientation]
    i0, i1 = int(first[1]), int(first[2])
    y = z["accel_m_s2"][i0:i1, "xyz".index(ch[1])] / 9.80665
    temp = z["temperature_c"][i0:i1]
    n = len(y) // 3
    return ([y[i * n:(i + 1) * n] for i in range(3)],
            [temp[i * n:(i + 1) * n] for i in range(3)])


def test_a_real_warm_up_response_agrees_with_the_segment_the_diagnosis_never_saw(
        reference_dir: Any) -> None:
    """A real sensor nobody tuned on, with its own temperature: the CATS tag's ay, model
    from the noise fit of the first 8.5 h segment (no temperature term). In the second
    segment the temperature rises 5.3 -> 10.3 degC in the held-out half only; in the
    third, 10.8 -> 16 degC in the fit half only. The diagnosis of each names the
    response, fitted on the whole segment, and its coefficient agrees within 10 % with
    the least squares of the OTHER segment's 600 s block means on its temperature
    (-0.00226 and -0.00212 g/degC). Before, the third segment's verdict was
    ``base_model`` (the response refused by a held-out half at 0.5 degC) and the second's
    coefficient came from a fit half at 0.5 degC."""
    from imubench.noisefit import fit_channel

    ys, temps = _cats_segments(reference_dir, "ay")
    fit = fit_channel(ys[0], 1.0, terms="auto", channel="ay")
    model = NoiseModel.single_term("ay", **{k: v for k, v in fit.params.items() if v})

    def block_ols(y: np.ndarray, temp: np.ndarray) -> float:
        m = len(y) // 600 * 600
        yb, tb = y[:m].reshape(-1, 600).mean(1), temp[:m].reshape(-1, 600).mean(1)
        return float(np.polyfit(tb, yb, 1)[0])

    for seg, other in ((1, 2), (2, 1)):
        d = diagnose_channel(model, "ay", Series(ys[seg], temps[seg], 1.0, f"cats{seg}"),
                             GapOptions(seed=7))
        out = d.to_dict()
        assert d.verdict == "temperature", (seg, out["reason"])
        k = next(x for x in out["kept"] if x["effect"] == "temperature")
        assert k["fitted_on"] == "whole_record"
        truth = block_ols(ys[other], temps[other])
        assert abs(k["params"]["temp_coeff"] / truth - 1.0) < 0.1, (seg, k["params"], truth)


def test_a_response_the_model_carries_as_slow_noise_takes_its_place(
        reference_dir: Any) -> None:
    """The CATS tag's ay, second static orientation: the noise fit of the first 8.5 h
    segment, while the temperature rose 8 degC, holds a Gauss-Markov process (about 7e-4
    g, tau_c 760 s) that is that segment's temperature response. On the third segment a
    response added on top of it over-predicted the long taus, the held-out gap rose and
    the verdict was `unexplained`. The response now takes the place of part of the
    model's slow noise: named `temperature`, the Markov scaled down, the held-out gap
    closed by at least 80 %, the coefficient within 20 % of the other segment's block
    slope (-0.00236 g/degC), and the text says what was scaled and why."""
    from imubench.noisefit import fit_channel

    ys, temps = _cats_segments(reference_dir, "ay", orientation=1)
    fit = fit_channel(ys[0], 1.0, terms="auto", channel="ay")
    model = NoiseModel.single_term("ay", **{k: v for k, v in fit.params.items() if v})
    assert model["ay"].markov_sigma > 0
    d = diagnose_channel(model, "ay", Series(ys[2], temps[2], 1.0, "cats1-2"),
                         GapOptions(seed=7))
    out = d.to_dict()
    assert d.verdict == "temperature", out["reason"]
    k = next(x for x in out["kept"] if x["effect"] == "temperature")
    assert k["slow_terms_scale"] < 0.5
    assert k["params"]["markov_sigma"] < 0.5 * model["ay"].markov_sigma
    h = out["holdout"]
    assert h["gap_excess_after"] <= 0.2 * h["gap_excess_before"]
    m = len(ys[1]) // 600 * 600
    other = float(np.polyfit(temps[1][:m].reshape(-1, 600).mean(1),
                             ys[1][:m].reshape(-1, 600).mean(1), 1)[0])
    assert abs(k["params"]["temp_coeff"] / other - 1.0) < 0.2
    text = " ".join(explain_channel(out, 10))
    assert "in place of part of the model's slow terms (markov_sigma scaled by" in text
    # both causes, not the refit's alone (an outside reviewer's model had no response)
    assert ("a model fitted without one does not, and a slow term's realisation over one "
            "record also varies this much by chance") in text


def test_a_true_slow_noise_stays_beside_a_temperature_response() -> None:
    """The same mechanism must not take out slow noise the record holds: white 0.004
    dps/sqrt(Hz), a Gauss-Markov process of 0.01 dps with tau_c 120 s (numpy AR(1), as
    in the model) and a response of 0.01 dps/degC to a +-3 degC, 25 min temperature
    cycle, 1 h at 26 Hz: the kept response (within 3 standard errors of the truth) leaves
    the model's Markov as it is."""
    fs, n = 26.0, 3600 * 26
    rng = np.random.default_rng(5)
    t = np.arange(n) / fs
    temp = 25.0 + 3.0 * np.sin(2 * np.pi * t / 1500.0)
    a = math.exp(-1.0 / (120.0 * fs))
    gm = lfilter([0.01 * math.sqrt(1 - a * a)], [1.0, -a], rng.standard_normal(n))
    y = 0.004 * math.sqrt(fs) * rng.standard_normal(n) + gm + 0.01 * (temp - 25.0)
    model = NoiseModel.single_term("gx", white=0.004, markov_sigma=0.01, markov_tau=120.0,
                                   temp_ref=25.0)
    d = diagnose_channel(model, "gx", Series(y, temp, fs, "gm+temp"), GapOptions(seed=4))
    out = d.to_dict()
    k = next(x for x in out["kept"] if x["effect"] == "temperature")
    assert "slow_terms_scale" not in k and "markov_sigma" not in k["params"]
    assert abs(k["params"]["temp_coeff"] - 0.01) < 3.0 * k["params_se"]["temp_coeff"]


def test_a_response_the_model_carries_as_a_ramp_takes_its_place() -> None:
    """An outside reviewer's case in this generator: the default fit of a 20 -> 28 degC
    warm-up (0.01 dps/degC, white 0.004 dps/sqrt(Hz), 10 Hz, 1 h) wrote white and a ramp
    of 3.5e-5 dps/s; on the next warm-up the diagnosis kept a random walk and then the
    response, and the held-out gap widened 0.121 -> 0.315. The response now takes the
    ramp's place: `temperature`, the ramp scaled below a tenth, the held-out gap closed."""
    fs, n = 10.0, 36000
    rng = np.random.default_rng(103)
    t = np.arange(n) / fs
    temp = 20.0 + 8.0 * (1.0 - np.exp(-t / 600.0)) + 0.01 * rng.standard_normal(n)
    y = 0.004 * math.sqrt(fs) * rng.standard_normal(n) + 0.01 * (temp - 25.0)
    model = NoiseModel.single_term("gx", white=0.00396, ramp=3.5e-5, temp_ref=25.0)
    d = diagnose_channel(model, "gx", Series(y, temp, fs, "warm-up"), GapOptions(seed=7))
    out = d.to_dict()
    assert d.verdict == "temperature", out["reason"]
    k = next(x for x in out["kept"] if x["effect"] == "temperature")
    assert k["slow_terms_scale"] < 0.1 and k["params"]["ramp"] < 3.5e-6
    assert abs(k["params"]["temp_coeff"] / 0.01 - 1.0) < 0.1
    h = out["holdout"]
    assert h["gap_after"] < 0.5 * h["gap_before"]


def _analogue_lowpass(y: np.ndarray, fs: float, fc_hz: float) -> np.ndarray:
    """``y`` through the magnitude of a 2nd-order analogue Butterworth low-pass, zero
    phase, applied by FFT (|H|^2 = 1 / (1 + (f / fc)^4)): not the simulator's bilinear IIR,
    so the base model's refit cannot match it exactly."""
    f = np.fft.rfftfreq(y.size, 1.0 / fs)
    return np.fft.irfft(np.fft.rfft(y) / np.sqrt(1.0 + (f / fc_hz) ** 4), y.size)


def test_a_line_after_an_unmodelled_filter_is_kept_beside_the_base_model_refit() -> None:
    """A 15 Hz analogue low-pass the model lacks and a 3 mdps line at 14.6 Hz added after
    it (blind pair filter + sine): the refit of the base model is kept first and leaves
    short-tau residues of z 10-70 (its bilinear filter is not the analogue one); the sine
    judged against that refit as it stood raised the Allan and band chi-squared by more
    than its line statistic lowered it and was never kept. Fitted with the refit fitted
    again beside it, it is kept, at the amplitude seen in the record."""
    n = int(900 * RATE)
    rng = np.random.default_rng(2710)
    t = np.arange(n) / RATE
    y = (_analogue_lowpass(white_flicker(rng, n, RATE, WHITE, 0.0008), RATE, 15.0)
         + 0.003 * np.sin(2 * math.pi * 14.6 * t + 1.1))
    model = NoiseModel.single_term("gx", white=WHITE, flicker=0.0008)
    d = diagnose_channel(model, "gx", Series(y, None, RATE, "filter+sine"),
                         GapOptions(seed=12, realisations=6))
    kept = {c.effect: c for c in d.kept}
    assert {"base_model", "sine"} <= set(kept), list(kept)
    assert d.verdict == "sine"  # a line is never a trim of the refit
    assert kept["sine"].as_recorded()["sine_amplitude"] == pytest.approx(0.003, rel=0.1)
    assert kept["sine"].params["sine_freq"] == pytest.approx(14.6, abs=0.01)
    assert kept["base_model"].params["bandwidth_hz"] == pytest.approx(15.0, rel=0.25)


def test_the_base_model_refit_moves_smoothly_with_its_input_curve() -> None:
    """The refit's bandwidth grid steps by 14 %; the best grid point is refined between
    its neighbours, so a hair's change of the model curve (a negligible term fitted
    beside the refit) moves the refit by a hair, not by a grid step."""
    from imubench.gap.avarfit import fit_base_model
    from imubench.noisefit import model_avar

    cm = MODEL["gx"]
    tau = np.geomspace(1.0 / RATE, 300.0, 16)
    truth = cm.replace(bandwidth_hz=16.0, filter_order=2, white=0.0041)
    real = model_avar(truth, tau, RATE)
    sigma = np.full(tau.size, 0.01)
    base = model_avar(cm, tau, RATE)
    bw0, order0, w0 = fit_base_model(cm, tau, RATE, real, base, sigma)
    assert order0 == 2
    assert bw0 == pytest.approx(16.0, rel=0.01) and w0 == pytest.approx(0.0041, rel=0.005)
    bw1, _, w1 = fit_base_model(cm, tau, RATE, real, base * (1 + 1e-6 * tau / tau[-1]),
                                sigma)
    assert bw1 == pytest.approx(bw0, rel=1e-3) and w1 == pytest.approx(w0, rel=1e-3)


def test_a_markov_turnover_near_the_end_of_the_curve_is_tried_when_it_fits_better() -> None:
    """A Gauss-Markov process (textbook AR(1), sigma 0.005 dps, tau_c 12 s) on a 1200 s
    record: on the 600 s fit part (longest tau 79 s) it is fitted at tau_c 13 s, beyond
    the longest tau / MARKOV_SPAN (9.9 s), where it was refused and the record was called
    flicker. Its turnover fits the Allan curve better than a random walk or flicker by more
    than MARKOV_DESCENT, so it is now tried, and kept."""
    n = int(1200 * RATE)
    rng = np.random.default_rng(2)
    phi = math.exp(-1.0 / (RATE * 12.0))
    e = 0.005 * math.sqrt(1.0 - phi * phi) * rng.standard_normal(n)
    y = white(rng, n) + lfilter([1.0], [1.0, -phi], e, zi=[phi * 0.005 * rng.standard_normal()])[0]
    d = diagnose_channel(MODEL, "gx", Series(y, None, RATE, "markov"),
                         GapOptions(seed=1, realisations=5))
    assert d.verdict == "markov", d.to_dict()["not_fitted"]
    tau_max = float(d.before.tau_s[-1])
    tc = d.kept[0].params["markov_tau"]
    assert tau_max / MARKOV_SPAN < tc <= tau_max / MARKOV_SPAN_SHOWN
    assert tc == pytest.approx(12.0, rel=0.25)


def test_a_second_effect_is_tried_while_the_held_out_part_departs(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Flicker (B 0.0025 dps added to 0.0008) and a random walk (K 3e-4 dps/sqrt(s)) in
    one hour, textbook generators: after the flicker is kept nothing on the fit part is
    significant any more, but the held-out part still departs; the selection takes one
    more step, and the random walk passes the fit part's likelihood-ratio level and the
    held-out check (before: `flicker` alone, the held-out departure only reported)."""
    steps: list[tuple[int, bool, bool]] = []
    goes_on = diagnose._goes_on

    def spy(st: Step, k: int) -> bool:
        assert st.hold is not None
        steps.append((k, st.significant, st.hold.significant))
        return goes_on(st, k)

    monkeypatch.setattr(diagnose, "_goes_on", spy)
    n = int(3600 * RATE)
    rng = np.random.default_rng(2)
    y = white_flicker(rng, n, RATE, WHITE, math.hypot(0.0008, 0.0025)) + np.cumsum(
        3e-4 / math.sqrt(RATE) * rng.standard_normal(n))
    model = NoiseModel.single_term("gx", white=WHITE, flicker=0.0008)
    d = diagnose_channel(model, "gx", Series(y, None, RATE, "flicker + walk"),
                         GapOptions(seed=1, realisations=5))
    assert [c.effect for c in d.kept] == ["flicker", "random_walk"]
    assert (1, False, True) in steps  # the second step was taken on the held-out part
    walk = d.kept[1]
    assert walk.holdout is not None and walk.holdout_dchi2 > 0
    assert 1e-4 < walk.params["random_walk"] < 6e-4
    # the kept processes widen the model's own scatter, against which the excess after is
    # measured: the JSON states both
    h = d.to_dict()["holdout"]
    assert h["gap_null_after"] > h["gap_null"]


def test_the_markov_gate_says_which_of_its_conditions_failed() -> None:
    """A ramp on white noise: the Gauss-Markov fit tried at the first step has no
    turnover; ``not_fitted`` gives the fitted sigma and tau_c beside the longest tau_c
    allowed and the share of the model's noise at 3 tau_c (an outside reviewer read the rule, saw
    a true tau_c under the limit, and could not tell which condition had failed)."""
    n = int(600 * RATE)
    y = white(np.random.default_rng(4), n) + 1e-4 * np.arange(n) / RATE
    d = diagnose_channel(MODEL, "gx", Series(y, None, RATE, "ramp"),
                         GapOptions(seed=1, realisations=5))
    why = d.to_dict()["not_fitted"]["markov"]
    assert why.startswith("no Gauss-Markov turnover on the fit part"), why
    tc_max = float(why.split("(at most ")[1].split(" s, or ")[0])
    shown_max = float(why.split(" s, or ")[1].split(" s with its turnover")[0])
    share = float(why.split("turnover), ")[1].split(" of the model")[0])
    tc = float(why.split("fitted sigma ")[1].split("tau_c ")[1].split(" s")[0])
    better = float(why.rsplit(" by ", 1)[1])
    # the gate's own numbers show why it shut
    assert (tc > shown_max or (tc > tc_max and better <= MARKOV_DESCENT)
            or share < 0.5), why


def test_a_markov_process_beside_a_temperature_response_is_tried_once_the_response_is_kept(
        ) -> None:
    """A Gauss-Markov process (textbook AR(1), sigma 4.5 mdps, tau_c 30 s) and a temperature
    response of 6e-3 dps/degC on +-3 degC in one hour (an outside reviewer's pair). Once
    the response is kept the Markov fit is right, but the response's Allan variance,
    the same in every realisation, was most of the realisations' at 3 tau_c, so the
    Markov term's share stayed under MARKOV_DOMINANCE, it was never tried and a random
    walk was kept in its place. The share is now of the realisations' noise."""
    n = int(3600 * RATE)
    t = np.arange(n) / RATE
    rng = np.random.default_rng(4)
    phi = math.exp(-1.0 / (RATE * 30.0))
    e = 0.0045 * math.sqrt(1.0 - phi * phi) * rng.standard_normal(n)
    markov = lfilter([1.0], [1.0, -phi], e, zi=[phi * 0.0045 * rng.standard_normal()])[0]
    temp = (25.0 + 3.0 * np.sin(2 * math.pi * t / 1500.0 + 0.3)
            + 1.2 * np.sin(2 * math.pi * t / 430.0) + t / 3600.0)
    y = white(rng, n) + markov + 6e-3 * (temp - 25.0)
    d = diagnose_channel(MODEL, "gx", Series(y, temp, RATE, "markov + temperature"),
                         GapOptions(seed=1, realisations=5))
    kept = {c.effect: c.params for c in d.kept}
    assert set(kept) == {"temperature", "markov"}, d.to_dict()["not_fitted"]
    assert kept["temperature"]["temp_coeff"] == pytest.approx(6e-3, rel=0.15)
    assert kept["markov"]["markov_tau"] == pytest.approx(30.0, rel=0.35)
    assert kept["markov"]["markov_sigma"] == pytest.approx(0.0045, rel=0.25)
    # the first step's gate for the Markov process, shut then, is not reported against
    # the Markov kept later (an outside reviewer read it as a contradiction); the first
    # step's ranking says which effects were kept in the end
    out = d.to_dict()
    assert "markov" not in out["not_fitted"]
    assert [e["effect"] for e in out["effects"] if e["kept"]] == ["temperature"]


def test_a_step_hidden_in_white_noise_on_single_blocks_is_seen_across_several() -> None:
    """A 6 mdps bias step inside a block of an hour of white noise of 5 mdps/sqrt(Hz)
    (an outside reviewer's 10.6 mdps step beside flicker read 3.7 and was missed): the
    differences of single block means (14 s) across it stay under STEP_SIGMAS (3.6-4.9
    on six seeds), the means of several blocks on either side do not (8.0-11.0; the
    null's statistic 2.9-4.2); the step is located within a block, sized within 20 %,
    and named."""
    from imubench.gap.evidence import STEP_BLOCKS, block_means_of
    from imubench.gap.step import STEP_SIGMAS

    n = int(3600 * RATE)
    rng = np.random.default_rng(7)
    y = 0.005 * math.sqrt(RATE) * rng.standard_normal(n) + np.where(
        np.arange(n) / RATE >= 1367.0, -0.006, 0.0)
    m = block_means_of(y, n // STEP_BLOCKS)
    single = 0.0
    for lag in (1, 2):  # the single-block statistic alone
        d = m[lag:] - m[:-lag]
        mad = 1.4826 * np.median(np.abs(d - np.median(d)))
        single = max(single, float(np.max(np.abs(d - np.median(d)) / mad)))
    stat, _ = step_statistic(y)
    assert single < STEP_SIGMAS < stat
    st = fit_bias_step(y, RATE)
    assert st.step_time_s == pytest.approx(1367.0, abs=14.0)
    assert st.step_size == pytest.approx(-0.006, rel=0.2)
    model = NoiseModel.single_term("gx", white=0.005)
    d = diagnose_channel(model, "gx", Series(y, None, RATE, "step"),
                         GapOptions(seed=1, realisations=5))
    assert d.verdict == "bias_step", d.to_dict()["not_fitted"]


def test_a_markov_candidate_must_fit_the_allan_curve_better_than_its_look_alikes() -> None:
    """Flicker three times the model's (textbook FFT generator, white 4.9 mdps/sqrt(Hz),
    1 h at 104 Hz) is fitted by a Gauss-Markov term of tau_c 10-17 s, inside the span
    (longest tau / 8 = 39 s), that fits the Allan curve worse than flicker itself (by 8.6
    and 19.1): no Markov candidate. An outside reviewer's flicker beside a sine was
    replaced by such a Markov on a realisation score 0.5 lower. A true Markov of 4 mdps
    and 30 s (AR(1)) fits it better by far and is a candidate."""
    from lsm6ds_sim.model import ChannelModel

    from imubench.gap.candidates import fit_candidates
    from imubench.gap.parts import PartSetup

    white_d, b0 = 0.0049, 0.00076
    cm = ChannelModel().replace(white=white_d, flicker=b0)
    n = int(3600 * RATE)
    nf = n // 2

    def markov(rng: np.random.Generator, sigma: float, tau_c: float) -> np.ndarray:
        phi = math.exp(-1.0 / (RATE * tau_c))
        e = rng.normal(0.0, sigma * math.sqrt(1.0 - phi * phi), n)
        e[0] = rng.normal(0.0, sigma)
        return lfilter([1.0], [1.0, -phi], e)

    def first_step(y: np.ndarray, rng: np.random.Generator) -> tuple[list[str], Any]:
        fit = PartSetup(Series(y[:nf], None, RATE, "fit"), cm)
        cur = fit.sim_features(np.array([white_flicker(rng, nf, RATE, white_d, b0)
                                         for _ in range(10)]))
        cands, ev = fit_candidates(cm, fit, Series(y, None, RATE, "whole"),
                                   fit.compare(cur), cur, fit.compare(cur).sigma,
                                   ("markov", "flicker", "random_walk"),
                                   None, math.nan)
        return [c.effect for c in cands], ev["markov_fit"]

    for seed in (0, 2):
        rng = np.random.default_rng(seed)
        names, (_, tau_c, tau_c_max, share, descent) = first_step(
            white_flicker(rng, n, RATE, white_d, 3.0 * b0), rng)
        assert tau_c <= tau_c_max and share >= 0.5  # passed the span and the share
        assert descent < 0.0
        assert "markov" not in names and "flicker" in names
    rng = np.random.default_rng(0)
    names, (_, tau_c, tau_c_max, _, descent) = first_step(
        white_flicker(rng, n, RATE, white_d, b0) + markov(rng, 0.004, 30.0), rng)
    assert "markov" in names and descent > 10.0 and tau_c <= tau_c_max


def test_candidates_are_weighted_by_the_band_of_the_record_less_the_kept_responses() -> None:
    """After a temperature response is kept, the candidates' Allan-curve fits are weighted
    by the one-sigma band of the fit part less the response against the realisations less
    it (:attr:`imubench.gap.step.Step.noise_sigma`), the record's own confidence
    interval recomputed on the view (:meth:`imubench.gap.parts.PartSetup.less`). With the
    response in, every realisation holds it alike, and the band at the long taus is
    narrower than the noise's."""
    from imubench.gap.candidates import deterministic
    from imubench.gap.parts import PartSetup, seeds_of, simulate_channel

    n = int(1800 * RATE)
    t = np.arange(n) / RATE
    temp = 25.0 + 3.0 * np.sin(2 * math.pi * t / 1500.0)
    model = NoiseModel.single_term("gx", white=0.004, flicker=0.0008)
    cm = model["gx"]
    y = white_flicker(np.random.default_rng(5), n, RATE, 0.004, 0.0008) + 0.01 * (temp - 25)
    series = Series(y, temp, RATE, "temp")
    nf = n // 2
    fit, hold = PartSetup(series.part(0, nf), cm), PartSetup(series.part(nf, n), cm)
    kept = model.with_channel("gx", temp_coeff=0.01)
    det = deterministic("temperature", {"temp_coeff": 0.01, "temp_coeff2": 0.0}, cm, series)
    assert det is not None
    sims = simulate_channel(kept, "gx", series, seeds_of(3, 10))
    st = Step(fit, hold, sims, series, RecordTemperature(cm, series), det, cm)
    less = PartSetup(Series(y[:nf] - det[:nf], temp[:nf], RATE, "less"), cm)
    assert np.allclose(st.fit_part.ci_s, less.ci_s, equal_nan=True)
    assert np.allclose(st.noise_sigma, less.compare(st.noise_feats).sigma, equal_nan=True)
    # the response, alike in every realisation, narrows the band at the long taus (here
    # 0.11, 0.16, 0.25 against 0.14, 0.18, 0.33 at 39-158 s)
    assert np.all(st.before.sigma[-3:] < st.noise_sigma[-3:])
    # nothing kept: the band is the comparison's own
    st0 = Step(fit, hold, simulate_channel(model, "gx", series, seeds_of(3, 10)), series,
                RecordTemperature(cm, series), 0.0, cm)
    assert st0.noise_sigma is st0.before.sigma


def test_the_same_effects_kept_in_another_order_are_not_an_alternative() -> None:
    """The second start kept temperature + flicker where the first kept flicker +
    temperature, and the report offered it as an alternative "not taken because it does
    not score lower" (46.2 against 46.1; an outside reviewer): the same effects in another
    order are the same selection."""
    def path(*effects: str) -> Any:
        return diagnose._Path([Candidate(e, {}, 1) for e in effects], [], False, [], [], {})

    main, alt = path("flicker", "temperature"), path("temperature", "flicker")
    first = cast(Any, SimpleNamespace(hold=None))
    kept, gone = diagnose._better_start(cast(Any, None), first, main, alt)
    assert kept is main and gone == [] and main.alternative is None


@pytest.mark.parametrize(("s_alt", "h_alt", "taken"), [
    (17010.5, 0.171, True),    # the S5 gy ramp: worse on the fit part, held-out decides
    (17010.5, 0.500, False),   # held-out lower by less than its scatter: the fit part's
    (13000.0, 0.700, True),    # better on the fit part, held-out within its scatter
    (13000.0, 0.800, False),   # better on the fit part, held-out worse beyond it
])
def test_the_held_out_part_decides_between_two_selections_it_tells_apart(
        s_alt: float, h_alt: float, taken: bool) -> None:
    """Samsung S5 gy, segment 1, a ramp of -4.45e-4 dps/s added: the selection from the
    best-scoring candidate kept the base model's refit, a bias step and a random walk
    (fit part 13763.3 with the BIC penalty, held-out excess 0.627), the one with the
    fired drift test first a bias step, the ramp (-3.88e-4) and the refit (17010.5,
    0.171; scatter 0.146). On a fit part whose chi-squared is ~430 times its terms the
    score difference says little; the held-out part, which neither was fitted on, tells
    the two apart, and decides."""
    def path(*effects: str) -> Any:
        return diagnose._Path([Candidate(e, {}, 1) for e in effects], [], False, [], [], {})

    main, alt = path("base_model", "bias_step", "random_walk"), path("bias_step", "ramp")
    scores = {id(main.kept): (13763.3, 0.627), id(alt.kept): (s_alt, h_alt)}

    def step(kept: list[Candidate]) -> Any:
        s, h = scores[id(kept)]
        return SimpleNamespace(chi2=lambda: s - 3.0 * math.log(30.0),
                               before=SimpleNamespace(n_terms=30),
                               hold=SimpleNamespace(excess_moment=h))

    first = cast(Any, SimpleNamespace(hold=SimpleNamespace(gap_null=0.146)))
    kept, gone = diagnose._better_start(cast(Any, SimpleNamespace(step=step)), first,
                                        main, alt)
    assert (kept is alt) == taken
    if taken:
        assert [c.effect for c in gone] == ["base_model", "random_walk"]
        assert all("replaced by bias_step + ramp" in c.note for c in gone)
    else:
        assert main.alternative is not None and gone == []


def _walk_record(seed: int, coeff: float) -> tuple[NoiseModel, NoiseModel, Series]:
    """30 min at RATE of white 0.004 dps/sqrt(Hz) + flicker 0.0008 dps + a random walk
    3e-4 dps/sqrt(s), with a response ``coeff`` (dps/degC) to a temperature cycling +-3
    and +-1.2 degC at periods of 25 and 7 min: (the base model, the model with the walk,
    the record)."""
    from imubench.gap.parts import simulate_channel

    n = int(1800 * RATE)
    t = np.arange(n) / RATE
    temp = (26.0 + 3.0 * np.sin(2 * math.pi * t / 1500.0 + 0.4)
            + 1.2 * np.sin(2 * math.pi * t / 420.0 + 1.0))
    base = NoiseModel.single_term("gx", white=0.004, flicker=0.0008)
    walk = base.with_channel("gx", random_walk=3e-4)
    shape = Series(np.zeros(n), temp, RATE, "temp")
    y = simulate_channel(walk, "gx", shape, [seed])[0] + coeff * (temp - 26.0)
    return base, walk, Series(y, temp, RATE, "walk")


def test_the_temperature_slope_error_under_the_walks_covariance_is_the_slopes_scatter() -> None:
    """The GLS temperature slope of a model with a random walk, under that model's
    covariance of the block-mean increments (:meth:`RecordTemperature.for_model`): its
    standard error (:func:`imubench.gap.curves.gls_slopes`) matches the scatter of the
    slopes of 40 simulated records (the simulator's walk against the analytic covariance,
    :func:`imubench.noisefit.model_avar.block_increment_acv`), and that scatter is
    smaller than the slopes' under the base model's covariance (Aitken 1935: GLS is
    efficient under the noise's own covariance), whose standard error understates it."""
    from imubench.gap.curves import block_means, gls_slopes
    from imubench.gap.parts import seeds_of, simulate_channel

    base, walk, series = _walk_record(0, 0.0)
    sims = simulate_channel(walk, "gx", series, seeds_of(7, 40))
    rt = RecordTemperature(base["gx"], series)
    assert rt.tb is not None
    out = {}
    for name, m in (("walk", walk), ("base", base)):
        view = rt.for_model(m["gx"])
        assert view.chol is not None
        yb = np.array([block_means(s, view.n_block) for s in sims])
        slopes, se = gls_slopes(np.diff(yb, axis=1), np.diff(rt.tb), view.chol)
        out[name] = float(np.std(slopes, ddof=1)), float(np.median(se))
    (sd_walk, se_walk), (sd_base, se_base) = out["walk"], out["base"]
    # measured 4.9e-4 against 5.1e-4 (40 records: the scatter's own error is ~11 %)
    assert 0.75 < sd_walk / se_walk < 1.3
    assert sd_walk < 0.85 * sd_base  # measured 4.9e-4 against 6.5e-4
    assert se_base < 0.5 * sd_base  # measured 2.2e-4 against 6.5e-4
    assert rt.for_model(base["gx"]) is rt and rt.for_model(walk["gx"]) is rt.for_model(
        walk.with_channel("gx", temp_coeff=0.01)["gx"])  # one view per noise


def test_the_whole_record_temperature_test_beside_a_kept_walk_is_made_under_its_covariance(
) -> None:
    """With a random walk kept, the whole-record temperature test is made under the
    covariance of the model with the walk (:class:`imubench.gap.step.Step`'s
    ``noise``): a response of 2e-3 dps/degC beside a walk of 3e-4 dps/sqrt(s) fires
    there (z 3.8), and not under the base model's covariance (z 2.8), where the walk's
    slow increments are weighed as flicker's (blind pairs temperature 1e-3 + random walk
    3e-4 on the hour: z 1.5 and 2.6 after the walk under the base model's covariance, 3.1
    and 2.9 under the walk's)."""
    from imubench.gap.parts import PartSetup, seeds_of, simulate_channel

    base, walk, series = _walk_record(1001, 2e-3)
    n = len(series.y)
    cm0 = base["gx"]
    fit, hold = PartSetup(series.part(0, n // 2), cm0), PartSetup(series.part(n // 2, n), cm0)
    sims = simulate_channel(walk, "gx", series, seeds_of(3, 10))
    rt = RecordTemperature(cm0, series)
    under_walk = Step(fit, hold, sims, series, rt, 0.0, walk["gx"])
    under_base = Step(fit, hold, sims, series, rt, 0.0, cm0)
    assert under_walk.temp_fired and under_walk.temp_z > 3.6
    assert not under_base.temp_fired and under_base.temp_z < 3.0


def test_a_ramp_on_a_steady_temperature_drift_says_what_response_it_would_be() -> None:
    """A response of 3e-3 dps/degC to a temperature that drifts steadily (20 -> 25 degC
    over the hour, a 0.2 degC wiggle): the drift is named ``ramp`` (the temperature's
    increments barely vary), and nothing said that the temperature drifted the same way
    (an outside reviewer's CATS piece: a ramp of -4.88e-6 dps/s where the temperature fell
    at 0.75 degC/h, a response of 0.026 dps/degC). The ramp now comes with the response
    that gives its drift; on a temperature that cycles, nothing is said."""
    n = int(3600 * WARM_RATE)
    t = np.arange(n) / WARM_RATE
    temp = np.round((20.0 + 5.0 * t / 3600.0 + 0.2 * np.sin(2 * math.pi * t / 900)) / 0.01) * 0.01
    y = white_flicker(np.random.default_rng(4), n, WARM_RATE, 0.004, 0.0008) + 3e-3 * (
        temp - 25.0)
    out = diagnose_channel(WARM_MODEL, "gx", Series(y, temp, WARM_RATE, "drift"),
                           GapOptions(seed=3)).to_dict()
    assert out["verdict"] == "ramp", out["reason"]
    alias = out["ramp_temperature_alias"]
    assert alias["r_time"] > 0.99
    assert alias["temp_coeff_equivalent"] == pytest.approx(3e-3, rel=0.15)
    text = "\n".join(explain_channel(out, 10, {"temp_coeff": "dps/degC", "ramp": "dps/s"}))
    assert "The temperature drifted in step with time (r +1.00 over the record, 4.9 degC/h)" \
        in text, text
    cycling = 20.0 + 3.0 * np.sin(2 * math.pi * t / 1500.0)
    out = diagnose_channel(WARM_MODEL, "gx", Series(
        white_flicker(np.random.default_rng(4), n, WARM_RATE, 0.004, 0.0008) + 5e-6 * t,
        cycling, WARM_RATE, "ramp"), GapOptions(seed=3)).to_dict()
    assert out["verdict"] == "ramp" and out["ramp_temperature_alias"] is None


@pytest.mark.parametrize("coeff", [0.0, 2e-3])
def test_a_temperature_that_steps_between_the_parts_is_fitted_on_the_whole_record(
        coeff: float) -> None:
    """The temperature steps from 20 to 30 degC at the split, each part at one
    temperature: compared part with part the spans were both 0 and the split was kept,
    and a response of 2e-3 dps/degC was ``unexplained``. Against the record's span (10
    degC) each part holds too little, and the response is fitted and tested on the whole
    record; without a response nothing is named."""
    n = int(3600 * WARM_RATE)
    temp = np.where(np.arange(n) < n // 2, 20.0, 30.0)
    y = white_flicker(np.random.default_rng(2), n, WARM_RATE, 0.004, 0.0008) + coeff * (
        temp - 25.0)
    out = diagnose_channel(WARM_MODEL, "gx", Series(y, temp, WARM_RATE, "stepped"),
                           GapOptions(seed=3)).to_dict()
    assert out["temperature_spans_c"] == pytest.approx(
        {"fit_part": 0.0, "held_out": 0.0, "record": 10.0})
    if not coeff:
        assert out["verdict"] == "none", out["reason"]
        return
    assert out["verdict"] == "temperature", out["reason"]
    k = out["kept"][0]
    assert k["fitted_on"] == "whole_record"
    assert k["params"]["temp_coeff"] == pytest.approx(coeff, rel=0.1)


def test_a_short_markov_process_is_no_slow_term_a_response_can_stand_for() -> None:
    """An outside reviewer's Samsung S5 model (white, Markov of tau_c 1.26 s): beside a
    response to a temperature that cycles over 600-1500 s, its Markov was scaled by 0.81
    as if it carried the response. Only a Markov process whose Allan-deviation peak
    (1.89 tau_c) lies within a decade of the temperature's time scale counts as slow."""
    from imubench.gap.candidates import slow_terms
    from imubench.gap.parts import PartSetup

    fs, n = 10.0, 18000
    t = np.arange(n) / fs
    temp = (25.0 + 2.5 * np.sin(2 * np.pi * t / 1500.0)
            + 1.5 * np.sin(2 * np.pi * t / 600.0 + 1.0))
    y = np.random.default_rng(3).standard_normal(n)
    series = Series(y, temp, fs, "cycle")
    short = NoiseModel.single_term("gx", white=0.003, markov_sigma=0.05, markov_tau=1.26,
                                   random_walk=2e-4).channels["gx"]
    assert slow_terms(short, PartSetup(series, short)) == ("random_walk",)
    long = short.replace(markov_tau=760.0)
    assert slow_terms(long, PartSetup(series, long)) == ("random_walk", "markov_sigma")
    assert slow_terms(long, PartSetup(Series(y, None, fs, "no temperature"),
                                      long)) == ("random_walk", "markov_sigma")


def test_a_record_that_holds_its_output_is_said_to() -> None:
    """A phone gyro repeats ~18 % of its samples in runs of ~7 (Samsung S5 record); the
    realisations do not, so the short taus depart for that reason alone. The diagnosis
    says so (JSON ``held_samples``, and in words); a record that does not hold has None."""
    from imubench.gap.explain import explain_channel

    fs, n = 10.0, 18000
    rng = np.random.default_rng(8)
    y = 0.004 * math.sqrt(fs) * rng.standard_normal(n)
    held = y.copy()
    starts = rng.choice(n - 8, size=n // 40, replace=False)
    for s in starts:  # runs of 6 repeats after a fresh sample
        held[s + 1:s + 7] = held[s]
    model = NoiseModel.single_term("gx", white=0.004)
    out = diagnose_channel(model, "gx", Series(held, None, fs, "held"),
                           GapOptions(seed=1, standard_errors=False)).to_dict()
    h = out["held_samples"]
    assert h is not None and 0.1 < h["share"] < 0.2 and h["median_hold_samples"] == 7
    assert "The record holds its output" in " ".join(explain_channel(out, 10))
    plain = diagnose_channel(model, "gx", Series(y, None, fs, "plain"),
                             GapOptions(seed=1, standard_errors=False)).to_dict()
    assert plain["held_samples"] is None
    assert "holds its output" not in " ".join(explain_channel(plain, 10))
    # every value held for 7 samples (a reviewer's record crashed the outliers fit: its
    # robust sigma far below the jumps put both ends of the root bracket on one side)
    whole = diagnose_channel(model, "gx", Series(np.repeat(y[::7], 7)[:n], None, fs, "all"),
                             GapOptions(seed=1, standard_errors=False)).to_dict()
    assert whole["held_samples"]["median_hold_samples"] == 7
