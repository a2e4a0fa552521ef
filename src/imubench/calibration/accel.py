"""Accelerometer calibration: one-point offset, +-1 g flip, six-position least squares.

Specific force convention: a perfect accelerometer at rest reads +1 g along the axis that
points up. The six positions (:data:`SIX_POSITIONS`) put each axis up and down once.

* One point (:func:`one_point_offset`): in one known position, ``offset = A - A_expected``
  on each axis (gain errors leak in on the axis along gravity; use a position where the
  axes of interest read 0 g).
* Two points per axis, the +-1 g flip (:func:`flip_two_point`): with ``A(+1g)`` and
  ``A(-1g)`` the axis's readings pointing up and down,
  ``offset = (A(+1g) + A(-1g)) / 2`` and ``gain = (A(+1g) - A(-1g)) / 2`` (g per g).
  A quadratic nonlinearity ``q`` is indistinguishable from offset here (it adds ``q`` to
  both readings).
* Six positions (:func:`six_position`): the 12-parameter least-squares fit (offset, gain
  and cross-axis; :mod:`imubench.calibration.sensor`), optionally with the quadratic term
  (15 parameters), with residuals and parameter confidence intervals.
"""

from __future__ import annotations

import numpy as np

from imubench.calibration.errors import CalibrationError
from imubench.calibration.sensor import SensorFit, fit_sensor

SIX_POSITIONS: dict[str, tuple[float, float, float]] = {
    "+X": (1.0, 0.0, 0.0),
    "-X": (-1.0, 0.0, 0.0),
    "+Y": (0.0, 1.0, 0.0),
    "-Y": (0.0, -1.0, 0.0),
    "+Z": (0.0, 0.0, 1.0),
    "-Z": (0.0, 0.0, -1.0),
}
"""Face name -> specific force in the sensor frame (g): ``+Z`` is Z up (flat, face up),
``-Z`` Z down."""


def one_point_offset(mean_g: np.ndarray, expected_g: np.ndarray) -> np.ndarray:
    """(3,) offset (g): the mean reading minus what a perfect sensor reads there."""
    return np.asarray(mean_g, dtype=np.float64) - np.asarray(expected_g, dtype=np.float64)


def flip_two_point(a_plus_g: np.ndarray, a_minus_g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis (offset (g), gain (g/g)) from each axis's reading at +1 g and -1 g."""
    ap = np.asarray(a_plus_g, dtype=np.float64)
    am = np.asarray(a_minus_g, dtype=np.float64)
    if np.any(ap <= am):
        raise CalibrationError(
            "flip calibration: an axis reads no more at +1 g than at -1 g"
            f" (+1 g {ap.tolist()}, -1 g {am.tolist()}); check the positions"
        )
    return (ap + am) / 2.0, (ap - am) / 2.0


def six_position(
    faces: list[str], means_g: np.ndarray, stderr_g: np.ndarray, *, quadratic: bool = False
) -> SensorFit:
    """Least-squares fit over the positions ``faces`` (names of :data:`SIX_POSITIONS`,
    at least the six) of the capture means (k, 3) and their standard errors (k, 3)."""
    unknown = [f for f in faces if f not in SIX_POSITIONS]
    if unknown:
        raise CalibrationError(
            f"six-position calibration: unknown faces {unknown}; use {list(SIX_POSITIONS)}"
        )
    missing = [f for f in SIX_POSITIONS if f not in faces]
    if missing:
        raise CalibrationError(f"six-position calibration: faces {missing} were not measured")
    inputs = np.array([SIX_POSITIONS[f] for f in faces])
    return fit_sensor(inputs, means_g, stderr_g, quadratic=quadratic,
                      what="six-position accelerometer calibration")


__all__ = ["SIX_POSITIONS", "flip_two_point", "one_point_offset", "six_position"]
