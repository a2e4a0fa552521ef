"""Rate table: gyro sensitivity (scale-factor error) and cross-axis coupling."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pytest
from scipy.stats import norm

from imubench.jig import analysis
from imubench.jig.calibrate import gyro_fit

if TYPE_CHECKING:
    from imubench.calibration.sensor import SensorFit
    from imubench.jig.plugin import Measure
    from imubench.jig.session import JigSession


AXES = ("x", "y", "z")


@pytest.fixture(scope="module")
def fit(jig: JigSession) -> SensorFit:
    f = jig.cached("gyro_fit", lambda: gyro_fit(jig.procedures,
                                                jig.station.calibration.nonlinearity))
    jig.artifacts["rate_table"] = {"inputs_dps": f.inputs, "residuals_dps": f.residuals,
                                   "stderr_dps": f.stderr}
    return f


@pytest.mark.parametrize("axis", AXES)
def test_sensitivity(fit: SensorFit, jig: JigSession, measure: Measure, axis: str) -> None:
    i = AXES.index(axis)
    v = analysis.interval_from_stderr(
        100.0 * fit.scale_error[i], 100.0 * fit.stderr_of("scale_error")[i], jig.confidence,
        "rate-table least squares: M_ii - 1")
    measure(f"gyro_sensitivity.g{axis}", v.value, v.ci, method=v.method)


@pytest.mark.parametrize("axis", AXES)
def test_cross_axis(fit: SensorFit, jig: JigSession, measure: Measure, axis: str) -> None:
    i = AXES.index(axis)
    others = [j for j in range(3) if j != i]
    c = fit.cross_axis[i, others]
    se = np.array([fit.fits[i].stderr[j] for j in others]) / fit.matrix[i, i]
    k = int(np.argmax(np.abs(c)))
    z = float(norm.ppf(0.5 + jig.confidence / 2.0))
    value, s = 100.0 * abs(float(c[k])), 100.0 * float(se[k])
    measure(f"gyro_cross_axis.g{axis}", value, (max(0.0, value - z * s), value + z * s),
            method=f"largest |M_ij / M_ii| (input {AXES[others[k]]}), rate-table least squares")
