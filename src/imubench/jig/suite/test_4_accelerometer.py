"""Six positions: zero-g offset, accelerometer calibration (12 parameters and with the
quadratic term), gains and residuals."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pytest
from scipy.stats import chi2, norm

from imubench.jig import analysis
from imubench.jig.calibrate import ACCEL, accel_fits

if TYPE_CHECKING:
    from imubench.calibration.sensor import SensorFit
    from imubench.jig.plugin import Measure
    from imubench.jig.procedures import Point
    from imubench.jig.session import JigSession


AXES = ("x", "y", "z")


@pytest.fixture(scope="module")
def six(jig: JigSession) -> list[Point]:
    return jig.procedures.six_position()


@pytest.fixture(scope="module")
def fits(six: list[Point], jig: JigSession) -> tuple[SensorFit, SensorFit]:
    linear, quad = jig.cached("accel_fits", lambda: accel_fits(jig.procedures))
    jig.artifacts["six_position"] = {
        "faces": [p.label.split()[1] for p in six],
        "residuals_12_mg": 1e3 * linear.residuals,
        "residuals_15_mg": 1e3 * quad.residuals,
        "stderr_mg": 1e3 * linear.stderr,
    }
    return linear, quad


@pytest.mark.parametrize("axis", AXES)
def test_zero_g_offset(six: list[Point], jig: JigSession, measure: Measure, axis: str) -> None:
    i = AXES.index(axis)
    level = [p for p in six if p.specific_force_g[i] == 0.0]
    means = np.array([p.mean(ACCEL)[i] for p in level])
    se = np.array([p.stderr(ACCEL)[i] for p in level])
    value = 1e3 * float(means.mean())
    stderr = 1e3 * float(np.sqrt(np.sum(se**2)) / len(se))
    v = analysis.interval_from_stderr(
        value, stderr, jig.confidence,
        f"mean of the {len(level)} positions with {axis.upper()} level; SE from each"
        " capture's OADEV")
    measure(f"zero_g_offset.a{axis}", v.value, v.ci, method=v.method)


@pytest.mark.parametrize("axis", AXES)
def test_gain_error(
    fits: tuple[SensorFit, SensorFit], jig: JigSession, measure: Measure, axis: str,
) -> None:
    _, quad = fits
    i = AXES.index(axis)
    v = analysis.interval_from_stderr(
        100.0 * quad.scale_error[i], 100.0 * quad.stderr_of("scale_error")[i], jig.confidence,
        "six-position least squares (offset, gain, cross-axis, quadratic): M_ii - 1")
    measure(f"accel_calibration.gain_error.a{axis}", v.value, v.ci, method=v.method)


def test_six_position_residuals(
    fits: tuple[SensorFit, SensorFit], jig: JigSession, measure: Measure,
) -> None:
    linear, _ = fits
    r = np.abs(linear.residuals)
    k = np.unravel_index(int(np.argmax(r)), r.shape)
    z = float(norm.ppf(0.5 + jig.confidence / 2.0))
    value, se = 1e3 * float(r[k]), 1e3 * float(linear.stderr[k])
    measure("accel_calibration.residual_max", value, (max(0.0, value - z * se), value + z * se),
            method="largest |residual| of the 12-parameter six-position fit, +-z SE of"
            " that capture mean")


def test_calibrated_residuals_at_noise_level(
    fits: tuple[SensorFit, SensorFit], measure: Measure,
) -> None:
    _, quad = fits
    total, dof = quad.chi2()
    value = total / dof
    high = float(chi2.ppf(0.999, dof) / dof)
    measure("accel_calibration.chi2_per_dof", value, (value, value), high=high, unit="1",
            method=f"weighted residual sum of the 15-parameter fit over {dof} degrees of"
            " freedom; limit: chi-squared 99.9 % quantile (residuals at the noise level)")
