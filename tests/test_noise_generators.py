"""Noise generators: seamless chunking, determinism, spectra (scipy.signal.welch), exact AVAR.

Spectral checks use published PSD shapes (IEEE Std 952 Annex C, one-sided S_y(f)):
white 2 N^2 (flat), flicker B^2/(pi f) (slope -1), random walk K^2/(2 pi^2 f^2) (slope -2),
quantization (rate = difference of white angle errors) rising as f^2 at low f,
Gauss-Markov Lorentzian 4 sigma^2 tau_c / (1 + (2 pi f tau_c)^2).
"""

from __future__ import annotations

import math

import allantools
import numpy as np
import pytest
from lsm6ds_sim import noise as nz
from lsm6ds_sim.model import NoiseModel
from lsm6ds_sim.physics import SensorPhysics, simulate
from scipy.signal import welch

RATE = 104.0
DT = 1.0 / RATE

TERMS: dict[str, dict[str, float]] = {
    "white": {"white": 0.004},
    "flicker": {"flicker": 0.001},
    "random_walk": {"random_walk": 0.001},
    "ramp": {"ramp": 1e-4},
    "quantization": {"quantization": 1e-4},
    "markov": {"markov_sigma": 0.01, "markov_tau": 2.0},
    "sine": {"sine_amplitude": 0.01, "sine_freq": 1.7},
    "resonance": {"resonance_freq_hz": 20.0, "resonance_width_hz": 2.0,
                  "resonance_height": 1e-4},
    "outliers": {"outlier_rate": 2.0, "outlier_amplitude": 0.5},
    "filter": {"white": 0.004, "bandwidth_hz": 10.0, "filter_order": 2},
}


@pytest.mark.parametrize("name", sorted(TERMS))
def test_chunked_generation_equals_one_call(name: str) -> None:
    """generate(n1) then generate(n2), ... equals generate(n1 + n2 + ...) bit for bit."""
    model = NoiseModel.single_term("gy", **TERMS[name])
    n_total = 20_000
    whole = SensorPhysics(model, seed=11, duration_hint_s=60.0).generate(n_total, DT)
    phys = SensorPhysics(model, seed=11, duration_hint_s=60.0)
    sizes = [1, 2, 999, 3, 5000, 7, 4096, 1]
    sizes.append(n_total - sum(sizes))
    parts = [phys.generate(k, DT).gyro_dps for k in sizes]
    joined = np.vstack(parts)
    assert np.array_equal(joined, whole.gyro_dps)
    assert np.std(whole.gyro_dps[:, 1]) > 0  # the term is really there
    assert phys.samples_generated == n_total


def test_flicker_seamless_across_internal_blocks() -> None:
    """Many small calls crossing the overlap-save block boundaries join exactly."""
    gen_a = nz.FlickerNoise(1.0, nz.term_rng(5, 0, "flicker"), taps=300)
    gen_b = nz.FlickerNoise(1.0, nz.term_rng(5, 0, "flicker"), taps=300)
    n = 3 * gen_a.block + 17
    t = np.arange(n) * DT
    whole = gen_a.generate(n, DT, t)
    parts = []
    k = 0
    while k < n:
        step = min(37, n - k)
        parts.append(gen_b.generate(step, DT, t[k : k + step]))
        k += step
    assert np.array_equal(np.concatenate(parts), whole)


def test_flicker_matches_direct_kasdin_walter_convolution() -> None:
    """The FFT overlap-save equals the direct FIR sum y_k = B sum_j h_j w_{k-j} (zero past)."""
    taps = 256
    gen = nz.FlickerNoise(0.3, nz.term_rng(9, 2, "flicker"), taps=taps)
    n = gen.block + 500  # crosses one internal block boundary
    y = gen.generate(n, DT, np.arange(n) * DT)
    rng = nz.term_rng(9, 2, "flicker")
    w = np.concatenate([rng.standard_normal(gen.block), rng.standard_normal(gen.block)])[:n]
    h = np.ones(taps)
    for k in range(1, taps):  # Kasdin & Walter (1992) recursion for alpha = 1
        h[k] = h[k - 1] * (k - 0.5) / k
    direct = 0.3 * np.convolve(w, h)[:n]
    # single-precision FFT convolution: error within 1e-5 of the output rms (docstring)
    assert np.max(np.abs(y - direct)) < 1e-5 * np.std(direct)


def test_seed_determinism_and_independence() -> None:
    m = NoiseModel.quiet().with_all(white=0.01, flicker=0.001)
    a = simulate(m, 5000, RATE, seed=3)
    b = simulate(m, 5000, RATE, seed=3)
    c = simulate(m, 5000, RATE, seed=4)
    assert np.array_equal(a["gx"], b["gx"])
    assert not np.array_equal(a["gx"], c["gx"])
    # channels get independent streams
    assert abs(np.corrcoef(a["gx"], a["gy"])[0, 1]) < 0.05
    # switching another term on does not change this term's stream
    m2 = m.with_channel("gx", random_walk=0.0, markov_sigma=0.01, markov_tau=1.0)
    d = simulate(m2, 5000, RATE, seed=3)
    assert np.array_equal(a["gy"], d["gy"])
    # asking for a subset of channels gives the same values
    e = simulate(m, 5000, RATE, seed=3, channels=["ay"])
    assert np.array_equal(a["ay"], e["ay"])


def _psd(y: np.ndarray, nperseg: int = 1 << 14) -> tuple[np.ndarray, np.ndarray]:
    return welch(y, fs=RATE, nperseg=nperseg, detrend=False)


def _slope(f: np.ndarray, p: np.ndarray, lo: float, hi: float) -> float:
    sel = (f >= lo) & (f <= hi)
    return float(np.polyfit(np.log10(f[sel]), np.log10(p[sel]), 1)[0])


def test_white_psd_flat_at_2N2() -> None:
    N = 0.004
    y = simulate(NoiseModel.single_term("gx", white=N), 400_000, RATE, seed=1)["gx"]
    f, p = _psd(y)
    sel = f > 0
    assert abs(_slope(f, p, 0.05, 50.0)) < 0.02
    assert np.median(p[sel]) == pytest.approx(2 * N**2, rel=0.03)


def test_flicker_psd_is_one_over_f_over_the_band() -> None:
    B = 0.001
    n = 1 << 20  # 2.8 h at 104 Hz
    y = simulate(NoiseModel.single_term("gx", flicker=B), n, RATE, seed=2)["gx"]
    f, p = _psd(y, nperseg=1 << 18)  # resolves down to 4e-4 Hz
    # slope -1 over 4e-3 .. 10 Hz (3.4 decades)
    assert _slope(f, p, 4e-3, 10.0) == pytest.approx(-1.0, abs=0.04)
    # level: one-sided S_y = B^2 / (pi f) (h_-1 = B^2/pi), averaged over 0.01 .. 5 Hz
    sel = (f >= 0.01) & (f <= 5.0)
    ratio = np.median(p[sel] * np.pi * f[sel] / B**2)
    assert ratio == pytest.approx(1.0, rel=0.05)


def test_random_walk_psd_slope_minus_two() -> None:
    y = simulate(NoiseModel.single_term("gx", random_walk=0.001), 1 << 19, RATE, seed=3)["gx"]
    f, p = _psd(y, nperseg=1 << 16)
    assert _slope(f, p, 0.01, 1.0) == pytest.approx(-2.0, abs=0.1)


def test_quantization_psd_rises_as_f_squared() -> None:
    Q = 1e-4
    y = simulate(NoiseModel.single_term("gx", quantization=Q), 1 << 18, RATE, seed=4)["gx"]
    f, p = _psd(y, nperseg=1 << 12)
    assert _slope(f, p, 0.1, 5.0) == pytest.approx(2.0, abs=0.1)
    # exact: one-sided S_y(f) = 2 Q^2 tau0 |1 - e^{-i 2 pi f tau0}|^2 / tau0^2
    sel = (f > 1.0) & (f < 50.0)
    model = 2 * Q**2 * DT * 4 * np.sin(np.pi * f[sel] * DT) ** 2 / DT**2
    assert np.median(p[sel] / model) == pytest.approx(1.0, rel=0.03)


def test_markov_psd_is_lorentzian() -> None:
    sigma, tau_c = 0.01, 2.0
    y = simulate(
        NoiseModel.single_term("gx", markov_sigma=sigma, markov_tau=tau_c), 1 << 20, RATE, seed=5
    )["gx"]
    f, p = _psd(y, nperseg=1 << 15)
    sel = (f > 0.005) & (f < 5.0)
    lorentz = 4 * sigma**2 * tau_c / (1 + (2 * np.pi * f[sel] * tau_c) ** 2)
    assert np.median(p[sel] / lorentz) == pytest.approx(1.0, rel=0.05)
    assert np.std(y) == pytest.approx(sigma, rel=0.05)


def test_markov_avar_keeps_its_digits_far_below_tau_c() -> None:
    """IEEE 952 C.6 as written, ``1 - (3 - 4 e^-x + e^-2x) / (2 x)`` with x = tau / tau_c,
    loses every digit for small x (60 % off at 1e-5, negative below): against the same
    formula in 60-digit decimal arithmetic, every x from 1e-9 to 1e3 within 1e-9, and
    positive."""
    from decimal import Decimal, getcontext

    getcontext().prec = 60
    x = np.geomspace(1e-9, 1e3, 241)
    got = nz.avar_markov(x * 100.0, 1.0, 100.0)  # tau_c 100 s
    for xi, g in zip(x, got, strict=True):
        d = Decimal(float(xi))
        bracket = 1 - (3 - 4 * (-d).exp() + (-2 * d).exp()) / (2 * d)
        want = float(Decimal(2) * Decimal(100) / (d * Decimal(100)) * bracket)
        assert g > 0 and abs(g / want - 1.0) < 1e-9, (xi, g, want)


def test_quantization_avar_exact_at_every_m() -> None:
    """3 Q^2 / tau^2 holds from m = 1 (not only asymptotically): allantools OADEV."""
    Q = 2e-4
    n = 400_000
    y = simulate(NoiseModel.single_term("gz", quantization=Q), n, RATE, seed=8)["gz"]
    taus, adev, _, _ = allantools.oadev(y, rate=RATE, data_type="freq", taus=[DT, 2 * DT, 4 * DT])
    expected = np.sqrt(nz.avar_quantization(taus, Q))
    np.testing.assert_allclose(adev, expected, rtol=0.01)


def test_random_walk_avar_exact_at_small_m() -> None:
    """Interval-mean generation: K^2 tau / 3 also at m = 1, 2 (a sampled RW gives 1.5x)."""
    K = 0.01
    adevs = []
    for seed in range(8):
        y = simulate(NoiseModel.single_term("gz", random_walk=K), 100_000, RATE, seed=seed)["gz"]
        _, adev, _, _ = allantools.oadev(y, rate=RATE, data_type="freq", taus=[DT, 2 * DT])
        adevs.append(adev**2)
    avar = np.mean(adevs, axis=0)
    np.testing.assert_allclose(avar, nz.avar_random_walk(np.array([DT, 2 * DT]), K), rtol=0.02)


def test_outliers_rate_and_amplitude() -> None:
    rate_hz, amp = 0.5, 2.0
    n = 2_000_000
    y = simulate(
        NoiseModel.single_term("ax", outlier_rate=rate_hz, outlier_amplitude=amp), n, RATE, seed=6
    )["ax"]
    hits = np.count_nonzero(y)
    expected = rate_hz * n * DT  # Poisson mean 9615
    assert abs(hits - expected) < 4 * math.sqrt(expected)
    assert np.std(y[y != 0]) == pytest.approx(amp, rel=0.05)


def test_sine_amplitude_and_frequency() -> None:
    y = simulate(
        NoiseModel.single_term("gx", sine_amplitude=0.2, sine_freq=3.25), 1 << 16, RATE, seed=1
    )["gx"]
    spec = np.abs(np.fft.rfft(y)) * 2 / len(y)
    f = np.fft.rfftfreq(len(y), DT)
    k = int(np.argmax(spec))
    assert f[k] == pytest.approx(3.25, abs=f[1])
    t = np.arange(len(y)) * DT
    basis = np.column_stack([np.sin(2 * np.pi * 3.25 * t), np.cos(2 * np.pi * 3.25 * t)])
    coef = np.linalg.lstsq(basis, y, rcond=None)[0]
    assert math.hypot(*coef) == pytest.approx(0.2, rel=1e-9)  # peak amplitude


def test_ramp_is_exact() -> None:
    out = simulate(NoiseModel.single_term("gz", ramp=0.01), 1000, RATE, seed=0)
    np.testing.assert_allclose(out["gz"], 0.01 * out["t_s"], rtol=0, atol=1e-15)


def test_avar_formulas_reference_values() -> None:
    """Closed forms against their textbook constants (IEEE 952 Annex C)."""
    assert math.sqrt(nz.avar_flicker(np.array([1.0]), 1.0)[0]) == pytest.approx(0.6643, abs=1e-4)
    assert math.sqrt(nz.avar_random_walk(np.array([3.0]), 0.7)[0]) == pytest.approx(0.7)
    assert math.sqrt(nz.avar_white(np.array([1.0]), 0.004)[0]) == pytest.approx(0.004)
    # Markov: tau >> tau_c -> white with N = q tau_c; tau << tau_c -> random walk K = q
    q = 0.1 * math.sqrt(2 / 5.0)
    big = nz.avar_markov(np.array([1e5]), 0.1, 5.0)[0]
    assert big == pytest.approx((q * 5.0) ** 2 / 1e5, rel=1e-3)
    small = nz.avar_markov(np.array([1e-3]), 0.1, 5.0)[0]
    assert small == pytest.approx(q**2 * 1e-3 / 3, rel=1e-3)
    # sampled sine tends to the continuous formula
    t = np.array([0.5, 1.3])
    np.testing.assert_allclose(
        nz.avar_sine_sampled(t, 1.0, 0.2, 1e-4), nz.avar_sine(t, 1.0, 0.2), rtol=1e-6
    )
