"""Gyroscope calibration: bias at rest; scale factor, cross-axis (and nonlinearity) on a
rate table.

* Bias at rest: the mean rate of a static capture is the zero-rate level (the Earth's
  rotation, 0.004 dps at most, is below what a MEMS gyro resolves in a jig capture and
  is ignored).
* Rate table: the board turns at known rates about each of its axes (``+-r`` about X
  with X vertical, and so on); the capture means fit ``y = M u + q u^2 + b``
  (:mod:`imubench.calibration.sensor`): ``M_ii - 1`` is the scale-factor error,
  ``M_ij / M_ii`` the cross-axis coupling, ``q`` the quadratic nonlinearity.
"""

from __future__ import annotations

import numpy as np

from imubench.calibration.sensor import SensorFit, fit_sensor


def bias_at_rest(mean_dps: np.ndarray) -> np.ndarray:
    """(3,) zero-rate level (dps): the static capture's mean."""
    return np.asarray(mean_dps, dtype=np.float64).copy()


def rate_table(
    rates_dps: np.ndarray, means_dps: np.ndarray, stderr_dps: np.ndarray, *,
    quadratic: bool = True,
) -> SensorFit:
    """Fit over captures at the true rates ``rates_dps`` (k, 3) of their means and
    standard errors (k, 3). ``quadratic`` needs at least two non-zero rate magnitudes."""
    return fit_sensor(rates_dps, means_dps, stderr_dps, quadratic=quadratic,
                      what="rate-table gyro calibration")


__all__ = ["bias_at_rest", "rate_table"]
