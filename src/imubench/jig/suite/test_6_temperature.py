"""Temperature sweep: offset temperature coefficients and the three-point temperature
calibration with its residuals over the sweep (the note's procedure, the exact
quadratic through the same points, the least-squares polynomial)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import pytest
from scipy.stats import norm

from imubench.batch import CHANNELS
from imubench.jig import analysis
from imubench.jig.calibrate import SENSOR_COLS, temperature_fits

if TYPE_CHECKING:
    from imubench.jig.calibrate import SweepData
    from imubench.jig.plugin import Measure
    from imubench.jig.procedures import TemperaturePoint
    from imubench.jig.session import JigSession


SCALE = {"gyro": (1.0, "dps"), "accel": (1e3, "mg")}


@pytest.fixture(scope="module")
def sweep(jig: JigSession) -> list[TemperaturePoint]:
    return jig.procedures.temperature_sweep()


@pytest.fixture(scope="module")
def tfits(sweep: list[TemperaturePoint], jig: JigSession) -> dict[str, SweepData]:
    ref = jig.procedures.static().die_temp_c
    out = jig.cached("temperature_fits", lambda: {
        name: temperature_fits(jig.procedures, cols)
        for name, cols in SENSOR_COLS.items()})
    art = {"set_points_c": [p.set_point_c for p in sweep],
           "chamber_c": [p.chamber_c for p in sweep],
           "die_c": [p.die_temp_c for p in sweep],
           "settle_s": [p.settle_s for p in sweep], "temp_ref_c": ref}
    for name, data in out.items():
        art[name] = {"offsets": data.offsets, "stderr": data.stderr,
                     "fits": {m: {"temp_ref_c": f.temp_ref_c, "offset": f.offset,
                                  "coeff1": f.coeff1, "coeff2": f.coeff2,
                                  "residuals": f.residuals(data.temps_c, data.offsets)}
                              for m, f in data.fits.items()}}
    jig.artifacts["temperature"] = art
    return out


@pytest.mark.parametrize("ch", CHANNELS)
def test_offset_temperature_coefficient(
    tfits: dict[str, SweepData], jig: JigSession, measure: Measure, ch: str,
) -> None:
    sensor = "gyro" if ch.startswith("g") else "accel"
    i = CHANNELS.index(ch) % 3
    f = tfits[sensor].fits["polynomial"]
    k, _ = SCALE[sensor]
    assert f.stderr1 is not None and f.stderr_dof is not None
    dof = float(f.stderr_dof[i])
    v = analysis.interval_from_stderr(
        k * f.coeff1[i], k * f.stderr1[i], jig.confidence,
        f"linear term of the least-squares quadratic over {len(tfits[sensor].temps_c)}"
        f" chamber points about {f.temp_ref_c:.2f} degC"
        + ("" if f.drift_per_h is None else ", beside a drift linear in time")
        + ("" if math.isinf(dof) else
           f"; error from the residual scatter, Student t with {dof:.0f} dof"), dof)
    measure(f"temperature_coefficient.{ch}", v.value, v.ci, method=v.method)


@pytest.mark.parametrize("sensor", ["gyro", "accel"])
def test_temperature_calibration_residuals(
    tfits: dict[str, SweepData], jig: JigSession, measure: Measure, sensor: str,
) -> None:
    method = jig.station.calibration.temperature_method
    data = tfits[sensor]
    r = np.abs(data.fits[method].residuals(data.temps_c, data.offsets))
    k = np.unravel_index(int(np.argmax(r)), r.shape)
    scale, _ = SCALE[sensor]
    z = float(norm.ppf(0.5 + jig.confidence / 2.0))
    value, se = scale * float(r[k]), scale * float(data.stderr[k])
    measure(f"temperature_calibration.residual_max.{sensor}", value,
            (max(0.0, value - z * se), value + z * se),
            method=f"largest |offset - {method} fit| over the sweep ({data.temps_c[k[0]]:.1f}"
            " degC), +-z SE of that point")
