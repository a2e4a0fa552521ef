"""Issue 5, acceptance 1: each noise term alone against its analytic Allan variance.

A recording of one term on gx is simulated at 104 Hz, quantised at the finest gyro LSB
(4.375 mdps, int16 saturation) with :func:`lsm6ds_sim.physics.quantize`, and its
overlapping ADEV is computed by an independent estimator, ``allantools.oadev``
(allantools 2024.6), at octave taus. Each estimate's 90 % confidence interval is the
chi-squared interval of NIST SP 1065 eq. (45) (``allantools.confidence_interval``) with
the EDF of Greenhall (2004) (``allantools.edf_greenhall``, overlapping ADEV), falling back
to the simple SP 1065 Table 5 formulas (``allantools.edf_simple``) where allantools has no
Greenhall case (white PM at the largest taus). For terms that are not a single power law
(Gauss-Markov: random walk below tau_c, white above; deterministic ramp and sinusoid) the
smaller EDF of the candidate noise types is used (a wider, conservative interval); the same
for quantization, whose 1/tau^2 AVAR meets the white-FM output-rounding floor at large tau
(with the white-PM EDF alone, 12 seeds of 3 h gave 42-58 % coverage at the two largest valid
taus while the mean AVAR ratio there was 1.000-1.002).

Expected AVAR = the term's analytic AVAR (IEEE Std 952 Annex C) + the output quantisation
floor (LSB^2/12) tau0/tau (Widrow: rounding a busy signal adds white noise of variance
LSB^2/12). Valid range of taus: tau <= T/10; tau where the term's AVAR is at least 10x
that floor (for the ramp, whose LSB staircase is not white, R^2 tau^2/2 >= 100 LSB^2/12);
flicker m >= 16 (the discrete Kasdin-Walter spectrum B^2 tau0/(2 sin(pi f tau0)) departs
from 1/f near Nyquist: +20 % ADEV at m = 1, < 0.5 % from m = 16); Gauss-Markov m >= 16 (the
sampled AR(1) exceeds the continuous-time AVAR by about 1/(2 m^2) at small m).
Pass: the expected value is inside the 90 % interval at >= 80 % of the valid taus,
pooled over five independent recordings (seeds 1-5), and at >= 60 % for each one. Why
pooled: the ADEV estimates of one recording are strongly correlated across taus (a random
walk realisation that is a little quiet is quiet at every tau), so the single-recording
criterion is itself a random event: measured over 40 seeds of 30 min it holds for a correct
generator in 78 % (random walk) to 100 % (ramp, sine) of recordings, while the mean AVAR
ratio is 1.00 +- 0.01 at every valid tau (docs/benchmarks.md, "Noise generators").

The default runs use 30 min records; the ``slow`` ones the issue's 3 h.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import allantools
import numpy as np
import pytest
import scipy.stats
from lsm6ds_sim import noise as nz
from lsm6ds_sim.model import NoiseModel
from lsm6ds_sim.physics import quantize, simulate

RATE_HZ = 104.0
TAU0_S = 1.0 / RATE_HZ
LSB_DPS = 4.375e-3  # finest gyro LSB (FS 125 dps), reference section 4.2
SEEDS = (1, 2, 3, 4, 5)


@dataclass(frozen=True)
class Case:
    terms: dict[str, float]
    avar: Callable[[np.ndarray], np.ndarray]
    alphas: tuple[int, ...]  # frequency-PSD exponents bracketing the term (SP 1065 Table 1)
    min_m: int = 1


# Magnitudes are chosen so each term moves the output by several LSB per sample (so that
# rounding acts as white noise) and stays inside the 125 dps full scale over 3 h.
CASES: dict[str, Case] = {
    "white": Case({"white": 0.004}, lambda t: nz.avar_white(t, 0.004), (0,)),
    "flicker": Case({"flicker": 0.02}, lambda t: nz.avar_flicker(t, 0.02), (-1,), min_m=16),
    "random_walk": Case({"random_walk": 0.05}, lambda t: nz.avar_random_walk(t, 0.05), (-2,)),
    "ramp": Case({"ramp": 0.005}, lambda t: nz.avar_ramp(t, 0.005), (0, -2)),
    "quantization": Case({"quantization": 0.01}, lambda t: nz.avar_quantization(t, 0.01), (2, 0)),
    "markov": Case(
        {"markov_sigma": 0.5, "markov_tau": 10.0},
        lambda t: nz.avar_markov(t, 0.5, 10.0),
        (0, -2),
        min_m=16,
    ),
    "sine": Case(
        {"sine_amplitude": 1.0, "sine_freq": 0.37},
        lambda t: nz.avar_sine_sampled(t, 1.0, 0.37, TAU0_S),
        (0, -2),
    ),
}


def _edf(alpha: int, m: int, n_phase: int) -> float:
    try:
        return float(allantools.edf_greenhall(alpha, 2, m, n_phase, overlapping=True))
    except NotImplementedError:
        return float(allantools.edf_simple(n_phase, m, alpha))


@dataclass
class Outcome:
    taus: np.ndarray
    adev: np.ndarray
    expected: np.ndarray
    inside: np.ndarray
    valid: np.ndarray

    @property
    def fraction(self) -> float:
        return float(np.mean(self.inside[self.valid]))

    def table(self) -> str:
        rows = [
            f"tau={t:9.3f}s ratio={a / e:6.3f} {'ok ' if i else 'OUT'}{'' if v else ' (not valid)'}"
            for t, a, e, i, v in zip(
                self.taus, self.adev, self.expected, self.inside, self.valid, strict=True
            )
        ]
        return "\n".join(rows)


def run_case(name: str, hours: float, seed: int) -> Outcome:
    case = CASES[name]
    n = round(hours * 3600 * RATE_HZ)
    model = NoiseModel.single_term("gx", **case.terms)
    y = quantize(simulate(model, n, RATE_HZ, seed=seed, channels=["gx"])["gx"], LSB_DPS, 125.0)
    taus, adev, _, _ = allantools.oadev(y, rate=RATE_HZ, data_type="freq", taus="octave")
    ms = np.round(taus * RATE_HZ).astype(int)
    floor = LSB_DPS**2 / 12.0 * TAU0_S / taus
    term = case.avar(taus)
    expected = np.sqrt(term + floor)
    inside = np.zeros(len(taus), dtype=bool)
    for i, (m, dev, exp) in enumerate(zip(ms, adev, expected, strict=True)):
        edf = min(_edf(a, int(m), n + 1) for a in case.alphas)
        lo, hi = allantools.confidence_interval(dev, edf, ci=0.90)
        inside[i] = lo <= exp <= hi
    valid = (taus <= n * TAU0_S / 10.0) & (ms >= case.min_m)
    if name == "ramp":
        valid &= term >= 100.0 * LSB_DPS**2 / 12.0
    else:
        valid &= term >= 10.0 * floor
    return Outcome(taus, adev, expected, inside, valid)


def _check(name: str, hours: float) -> Outcome:
    outs = [run_case(name, hours, seed) for seed in SEEDS]
    for seed, out in zip(SEEDS, outs, strict=True):
        assert out.valid.sum() >= 6, f"{name}: too few valid taus\n{out.table()}"
        assert out.fraction >= 0.60, (
            f"{name} seed {seed}: {out.fraction:.0%} of taus inside\n{out.table()}"
        )
    pooled = np.mean(np.concatenate([o.inside[o.valid] for o in outs]))
    assert pooled >= 0.80, f"{name}: {pooled:.0%} of (recording, tau) pairs inside"
    # the criterion itself (>= 80 % of valid taus inside the 90 % interval) must
    # hold in at least 4 of the 5 recordings (one correct recording in 5 may miss it by
    # chance: the measured single-recording pass rate is 78-100 % depending on the term)
    passing = [seed for seed, o in zip(SEEDS, outs, strict=True) if o.fraction >= 0.80]
    assert len(passing) >= 4, (
        f"{name}: the 80 % criterion holds only for seeds {passing}: "
        + ", ".join(f"{o.fraction:.0%}" for o in outs)
    )
    return outs[0]


@pytest.mark.parametrize("name", sorted(CASES))
def test_term_oadev_matches_analytic_30min(name: str) -> None:
    _check(name, 0.5)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CASES))
def test_term_oadev_matches_analytic_3h(name: str) -> None:
    _check(name, 3.0)


def _flicker_flat(hours: float) -> None:
    out = _check("flicker", hours)
    taus = out.taus[out.valid]
    decades = math.log10(taus.max() / taus.min())
    assert decades >= 3.0, f"flicker valid band only {decades:.2f} decades"
    level = 0.664 * 0.02  # ADEV of flicker = sqrt(2 ln2 / pi) B = 0.664 B
    assert math.isclose(math.sqrt(2 * math.log(2) / math.pi), 0.664, abs_tol=5e-4)
    ratio = out.adev[out.valid] / level
    # flat: a 1/f spectrum gives a slope-0 ADEV; a power law with another slope is far off
    slope = np.polyfit(np.log10(taus), np.log10(out.adev[out.valid]), 1)[0]
    assert abs(slope) < 0.03, f"flicker ADEV slope {slope:.3f} over {decades:.1f} decades"
    assert abs(np.median(ratio) - 1.0) < 0.03, f"median ADEV / 0.664 B = {np.median(ratio):.3f}"


def test_flicker_adev_flat_over_three_decades_30min() -> None:
    _flicker_flat(0.5)


@pytest.mark.slow
def test_flicker_adev_flat_over_three_decades_3h() -> None:
    _flicker_flat(3.0)


def test_white_sigma_at_1s_is_N() -> None:
    n = int(0.5 * 3600 * RATE_HZ)
    y = simulate(NoiseModel.single_term("gx", white=0.004), n, RATE_HZ, seed=3)["gx"]
    _, adev, _, _ = allantools.oadev(
        quantize(y, LSB_DPS), rate=RATE_HZ, data_type="freq", taus=[1.0]
    )
    edf = _edf(0, int(RATE_HZ), n + 1)
    lo, hi = allantools.confidence_interval(adev[0], edf, ci=0.90)
    assert lo <= math.hypot(0.004, LSB_DPS * math.sqrt(TAU0_S / 12)) <= hi


def test_random_walk_sigma_at_3s_is_K() -> None:
    n = int(0.5 * 3600 * RATE_HZ)
    y = simulate(NoiseModel.single_term("gx", random_walk=0.05), n, RATE_HZ, seed=3)["gx"]
    m = 312  # tau = 3.0 s at 104 Hz
    _, adev, _, _ = allantools.oadev(
        quantize(y, LSB_DPS), rate=RATE_HZ, data_type="freq", taus=[m / RATE_HZ]
    )
    lo, hi = allantools.confidence_interval(adev[0], _edf(-2, m, n + 1), ci=0.90)
    assert lo <= 0.05 <= hi  # sigma(3 s) = K since K^2 * 3 / 3 = K^2


def test_markov_peak_formula_and_textbook_value() -> None:
    # tau_c = 1 s, sigma chosen so that q_c = 0.1 * sqrt(2): the textbook example's numbers
    tau_c = 1.0
    q_c = 0.1 * math.sqrt(2.0)
    sigma = q_c / math.sqrt(2.0 / tau_c)
    tau_peak, adev_peak = nz.markov_adev_peak(sigma, tau_c)
    assert tau_peak == pytest.approx(1.89 * tau_c, rel=2e-3)
    assert adev_peak == pytest.approx(0.437 * q_c * math.sqrt(tau_c), rel=2e-3)
    assert adev_peak == pytest.approx(0.0618, abs=1e-4)  # not the printed 0.0062


def _markov_peak(hours: float) -> None:
    """The Gauss-Markov ADEV peak measured by allantools.oadev (independent estimator) on
    41 log-spaced taus from 0.5 to 5 tau_c plus tau = 1.89 tau_c. Expected: the IEEE 952
    C.6 maximum, height 0.437 q_c sqrt(tau_c) at 1.89 tau_c. Checked: the ADEV at
    1.89 tau_c is inside its 90 % interval (smaller EDF of white and random-walk FM, as
    for the acceptance table) in at least 3 of 5 recordings (a correct generator misses
    that with probability ~1.5 %: over 40 seeds of 30 min the AVAR ratio there was
    1.002 +- 0.160, an EDF of 78 against Greenhall's 87); the mean AVAR ratio over the
    five recordings is 1 within its Student-t 90 % interval; the pooled peak, located
    by a quadratic fit of log ADEV vs log tau around the maximum, is within 10 % of
    1.89 tau_c. (The maximum of one recording's curve is biased up and wanders by +-40 %
    on the flat top in 30 min, so it is not used per recording.)"""
    sigma, tau_c = 0.5, 10.0
    n = round(hours * 3600 * RATE_HZ)
    model = NoiseModel.single_term("gx", markov_sigma=sigma, markov_tau=tau_c)
    m_peak = round(1.89 * tau_c * RATE_HZ)
    grid = np.round(np.geomspace(0.5 * tau_c, 5 * tau_c, 41) * RATE_HZ).astype(int)
    ms = np.unique(np.append(grid, m_peak))
    k = int(np.searchsorted(ms, m_peak))
    q_c = sigma * math.sqrt(2.0 / tau_c)
    height = 0.437 * q_c * math.sqrt(tau_c)
    edf = min(_edf(a, m_peak, n + 1) for a in (0, -2))
    avars, inside = [], []
    for seed in SEEDS:
        y = quantize(simulate(model, n, RATE_HZ, seed=seed)["gx"], LSB_DPS)
        taus, adev, _, _ = allantools.oadev(y, rate=RATE_HZ, data_type="freq", taus=ms / RATE_HZ)
        avars.append(adev**2)
        lo, hi = allantools.confidence_interval(adev[k], edf, ci=0.90)
        inside.append(lo <= height <= hi)
    assert sum(inside) >= 3, f"ADEV(1.89 tau_c) inside its 90 % interval for {inside}"
    # pooled: mean AVAR ratio at the peak over the independent recordings, inside its
    # Student-t 90 % interval (uses the recordings' own spread, not an EDF model)
    ratio = np.array(avars)[:, k] / height**2
    half = scipy.stats.t.ppf(0.95, len(SEEDS) - 1) * ratio.std(ddof=1) / math.sqrt(len(SEEDS))
    assert abs(ratio.mean() - 1.0) <= half, f"AVAR(1.89 tau_c) / expected: {ratio}"
    pooled = np.sqrt(np.mean(avars, axis=0))
    i = int(np.argmax(pooled))
    near = slice(max(i - 8, 0), i + 9)
    c2, c1, _ = np.polyfit(np.log(taus[near]), np.log(pooled[near]), 2)
    assert math.exp(-c1 / (2 * c2)) == pytest.approx(1.89 * tau_c, rel=0.10)


def test_markov_adev_peak_30min() -> None:
    _markov_peak(0.5)


@pytest.mark.slow
def test_markov_adev_peak_3h() -> None:
    _markov_peak(3.0)
