"""The resonance noise term: model keys, simulator generator, AVAR column, fit extension.

Independent checks: the generator against Welch's PSD estimate (centre, -3 dB width,
peak height) and the AVAR column against the overlapping ADEV of long simulated records
(estimator vs generator); the fit against simulated records with and without a
resonance, and against the ADIS16405 gz replicates (20 Hz resonance).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from lsm6ds_sim.model import NoiseModel, load_model
from lsm6ds_sim.noise import Resonance, term_rng
from lsm6ds_sim.physics import simulate
from scipy.signal import welch

from imubench.cli import main
from imubench.errors import ModelError
from imubench.gap import extras
from imubench.noisefit import fit_channel
from imubench.noisefit.errors import FitError
from imubench.noisefit.kernels import resonance_avar
from imubench.stats import oadev
from tests.test_fit_cli import write_recording
from tests.test_noisefit import _adis

FS = 100.0
RES = {"resonance_freq_hz": 19.7, "resonance_width_hz": 1.8, "resonance_height": 4e-4}
TRUTH = {"white": 0.004, "resonance_freq_hz": 19.7, "resonance_width_hz": 1.8,
         "resonance_height": 4e-4}
"""White 0.004 dps/sqrt(Hz) (one-sided PSD 3.2e-5) and a resonance 12.5x above it."""


# ------------------------------------------------------------------ model file
def test_keys_round_trip_through_the_toml(tmp_path: Path) -> None:
    model = NoiseModel.single_term("gz", white=0.01, **RES)
    path = tmp_path / "m.toml"
    path.write_text(model.to_toml())
    back = load_model(path)
    assert back.to_dict() == model.to_dict()
    assert back["gz"].resonance_freq_hz == 19.7 and back["gz"].resonance_height == 4e-4


@pytest.mark.parametrize("given", [
    {"resonance_height": 1e-3},
    {"resonance_freq_hz": 20.0, "resonance_height": 1e-3},
    {"resonance_freq_hz": 20.0, "resonance_width_hz": 1.0},
])
def test_a_resonance_needs_all_three_keys(tmp_path: Path, given: dict[str, float]) -> None:
    text = "[channels.gz]\n" + "".join(f"{k} = {v}\n" for k, v in given.items())
    path = tmp_path / "m.toml"
    path.write_text(text)
    with pytest.raises(ModelError, match=r"\[channels\.gz\].*needs .*resonance_") as exc:
        load_model(path)
    missing = {"resonance_freq_hz", "resonance_width_hz", "resonance_height"} - set(given)
    assert all(k in str(exc.value) for k in missing)


def test_negative_width_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "m.toml"
    path.write_text("[channels.gz]\nresonance_freq_hz = 20.0\nresonance_width_hz = -1.0\n"
                    "resonance_height = 1e-3\n")
    with pytest.raises(ModelError, match=r"resonance_width_hz.*>= 0"):
        load_model(path)


def test_centre_at_or_above_nyquist_is_refused_when_simulating() -> None:
    model = NoiseModel.single_term("gz", resonance_freq_hz=60.0, resonance_width_hz=2.0,
                                   resonance_height=1e-3)
    with pytest.raises(ModelError, match=r"\[channels.gz\] resonance_freq_hz = 60 Hz.*"
                                         r"Nyquist.*50 Hz"):
        simulate(model, 1000, FS, 1, channels=["gz"])


# ------------------------------------------------------------------ generator
def test_generator_centre_width_and_height_by_welch() -> None:
    """Welch PSD (Hann, 8192-sample segments: 0.012 Hz bins, many averages) of a pure
    resonance: peak at f0, the bins above half the peak span the -3 dB width, and the
    mean PSD within +-0.1 Hz of f0 is the height (a Lorentzian drops 1 % there)."""
    y = simulate(NoiseModel.single_term("gz", **RES), 1 << 21, FS, 3, channels=["gz"])["gz"]
    f, p = welch(y, fs=FS, nperseg=8192)
    smooth = np.convolve(p, np.ones(9) / 9, mode="same")
    assert f[int(np.argmax(smooth))] == pytest.approx(19.7, abs=0.05)
    top = float(np.mean(p[np.abs(f - 19.7) <= 0.1]))
    assert top == pytest.approx(RES["resonance_height"], rel=0.05)
    above = f[smooth >= top / 2]
    assert above.max() - above.min() == pytest.approx(1.8, rel=0.05)
    # the variance is the height times a Lorentzian line's noise bandwidth, pi/2 width
    assert np.var(y) == pytest.approx(4e-4 * math.pi / 2 * 1.8, rel=0.08)


def test_generator_wings_are_lorentzian() -> None:
    """Away from the centre the line keeps the Lorentzian's wings H / (1 + (2 (f - f0) /
    w)^2), the shape the gap tool fits (docs/gap.md), and a floor at 0 Hz: Welch PSD
    averaged over +-0.25 Hz at 2-8 widths from f0 = 19.7 Hz and below 1 Hz, against the
    Lorentzian at +-f0 and their aliases (a sampled damped cosine; the aliases add 6-8 %
    at 8 widths; each estimate the mean of ~1000 chi2_2 bins: 3 %). A second-order
    band-pass of the same width (the generator until 2026-12-06) has 0.16x this 8 widths
    below the centre, 0.65x 4 widths below, 0.60x 8 widths above and nothing at 0 Hz."""
    h, f0, w = RES["resonance_height"], RES["resonance_freq_hz"], RES["resonance_width_hz"]
    y = simulate(NoiseModel.single_term("gz", **RES), 1 << 21, FS, 5, channels=["gz"])["gz"]
    f, p = welch(y, fs=FS, nperseg=8192)

    def lorentz(x: np.ndarray) -> np.ndarray:
        alias = FS * np.arange(-200, 201)[:, None]
        return np.sum(h / (1 + (2 * (x - f0 - alias) / w) ** 2)
                      + h / (1 + (2 * (x + f0 - alias) / w) ** 2), axis=0)

    for centre in (f0 - 8 * w, f0 - 4 * w, f0 - 2 * w, f0 + 2 * w, f0 + 4 * w, f0 + 8 * w,
                   0.5):
        near = np.abs(f - centre) <= 0.25 if centre > 0.5 else (f > 0) & (f <= 1.0)
        assert float(np.mean(p[near] / lorentz(f[near]))) == pytest.approx(1.0, abs=0.1), \
            centre


def test_gap_increment_is_the_simulator_generator() -> None:
    """gap's resonance effect draws the simulator's generator from its own stream."""
    got = extras.increment("resonance", dict(RES), 5000, FS, seed=4)
    rng = np.random.default_rng([4, 0x6A9, 3])
    want = Resonance(RES["resonance_height"], RES["resonance_freq_hz"],
                     RES["resonance_width_hz"], rng).generate(5000, 1 / FS, np.arange(5000) / FS)
    np.testing.assert_array_equal(got, want)


def test_stationary_from_the_first_sample() -> None:
    """The variance of sample 0 over many seeds is the stationary variance (no transient)."""
    def gen(seed: int) -> Resonance:
        return Resonance(1.0, 19.7, 1.8, term_rng(seed, 2, "resonance"))

    first = [gen(s).generate(1, 0.01, np.zeros(1))[0] for s in range(3000)]
    y = gen(1).generate(1 << 20, 0.01, np.zeros(0))
    assert np.var(first) == pytest.approx(np.var(y), rel=0.08)


# ------------------------------------------------------------------ AVAR column
@pytest.mark.parametrize(("f0", "width", "bandwidth"), [(19.7, 1.8, 0.0), (6.0, 0.4, 0.0),
                                                        (19.7, 1.8, 15.0)])
def test_avar_column_matches_oadev_of_simulated_records(f0: float, width: float,
                                                        bandwidth: float) -> None:
    """The column (closed form at the complex pole) against the overlapping ADEV of 6 h of
    the generator's output (through the output low-pass when given): within 3 % in AVAR
    up to tau = 0.64 s, where the estimates have EDF > 1e4, and within 12 % at 1.28-5.12 s
    (EDF > 600), where the lines' floor near 0 Hz makes the AVAR fall as 1/tau (a
    frequency-domain integral that averaged the kernel there was 2x low at 2.56 s)."""
    model = NoiseModel.single_term("gz", resonance_freq_hz=f0, resonance_width_hz=width,
                                   resonance_height=1e-3, bandwidth_hz=bandwidth)
    y = simulate(model, 1 << 21, FS, 7, channels=["gz"])["gz"]
    m = 2 ** np.arange(0, 10)
    meas = oadev(y, FS, "freq", list(m / FS)).var
    col = 1e-3 * resonance_avar(m, FS, f0, width, bandwidth, 1)
    np.testing.assert_allclose(meas[:7], col[:7], rtol=0.03)
    np.testing.assert_allclose(meas[7:], col[7:], rtol=0.12)


@pytest.mark.parametrize(("rate", "f0", "width", "bandwidth", "order"), [
    (100.0, 19.7, 1.8, 0.0, 1), (100.0, 19.7, 1.8, 15.0, 2), (6660.0, 100.0, 3.0, 50.0, 2),
    (104.0, 40.0, 20.0, 2.0, 2)])  # the last: the line dies within the filter's length
def test_avar_column_equals_the_direct_sum_of_its_autocovariance(
        rate: float, f0: float, width: float, bandwidth: float, order: int) -> None:
    """The closed form (complex pole, filtered tail) against the Allan sum of the
    autocovariance var r^k cos(w0 k) convolved with the filter's, lag by lag to 2 max m:
    the algebra, not the model (the model is checked against simulated records above)."""
    from lsm6ds_sim.noise import resonance_drive

    from imubench.noisefit.kernels import avar_from_gacv, filter_autocorrelation

    m = np.unique(np.geomspace(1, 3000, 25).astype(np.int64))
    pole, s2 = resonance_drive(f0, width, rate)
    rho = filter_autocorrelation(bandwidth, order, rate)
    j = rho.size - 1
    lags = np.arange(-j, 2 * int(m.max()) + 10 + j + 1)
    g = np.convolve((pole ** np.abs(lags)).real, np.concatenate([rho[:0:-1], rho]), "valid")
    want = s2 / (1 - abs(pole) ** 2) * avar_from_gacv(g, m)
    np.testing.assert_allclose(resonance_avar(m, rate, f0, width, bandwidth, order), want,
                               rtol=1e-11)


def test_model_edf_and_correlation_with_a_resonance_match_monte_carlo() -> None:
    """The covariance model with the resonance's spectrum against 150 simulated records
    (white + resonance, 2^15 samples): EDF and the correlation of neighbouring octaves.
    Without the resonance the model EDF at m = 2 was 17x too high, and Greenhall-Riley's
    (white noise) 2.4x."""
    from imubench.noisefit.covariance import oavar_correlation, oavar_edf

    n, m = 1 << 15, np.array([1, 2, 4, 8, 16])
    est = np.array([oadev(simulate(NoiseModel.single_term("gz", **TRUTH), n, FS, s,
                                   channels=["gz"])["gz"], FS, "freq", list(m / FS)).var
                    for s in range(150)])
    mc_edf = 2 * est.mean(0) ** 2 / est.var(0)
    amp2 = {"white": 0.004**2, "resonance": 4e-4}
    model = 0.004**2 * FS / m + 4e-4 * resonance_avar(m, FS, 19.7, 1.8)
    edf = oavar_edf(m, n - 2 * m, amp2, model, FS, resonance=(19.7, 1.8))
    np.testing.assert_allclose(edf / mc_edf, 1.0, atol=0.3)
    corr = oavar_correlation(m, n - 2 * m, amp2, FS, resonance=(19.7, 1.8))
    mc_corr = np.corrcoef(est.T)
    np.testing.assert_allclose(corr[0, 1:3], mc_corr[0, 1:3], atol=0.12)


def test_avar_column_is_what_model_avar_sums() -> None:
    from imubench.noisefit.model_avar import model_avar

    cm = NoiseModel.single_term("gz", white=0.01, **RES)["gz"]
    tau = np.array([0.01, 0.02, 0.05, 1.0])
    m = np.rint(tau * FS).astype(np.int64)
    want = 0.01**2 / tau + 4e-4 * resonance_avar(m, FS, 19.7, 1.8)
    np.testing.assert_allclose(model_avar(cm, tau, FS), want, rtol=1e-12)


# ------------------------------------------------------------------ fit


def test_fit_recovers_a_simulated_resonance() -> None:
    y = simulate(NoiseModel.single_term("gz", **TRUTH), 1 << 20, FS, 12, channels=["gz"])["gz"]
    f = fit_channel(y, FS, channel="gz")
    assert "resonance_height" in f.present, f.reasons["resonance"]
    assert f.reasons["resonance"].startswith("kept")
    assert f.params["resonance_freq_hz"] == pytest.approx(19.7, abs=0.4)  # 2 bins of 0.2 Hz
    lo, hi = f.ci["resonance_height"]
    assert lo <= 4e-4 <= hi, (lo, hi, f.params["resonance_height"])
    assert f.params["white"] == pytest.approx(0.004, rel=0.05)
    assert "sine_amplitude" not in f.present


def test_fit_adds_no_resonance_without_a_peak() -> None:
    truth = {"white": 0.004, "flicker": 0.001, "bandwidth_hz": 20.0, "filter_order": 2}
    y = simulate(NoiseModel.single_term("gz", **truth), 1 << 20, FS, 13, channels=["gz"])["gz"]
    f = fit_channel(y, FS, channel="gz")
    assert "resonance_height" not in f.present
    assert f.reasons["resonance"].startswith("dropped"), f.reasons["resonance"]


def test_explicit_terms_fit_a_resonance_only_at_a_peak() -> None:
    """terms="white,resonance": fitted at the peak; refused where the spectrum has none,
    and by the whittle method (it does not model a resonance)."""
    y = simulate(NoiseModel.single_term("gz", **TRUTH), 1 << 19, FS, 14, channels=["gz"])["gz"]
    f = fit_channel(y, FS, channel="gz", terms="white,resonance")
    assert f.params["resonance_freq_hz"] == pytest.approx(19.7, abs=0.4)
    assert f.params["resonance_width_hz"] == pytest.approx(1.8, rel=0.2)
    assert f.params["resonance_height"] == pytest.approx(4e-4, rel=0.2)
    white = simulate(NoiseModel.single_term("gz", white=0.004), 1 << 19, FS, 14,
                     channels=["gz"])["gz"]
    with pytest.raises(FitError, match="narrowband peak"):
        fit_channel(white, FS, channel="gz", terms="white,resonance")
    with pytest.raises(FitError, match="wls only"):
        fit_channel(y, FS, channel="gz", terms="white,resonance", method="whittle")


@pytest.mark.parametrize("rep", [1, pytest.param(2, marks=pytest.mark.slow),
                                 pytest.param(3, marks=pytest.mark.slow)])
def test_adis16405_gz_resonance_closes_the_short_tau_misfit(reference_dir: Path,
                                                             rep: int) -> None:
    """ADIS16405 gz: without a resonance term the model was off by ln(ADEV/model) = +0.28
    at tau = 0.02 s (rep 1); with it the fit keeps a resonance near 19.5-20 Hz and the
    misfit at 0.01-0.04 s is below 0.05."""
    y = _adis(reference_dir, rep, "gz")
    f = fit_channel(y, FS, channel="gz")
    assert "resonance_height" in f.present, f.reasons["resonance"]
    assert 19.3 <= f.params["resonance_freq_hz"] <= 20.2
    meas = oadev(y, FS, "freq", [0.01, 0.02, 0.04])
    misfit = np.log(meas.dev / np.sqrt(f.model_avar(meas.tau_s)))
    assert np.all(np.abs(misfit) < 0.05), misfit
    # a width at the search's edge fixes the band's power, not the peak: no interval is
    # stated for the height and width then (one was printed, 1 % wide, on a height 1.6x
    # the spectrum's); otherwise both have one
    at_edge = "the width is the" in f.reasons["resonance"]
    for key in ("resonance_height", "resonance_width_hz"):
        assert all(np.isfinite(f.ci[key])) != at_edge, (key, f.ci[key], f.reasons)


# ------------------------------------------------------------------ CLI
def test_fit_writes_the_resonance_and_report_reads_it(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    """imubench fit -o writes the fitted resonance to the model file; report --model
    reads it back (its keys with units in fit.json)."""
    model = NoiseModel.quiet().with_all(white=0.004).with_channel(
        "gz", white=0.004, resonance_freq_hz=20.0, resonance_width_hz=2.0,
        resonance_height=5e-4)
    rec = write_recording(tmp_path / "r.imbr", model, 200_000)
    out = tmp_path / "fit.toml"
    assert main(["fit", str(rec), "--channels", "gz", "-o", str(out)]) == 0, \
        capsys.readouterr().err
    fitted = load_model(out)["gz"]
    assert fitted.resonance_height > 0 and abs(fitted.resonance_freq_hz - 20.0) < 0.5
    rep = tmp_path / "rep"
    assert main(["report", str(rec), "--model", str(out), "--out", str(rep)]) == 0, \
        capsys.readouterr().err
    doc = json.loads((rep / "fit.json").read_text())
    gz = doc["channels"]["gz"]
    assert gz["params"]["resonance_height"] == pytest.approx(fitted.resonance_height)
    assert {"resonance_height", "resonance_freq_hz", "resonance_width_hz"} <= set(gz["present"])


def test_whittle_says_it_does_not_model_a_peak_it_sees() -> None:
    """--method whittle (auto) on a record with a resonance: a reason and a note say the
    peak is there and not modelled (it had turned into Markov and quantization terms
    without a word); on a record without one, no such reason."""
    y = simulate(NoiseModel.single_term("gz", **TRUTH), 1 << 19, FS, 15, channels=["gz"])["gz"]
    f = fit_channel(y, FS, channel="gz", method="whittle")
    assert f.reasons["resonance"].startswith("not fitted: a narrowband peak at 19")
    assert any("not modelled by --method whittle" in n for n in f.notes)
    white = simulate(NoiseModel.single_term("gz", white=0.004), 1 << 19, FS, 15,
                     channels=["gz"])["gz"]
    assert "resonance" not in fit_channel(white, FS, channel="gz", method="whittle").reasons


def test_psd_model_line_holds_a_peak_narrower_than_its_band() -> None:
    """The report's PSD overlay averages the resonance over each log band as the measured
    band PSD does: a 0.5 Hz wide peak at 20.8 Hz was drawn at the band centre, half the
    measured level. Checked against the band PSD of a simulated record (generator vs
    the overlay's own formula)."""
    from imubench.noisefit.recording_fit import channel_from_model
    from imubench.noisefit.spectrum import band_psd, term_psds

    truth = {"white": 0.004, "resonance_freq_hz": 20.8, "resonance_width_hz": 0.5,
             "resonance_height": 0.05}
    cm = NoiseModel.single_term("gz", **truth)["gz"]
    y = simulate(NoiseModel.single_term("gz", **truth), 1 << 19, FS, 16, channels=["gz"])["gz"]
    bands = band_psd(y, FS)
    model = sum(term_psds(channel_from_model(cm, y, FS, "gz"), bands).values())
    i = int(np.argmax(bands.psd))
    assert bands.f_low_hz[i] <= 20.8 <= bands.f_high_hz[i]
    assert model[i] / bands.psd[i] == pytest.approx(1.0, abs=0.15)
