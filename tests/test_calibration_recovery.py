"""Calibration recovers injected sensor errors on the simulated jig (issue acceptance 2).

Each seed builds a simulated LSM6DSL whose noise model carries random offsets,
``scale_error``, ``cross_*``, ``nonlinearity``, ``temp_coeff`` and ``temp_coeff2`` on every
channel, white noise at the datasheet-typical densities, and runs the jig's captures
(six positions, rate table, chamber sweep) through the real driver in virtual time.

Tolerance (derived, not fitted): a capture of ``T`` seconds of white noise of density
``N`` has a mean with standard error ``N / sqrt(T)`` (AVAR = N^2/tau). Every fit is a
linear least-squares problem whose design is known (the positions, rates and die
temperatures), so each parameter's standard error is ``sigma_p = sqrt(diag(sigma_m^2
(X^T X)^-1))`` (temperature offsets are means of two flipped captures:
``sigma_m / sqrt 2``). The tolerance is ``3 sigma_p`` (99.7 % for a Gaussian estimate);
a parameter passes when at least 95 % of the seeds recover it within it. The standard
errors come from this analytic design, never from the fit's own residuals.

After calibration the six-position residuals are at the noise level: a second set of six
captures, corrected by the calibration file, misses the true specific force by a
chi-squared statistic ``sum e^2 / (sigma_m^2 (1 + h_kk))`` (``h`` the design's leverage:
the calibration's own error at that position) whose mean over the seeds is that of
chi-squared with 18 degrees of freedom.

Measured (24 seeds, 2026-11-23): every parameter within tolerance on 97-100 % of the
seeds x axes; mean squared error in sigma units 0.88-1.41 (1 expected).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from lsm6ds_sim.model import NoiseModel
from scipy.stats import chi2

from imubench.calibration.accel import SIX_POSITIONS
from imubench.jig.calibrate import build_calibration, fit_board, provenance
from imubench.jig.dut import Dut
from imubench.jig.fixtures.sim import SimFixture
from imubench.jig.procedures import Procedures, point
from imubench.jig.station import CalibrationSection, CaptureSection

N_GYRO = 0.004  # dps/sqrt(Hz)
N_ACCEL = 80e-6  # g/sqrt(Hz)
ODR = 104.0
K_TOL = 3.0
CFG = CaptureSection.model_validate({
    "settle_s": 1.0, "static_s": 4.0, "position_s": 2.0, "rates_dps": [100.0, 200.0],
    "rate_s": 2.0, "temperatures_c": [25.0, 55.0, 85.0, -10.0, -40.0],
    "temp_capture_s": 3.0, "temp_window_s": 10.0, "temp_stable_c": 0.05})
CAL = CalibrationSection.model_validate({})
CHAMBER_TAU_S = 10.0
FACES = list(SIX_POSITIONS)


def injected(seed: int) -> dict[str, dict[str, float]]:
    """Random errors of every channel (model keys and units of docs/noise-model.md)."""
    rng = np.random.default_rng(1000 + seed)
    out: dict[str, dict[str, float]] = {}
    for ch in ("gx", "gy", "gz", "ax", "ay", "az"):
        gyro = ch.startswith("g")
        own = ch[1]
        p = {
            "white": N_GYRO if gyro else N_ACCEL,
            "bias": rng.uniform(-1.0, 1.0) if gyro else rng.uniform(-0.05, 0.05),
            "scale_error": rng.uniform(-0.02, 0.02),
            "nonlinearity": rng.uniform(-3e-5, 3e-5) if gyro else rng.uniform(-0.005, 0.005),
            "temp_coeff": rng.uniform(-0.02, 0.02) if gyro else rng.uniform(-2e-4, 2e-4),
            "temp_coeff2": rng.uniform(-1e-4, 1e-4) if gyro else rng.uniform(-3e-6, 3e-6),
        }
        for other in "xyz":
            if other != own:
                p[f"cross_{other}"] = rng.uniform(-0.01, 0.01)
        out[ch] = p
    return out


def run_board(seed: int, tmp: Path) -> dict[str, object]:
    params = injected(seed)
    model = NoiseModel.quiet()
    for ch, p in params.items():
        model = model.with_channel(ch, **p)
    path = tmp / f"model-{seed}.toml"
    path.write_text(model.to_toml())
    dut = Dut(f"sim://lsm6dsl?odr_hz={ODR:g}&seed={seed}&clock=virtual&model={path}")
    try:
        fixture = SimFixture(dut.sim, CHAMBER_TAU_S)  # type: ignore[arg-type]
        proc = Procedures(dut, fixture, CFG)
        fits = fit_board(proc, CAL)
        cal = build_calibration(fits, CAL,
                                provenance(f"SEED-{seed}", "test", "lsm6dsl", dut.uri, "r"))
        # a second six-position set, corrected by the calibration, once the die is back
        # at ambient (the sweep ends by setting the chamber to ambient)
        dut.wait_temperature_stable(CFG.temp_stable_c, CFG.temp_window_s, CFG.temp_timeout_s)
        again = []
        for face in FACES:
            fixture.face(face)
            dut.settle(CFG.settle_s)
            cap = dut.capture(CFG.position_s, f"check {face}")
            again.append(point(f"check {face}", cap, np.array(SIX_POSITIONS[face]),
                               np.zeros(3)))
        means = np.array([p.mean(slice(3, 6)) for p in again])
        temps = np.array([p.die_temp_c for p in again])
        assert cal.accel is not None
        corrected = cal.accel.correct(means, temps)
        truth = np.array([SIX_POSITIONS[f] for f in FACES])
        die_temps = np.array([p.die_temp_c for p in proc.temperature_sweep()])
    finally:
        dut.close()
    return {"params": params, "fits": fits, "corrected": corrected, "truth": truth,
            "die_temps": die_temps, "temp_ref": fits.temp_ref_c}


def _cov(X: np.ndarray, sigma: float) -> np.ndarray:
    return sigma**2 * np.linalg.inv(X.T @ X)


def tolerances(die_temps: np.ndarray, temp_ref: float) -> dict[str, dict[str, float]]:
    """3 sigma of each estimated parameter from the design and N / sqrt(T) (module
    docstring); keys ``accel``/``gyro`` -> parameter -> tolerance (model units)."""
    out: dict[str, dict[str, float]] = {}
    # six positions, one axis: columns u_x u_y u_z 1 u_i^2 (axis x; the others permute)
    u = np.array([SIX_POSITIONS[f] for f in FACES])
    sm_a = N_ACCEL / math.sqrt(round(CFG.position_s * ODR) / ODR)
    Xa = np.hstack([u, np.ones((6, 1)), u[:, :1] ** 2])
    Ca = _cov(Xa, sm_a)
    # rate table, one axis: each axis-up mount at 0, +-r1, +-r2 (inputs on one axis)
    rates = [0.0, 100.0, -100.0, 200.0, -200.0]
    ur = np.zeros((15, 3))
    for a in range(3):
        ur[5 * a : 5 * a + 5, a] = rates
    sm_g = N_GYRO / math.sqrt(round(CFG.rate_s * ODR) / ODR)
    Xg = np.hstack([ur, np.ones((15, 1)), ur[:, :1] ** 2])
    Cg = _cov(Xg, sm_g)
    # temperature: offsets are means of two flipped captures
    d = die_temps - temp_ref
    Xt = np.stack([np.ones_like(d), d, d**2], axis=1)
    st_a = N_ACCEL / math.sqrt(round(CFG.temp_capture_s * ODR) / ODR) / math.sqrt(2)
    st_g = N_GYRO / math.sqrt(round(CFG.temp_capture_s * ODR) / ODR) / math.sqrt(2)
    for name, C, Ct in (("accel", Ca, _cov(Xt, st_a)), ("gyro", Cg, _cov(Xt, st_g))):
        out[name] = {
            "scale_error": K_TOL * math.sqrt(C[0, 0]),
            "cross": K_TOL * math.sqrt(C[1, 1]),
            "bias": K_TOL * math.sqrt(C[3, 3]),
            "nonlinearity": K_TOL * math.sqrt(C[4, 4]),
            "temp_coeff": K_TOL * math.sqrt(Ct[1, 1]),
            "temp_coeff2": K_TOL * math.sqrt(Ct[2, 2]),
        }
    return out


def errors(run: dict[str, object]) -> dict[str, list[float]]:
    """|estimate - injected| / tolerance for every parameter and channel."""
    params = run["params"]
    fits = run["fits"]
    tol = tolerances(run["die_temps"], run["temp_ref"])  # type: ignore[arg-type]
    out: dict[str, list[float]] = {}
    for sensor, fit, chans in (("accel", fits.accel, ("ax", "ay", "az")),  # type: ignore[attr-defined]
                               ("gyro", fits.gyro, ("gx", "gy", "gz"))):  # type: ignore[attr-defined]
        tf = fits.sweep[sensor].fits["polynomial"]  # type: ignore[attr-defined]
        t = tol[sensor]
        for i, ch in enumerate(chans):
            p = params[ch]  # type: ignore[index]
            s = 1.0 + p["scale_error"]
            est = {
                "bias": (fit.offset[i], p["bias"]),
                "scale_error": (fit.scale_error[i], p["scale_error"]),
                "nonlinearity": (fit.nonlinearity[i] / fit.matrix[i, i], p["nonlinearity"]),
                "temp_coeff": (tf.coeff1[i], p["temp_coeff"]),
                "temp_coeff2": (tf.coeff2[i], p["temp_coeff2"]),
            }
            for j, other in enumerate("xyz"):
                if j != i:
                    est[f"cross_{other}"] = (fit.cross_axis[i, j], p[f"cross_{other}"])
            for key, (e, true) in est.items():
                base = "cross" if key.startswith("cross") else key
                scale = s if base == "nonlinearity" else 1.0
                out.setdefault(f"{sensor}.{key}", []).append(
                    abs(e - true) / (t[base] / (scale if base != "nonlinearity" else 1.0)))
    return out


def residual_chi2(run: dict[str, object]) -> float:
    e = np.asarray(run["corrected"]) - np.asarray(run["truth"])
    u = np.asarray(run["truth"])
    sm = N_ACCEL / math.sqrt(round(CFG.position_s * ODR) / ODR)
    X = np.hstack([u, np.ones((6, 1))])
    total = 0.0
    for i in range(3):
        Xi = np.hstack([X, u[:, i : i + 1] ** 2])
        h = np.diag(Xi @ np.linalg.inv(Xi.T @ Xi) @ Xi.T)
        total += float(np.sum(e[:, i] ** 2 / (sm**2 * (1.0 + h))))
    return total


def _check(seeds: list[int], tmp: Path, *, per_parameter: bool) -> None:
    """Within tolerance on >= 95 % of seeds x axes: of each parameter (``per_parameter``,
    needs >= 20 seeds for one miss to be allowed), else of all parameters pooled."""
    runs = [run_board(s, tmp) for s in seeds]
    table: dict[str, list[float]] = {}
    for r in runs:
        for k, v in errors(r).items():
            table.setdefault(k, []).extend(v)
    if per_parameter:
        bad = {k: float(np.mean(np.asarray(v) <= 1.0)) for k, v in table.items()
               if np.mean(np.asarray(v) <= 1.0) < 0.95}
        assert not bad, f"recovered within 3 sigma on fewer than 95 % of seeds x axes: {bad}"
    else:
        pooled = np.concatenate([np.asarray(v) for v in table.values()])
        assert np.mean(pooled <= 1.0) >= 0.95, {k: max(v) for k, v in table.items()}
    # the errors are of the size the derivation says (not just under a loose bound): the
    # sum of squared errors in units of sigma (= tolerance / 3) over n estimates is
    # chi-squared with n degrees of freedom (two-sided 0.1 % bounds)
    for k, v in table.items():
        z2 = float(np.sum((3.0 * np.asarray(v)) ** 2))
        n = len(v)
        assert chi2.ppf(0.0005, n) < z2 < chi2.ppf(0.9995, n), (k, z2 / n, n)
    chis = np.array([residual_chi2(r) for r in runs])
    # mean of chi2(18) over the seeds: 18 with sd sqrt(36 / n)
    assert abs(chis.mean() - 18.0) < 4.0 * math.sqrt(36.0 / len(chis)) + 2.0, chis
    assert np.all(chis < chi2.ppf(0.9999, 18)), chis


def test_recovery_few_seeds(tmp_path: Path) -> None:
    _check([1, 2, 3, 4], tmp_path, per_parameter=False)


@pytest.mark.slow
def test_recovery_24_seeds(tmp_path: Path) -> None:
    _check(list(range(1, 25)), tmp_path, per_parameter=True)


def test_bias_wander_is_the_allan_variance_beyond_white() -> None:
    """The variance a bias random walk adds to captures 5 s apart is its Allan variance
    K^2 tau / 3 (IEEE 952 C.4); white noise adds none (it is in the means' own errors)."""
    from imubench.jig.calibrate import ACCEL, bias_wander
    from imubench.jig.dut import Capture
    from imubench.jig.procedures import point

    rate, n = 104.0, 104 * 600
    rng = np.random.default_rng(11)
    white = 1e-4 * rng.standard_normal((n, 6))
    k = 2e-5  # g/sqrt(s)
    walk = np.cumsum(k / np.sqrt(rate) * rng.standard_normal((n, 6)), axis=0)

    def static(values: np.ndarray) -> object:
        cap = Capture("static", rate, 0, values, np.full(n, 25.0), 0.0, (), np.zeros(6),
                      np.zeros(6, dtype=np.int64))
        return point("static", cap, np.zeros(3), np.zeros(3))

    quiet = bias_wander(static(white), ACCEL, 5.0)  # type: ignore[arg-type]
    assert np.all(quiet < 0.5 * 1e-8 / (5.0 * rate))  # half white's AVAR at 5 s at most
    wander = bias_wander(static(white + walk), ACCEL, 5.0)  # type: ignore[arg-type]
    np.testing.assert_allclose(wander, k**2 * 5.0 / 3.0, rtol=0.6)
