"""Tilt angles from a static accelerometer (specific force in g, sensor frame).

Forms (Analog Devices AN-1057, C. J. Fisher, "Using an Accelerometer for Inclination
Sensing", 2010; ST DT0058 for roll and pitch):

* single axis: ``theta = arcsin(A_i / 1 g)``, the angle of axis ``i`` above the
  horizontal; most sensitive near 0 deg, useless near +-90 deg (and wrong by the whole
  gain error: the reading is divided by an assumed 1 g);
* dual axis: ``theta = atan2(A_i, A_j)`` with both axes in the plane of rotation (``j``
  vertical at 0 deg); independent of the gain common to both axes, full 360 deg;
* three axis: ``theta = atan2(A_x, sqrt(A_y^2 + A_z^2))`` (X above horizontal),
  ``psi = atan2(A_y, sqrt(A_x^2 + A_z^2))`` (Y above horizontal),
  ``phi = atan2(sqrt(A_x^2 + A_y^2), A_z)`` (Z from vertical, the tilt);
  roll ``atan2(A_y, A_z)`` and pitch ``atan2(-A_x, sqrt(A_y^2 + A_z^2))``.

Averaging (:func:`block_average`) takes the mean of each block of ``n`` samples
*before* the nonlinear functions (averaging angles would bias them near the ends of
arcsin's range). Every function returns degrees.
"""

from __future__ import annotations

import numpy as np

from imubench.tilt.errors import TiltError

FORMS = ("single", "dual", "triple")
AXIS_INDEX = {"x": 0, "y": 1, "z": 2}


def block_average(a: np.ndarray, n: int) -> np.ndarray:
    """(n_blocks, k) means of consecutive blocks of ``n`` rows of ``a`` (k columns),
    NaN samples (lost) ignored; an incomplete last block is dropped."""
    a = np.asarray(a, dtype=np.float64)
    if n < 1:
        raise TiltError(f"averaging over n={n} samples: n must be >= 1")
    blocks = len(a) // n
    if blocks == 0:
        raise TiltError(f"averaging over n={n} samples: only {len(a)} samples")
    with np.errstate(invalid="ignore"):
        return np.nanmean(a[: blocks * n].reshape(blocks, n, a.shape[1]), axis=1)


def single_axis(a_axis_g: np.ndarray) -> np.ndarray:
    """arcsin form: angle of the axis above the horizontal (readings clipped to +-1 g)."""
    return np.degrees(np.arcsin(np.clip(np.asarray(a_axis_g, dtype=np.float64), -1.0, 1.0)))


def dual_axis(a_axis_g: np.ndarray, a_ref_g: np.ndarray) -> np.ndarray:
    """atan2 form of two axes in the plane of rotation (``ref`` vertical at 0 deg)."""
    return np.degrees(np.arctan2(np.asarray(a_axis_g, float), np.asarray(a_ref_g, float)))


def triple_axis(a_g: np.ndarray) -> dict[str, np.ndarray]:
    """Three-axis forms of rows of ``a_g`` (n, 3): ``theta``, ``psi``, ``phi``, ``roll``,
    ``pitch`` (module docstring)."""
    a = np.asarray(a_g, dtype=np.float64)
    ax, ay, az = a[:, 0], a[:, 1], a[:, 2]
    return {
        "theta": np.degrees(np.arctan2(ax, np.hypot(ay, az))),
        "psi": np.degrees(np.arctan2(ay, np.hypot(ax, az))),
        "phi": np.degrees(np.arctan2(np.hypot(ax, ay), az)),
        "roll": np.degrees(np.arctan2(ay, az)),
        "pitch": np.degrees(np.arctan2(-ax, np.hypot(ay, az))),
    }


def tilt(a_g: np.ndarray, form: str, axis: str = "x", ref: str = "z") -> dict[str, np.ndarray]:
    """Angles of rows of ``a_g`` (n, 3) in one form: ``single`` (arcsin of ``axis``),
    ``dual`` (atan2 of ``axis`` over ``ref``) or ``triple`` (every three-axis angle)."""
    if form not in FORMS:
        raise TiltError(f"tilt form {form!r} must be one of {', '.join(FORMS)}")
    for name in (axis, ref):
        if name not in AXIS_INDEX:
            raise TiltError(f"tilt axis {name!r} must be x, y or z")
    a = np.asarray(a_g, dtype=np.float64)
    if form == "single":
        return {f"{axis}_deg": single_axis(a[:, AXIS_INDEX[axis]])}
    if form == "dual":
        if axis == ref:
            raise TiltError("dual-axis tilt needs two different axes (--axis and --ref)")
        return {f"{axis}_{ref}_deg": dual_axis(a[:, AXIS_INDEX[axis]], a[:, AXIS_INDEX[ref]])}
    return {f"{k}_deg": v for k, v in triple_axis(a).items()}


def angle_between_deg(a_g: np.ndarray, b_g: np.ndarray) -> np.ndarray:
    """Angle between rows of two vector arrays (n, 3), degrees (the error of a measured
    gravity direction against the true one)."""
    a = np.asarray(a_g, dtype=np.float64)
    b = np.asarray(b_g, dtype=np.float64)
    cross = np.linalg.norm(np.cross(a, b), axis=1)
    return np.degrees(np.arctan2(cross, np.sum(a * b, axis=1)))


__all__ = ["AXIS_INDEX", "FORMS", "angle_between_deg", "block_average", "dual_axis",
           "single_axis", "tilt", "triple_axis"]
