"""Fit of a 3-axis sensor's static error model to capture means at known inputs.

The sensor model, per output axis ``i`` (the simulator's signal chain,
``lsm6ds_sim.physics``, in matrix form)::

    y_i = sum_j M_ij u_j + q_i u_i^2 + b_i        (+ temperature terms, see temperature.py)

``u`` the true input (accelerometer: specific force in g; gyro: rate in dps), ``M`` the
3x3 sensitivity matrix (diagonal ``1 + scale_error``, off-diagonal the cross-axis
coupling times the own-axis sensitivity: ``M_ij = (1 + scale_error_i) cross_ij``),
``q_i`` the quadratic nonlinearity (``(1 + scale_error_i) nonlinearity_i``) and ``b_i``
the offset. Without ``q`` that is the classic 12-parameter model (offset, gain and
cross-axis; e.g. the six-position method of ST DT0053 / Analog Devices AN-1057 and
MATLAB's ``accelcal``). Each axis is one weighted linear least-squares problem
(:func:`imubench.calibration.lsq.weighted_lsq`): 4 (or 5) unknowns from the ``k``
positions or rates, weighted by the standard error of each capture mean.

Six positions (+-1 g on each axis) determine the 12 parameters with 2 residual degrees of
freedom per axis, and the quadratic term too (``u_i^2`` is 1 in the two positions along
axis ``i`` and 0 in the other four: a nonlinearity looks like an offset seen only along
gravity) with 1 left. On a rate table (``+-r1, +-r2, 0`` about each axis) the gyro
model is over-determined the same way.

The correction inverts the model: ``u = M^-1 (y - b - q u^2)``, solved by fixed-point
iteration from ``u0 = M^-1 (y - b)`` (a contraction for ``|2 q u| << 1``; 4 steps leave
``(2 q u)^4`` of the nonlinearity, below 1e-8 for 0.5 % at 1 g).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imubench.calibration.errors import CalibrationError
from imubench.calibration.lsq import LinearFit, weighted_lsq

AXES = ("x", "y", "z")
CORRECTION_ITERATIONS = 4


@dataclass(frozen=True)
class SensorFit:
    """The fitted static model of one 3-axis sensor.

    Attributes:
        matrix: (3, 3) sensitivity matrix ``M`` (unitless).
        offset: (3,) ``b`` (sensor unit).
        nonlinearity: (3,) ``q`` (1/unit), zeros when not fitted.
        quadratic: whether ``q`` was fitted.
        fits: the per-axis least-squares results (parameter order ``M_i1 M_i2 M_i3 b_i
            [q_i]``).
        inputs: (k, 3) the true inputs; ``means`` (k, 3) and ``stderr`` (k, 3) the data.
    """

    matrix: np.ndarray
    offset: np.ndarray
    nonlinearity: np.ndarray
    quadratic: bool
    fits: tuple[LinearFit, LinearFit, LinearFit]
    inputs: np.ndarray
    means: np.ndarray
    stderr: np.ndarray

    @property
    def residuals(self) -> np.ndarray:
        """(k, 3) ``y - model`` at each input (sensor unit)."""
        return np.stack([f.residuals for f in self.fits], axis=1)

    @property
    def scale_error(self) -> np.ndarray:
        """(3,) ``M_ii - 1``."""
        return np.diag(self.matrix) - 1.0

    @property
    def cross_axis(self) -> np.ndarray:
        """(3, 3) ``M_ij / M_ii`` (zero diagonal): the model's ``cross_*`` keys."""
        c = self.matrix / np.diag(self.matrix)[:, None]
        np.fill_diagonal(c, 0.0)
        return c

    def stderr_of(self, name: str) -> np.ndarray:
        """Standard errors of ``offset``, ``scale_error`` or ``nonlinearity`` (3,)."""
        col = {"scale_error": None, "offset": 3, "nonlinearity": 4}[name]
        out = np.empty(3)
        for i, f in enumerate(self.fits):
            j = i if col is None else col
            if name == "nonlinearity" and not self.quadratic:
                raise CalibrationError("nonlinearity was not fitted (quadratic=False)")
            out[i] = f.stderr[j]
        return out

    def chi2(self) -> tuple[float, int]:
        """Sum of the axes' weighted residual sums and degrees of freedom."""
        return sum(f.chi2 for f in self.fits), sum(f.dof for f in self.fits)


def fit_sensor(
    inputs: np.ndarray, means: np.ndarray, stderr: np.ndarray, *, quadratic: bool, what: str
) -> SensorFit:
    """Fit ``M``, ``b`` (and ``q`` if ``quadratic``) to capture means at known inputs.

    Args:
        inputs: (k, 3) true input of each capture (g or dps).
        means: (k, 3) mean output of each capture.
        stderr: (k, 3) standard error of each mean.
        quadratic: fit the nonlinearity ``q`` too.
        what: names the fit in error messages.
    """
    u = np.asarray(inputs, dtype=np.float64)
    y = np.asarray(means, dtype=np.float64)
    se = np.asarray(stderr, dtype=np.float64)
    if u.ndim != 2 or u.shape[1] != 3 or y.shape != u.shape or se.shape != u.shape:
        raise CalibrationError(f"{what}: inputs, means and standard errors must be (k, 3)")
    fits = []
    for i in range(3):
        cols = [u, np.ones((len(u), 1))]
        if quadratic:
            cols.append(u[:, i : i + 1] ** 2)
        fits.append(weighted_lsq(np.hstack(cols), y[:, i], se[:, i], f"{what}, axis {AXES[i]}"))
    matrix = np.array([f.params[:3] for f in fits])
    offset = np.array([f.params[3] for f in fits])
    q = np.array([f.params[4] for f in fits]) if quadratic else np.zeros(3)
    return SensorFit(matrix, offset, q, quadratic, (fits[0], fits[1], fits[2]), u, y, se)


def check_invertible(matrix: np.ndarray, what: str) -> None:
    """Refuse a sensitivity matrix no correction can invert (an axis that does not
    respond: stuck, dead, or a fit that went wrong)."""
    diag = np.diag(matrix)
    if np.any(np.abs(diag) < 0.5) or np.linalg.cond(matrix) > 10.0:
        raise CalibrationError(
            f"{what}: the sensitivity matrix cannot be a working sensor's (diagonal"
            f" {np.round(diag, 4).tolist()}, condition {np.linalg.cond(matrix):.3g});"
            " an axis does not respond"
        )


def correct(
    y: np.ndarray, matrix: np.ndarray, offset: np.ndarray, nonlinearity: np.ndarray
) -> np.ndarray:
    """Invert ``y = M u + q u^2 + b`` for ``u`` (rows of ``y``; see the module docstring)."""
    y = np.asarray(y, dtype=np.float64)
    minv = np.linalg.inv(matrix)
    rhs = y - offset
    u = rhs @ minv.T
    if np.any(nonlinearity):
        for _ in range(CORRECTION_ITERATIONS):
            u = (rhs - nonlinearity * u**2) @ minv.T
    return u


__all__ = ["AXES", "SensorFit", "check_invertible", "correct", "fit_sensor"]
