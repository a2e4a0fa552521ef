"""Offset over temperature: the application note's three-point procedure, the exact
quadratic through the same three points, and a least-squares polynomial over a sweep.

Model of the offset of each axis against the die temperature ``T`` (read from the chip's
own sensor, the reading the correction will use at run time), about ``T_ref``::

    b(T) = c0 + c1 dT + c2 dT^2,     dT = T - T_ref

(the simulator's ``temp_coeff`` and ``temp_coeff2``). The correction subtracts
``c1 dT + c2 dT^2``; the constant belongs to the offset calibration at ``T_ref``.

* :func:`three_point_note`: the procedure of Analog Devices' tilt note (A. Fan, "How to
  Improve the Accuracy of Inclination Measurement Using an Accelerometer", Analog
  Dialogue): offset at ambient (``c0 = b(T_amb)``), linear term from the hot point
  (``c1 = (b_hot - b_amb) / (T_hot - T_amb)``), then the quadratic term from what the
  linear term leaves at the cold point
  (``c2 = (b_cold - b_amb - c1 dT_cold) / dT_cold^2``). Taken literally this is a
  sequential fit: with a true curve ``a dT + beta dT^2`` it gives
  ``c1 = a + beta dT_hot`` and ``c2 = beta (dT_cold - dT_hot) / dT_cold``, so the
  corrected curve misses the hot point by ``beta dT_hot^2 (dT_hot - dT_cold) / dT_cold``
  (with +60 / -65 K: 1.92 times the quadratic term itself, in the opposite sense).
* :func:`three_point_exact`: the quadratic through the three points (Vandermonde
  solve); exact at all three for the same measurements.
* :func:`polynomial`: weighted least squares of degree 1 or 2 over any number of chamber
  points (:func:`imubench.calibration.lsq.weighted_lsq`), with standard errors of the
  coefficients scaled by the Birge ratio ``sqrt(max(1, chi2 / dof))`` when the points
  scatter more than their capture noise says (the bias wanders between chamber points);
  such an error is itself estimated from ``dof`` residuals, so its intervals take
  Student's t quantile with ``dof`` degrees of freedom (:attr:`TemperatureFit.stderr_dof`,
  the GUM's Welch-Satterthwaite case of one Type A component). Given the points' times, a
  drift linear in time is fitted beside the polynomial: a sweep takes an hour or more, the
  bias's random walk and flicker drift over it, and a sweep that climbs and then falls
  (25, 45, 65, 85, 0, -20, -40, 25 degC) aliases that drift into the temperature terms
  (simulated LSM6DSL boards: 95 % intervals of the linear term covered the truth in 117 of
  144 channel fits, z spread 1.5-2.0). The repeated set point is what measures it.

Every fit reports its residuals over the sweep (:meth:`TemperatureFit.residuals`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from imubench.calibration.errors import CalibrationError
from imubench.calibration.lsq import weighted_lsq

METHODS = ("three-point-note", "three-point-exact", "polynomial")


@dataclass(frozen=True)
class TemperatureFit:
    """Offset-versus-temperature coefficients of one 3-axis sensor.

    Attributes:
        method: one of :data:`METHODS`.
        temp_ref_c: ``T_ref`` (degC).
        offset: (3,) ``c0`` (unit).
        coeff1: (3,) ``c1`` (unit/degC).
        coeff2: (3,) ``c2`` (unit/degC^2).
        stderr1, stderr2: (3,) standard errors of ``c1``, ``c2`` (least squares only).
        chi2, dof: the weighted residual sum and its degrees of freedom (least squares).
    """

    method: str
    temp_ref_c: float
    offset: np.ndarray
    coeff1: np.ndarray
    coeff2: np.ndarray
    stderr1: np.ndarray | None = None
    stderr2: np.ndarray | None = None
    chi2: float | None = None
    dof: int | None = None
    stderr_dof: np.ndarray | None = None
    """(3,) degrees of freedom of ``stderr1``/``stderr2`` per axis: the residuals' ``dof``
    where the Birge ratio scaled them, ``inf`` where they are the capture noise's."""
    drift_per_h: np.ndarray | None = None
    """(3,) fitted bias drift over the sweep, unit per hour (None: not fitted)."""

    def model(self, temp_c: np.ndarray) -> np.ndarray:
        """(k, 3) ``c0 + c1 dT + c2 dT^2`` at the temperatures ``temp_c`` (k,)."""
        dT = np.asarray(temp_c, dtype=np.float64)[:, None] - self.temp_ref_c
        return self.offset + dT * (self.coeff1 + dT * self.coeff2)

    def residuals(self, temp_c: np.ndarray, means: np.ndarray) -> np.ndarray:
        """(k, 3) measured offsets minus the model (what the correction leaves)."""
        return np.asarray(means, dtype=np.float64) - self.model(temp_c)


def _pick(temps: np.ndarray, means: np.ndarray, t: float) -> tuple[float, np.ndarray]:
    k = int(np.argmin(np.abs(temps - t)))
    return float(temps[k]), means[k]


def three_point_note(temps_c: np.ndarray, means: np.ndarray, ambient_c: float, hot_c: float,
                     cold_c: float) -> TemperatureFit:
    """The note's sequential procedure (module docstring) from the points of a sweep
    nearest ``ambient_c``, ``hot_c`` and ``cold_c`` (chamber set points, degC); the
    measured die temperatures of those points are used."""
    temps = np.asarray(temps_c, dtype=np.float64)
    y = np.asarray(means, dtype=np.float64)
    ta, ya = _pick(temps, y, ambient_c)
    th, yh = _pick(temps, y, hot_c)
    tc, yc = _pick(temps, y, cold_c)
    if not tc < ta < th:
        raise CalibrationError(
            f"three-point temperature calibration needs cold < ambient < hot, got die"
            f" temperatures {tc:.2f}, {ta:.2f}, {th:.2f} degC"
        )
    c1 = (yh - ya) / (th - ta)
    dtc = tc - ta
    c2 = (yc - ya - c1 * dtc) / dtc**2
    return TemperatureFit("three-point-note", ta, ya.copy(), c1, c2)


def three_point_exact(temps_c: np.ndarray, means: np.ndarray, ambient_c: float, hot_c: float,
                      cold_c: float) -> TemperatureFit:
    """The quadratic through the same three points as :func:`three_point_note`."""
    temps = np.asarray(temps_c, dtype=np.float64)
    y = np.asarray(means, dtype=np.float64)
    pts = [_pick(temps, y, t) for t in (ambient_c, hot_c, cold_c)]
    ta = pts[0][0]
    d = np.array([p[0] - ta for p in pts])
    if len(set(np.round(d, 9))) < 3:
        raise CalibrationError("three-point temperature calibration: two points coincide")
    V = np.stack([np.ones(3), d, d**2], axis=1)
    coef = np.linalg.solve(V, np.stack([p[1] for p in pts]))
    return TemperatureFit("three-point-exact", ta, coef[0], coef[1], coef[2])


def polynomial(temps_c: np.ndarray, means: np.ndarray, stderr: np.ndarray, temp_ref_c: float,
               degree: int = 2, times_s: np.ndarray | None = None) -> TemperatureFit:
    """Weighted least-squares polynomial (degree 1 or 2) of the offsets over a sweep;
    with ``times_s`` (each point's time, s), a drift linear in time beside it (see the
    module docstring: pass times only where the sweep revisits a temperature, else the
    drift and the temperature terms cannot be told apart and the fit is refused)."""
    if degree not in (1, 2):
        raise CalibrationError(f"temperature polynomial degree {degree} must be 1 or 2")
    temps = np.asarray(temps_c, dtype=np.float64)
    y = np.asarray(means, dtype=np.float64)
    se = np.asarray(stderr, dtype=np.float64)
    dT = temps - temp_ref_c
    cols = [dT**p for p in range(degree + 1)]
    if times_s is not None:
        t_h = np.asarray(times_s, dtype=np.float64) / 3600.0
        cols.append(t_h - t_h.mean())
    X = np.stack(cols, axis=1)
    fits = [weighted_lsq(X, y[:, i], se[:, i], f"temperature polynomial, axis {'xyz'[i]}")
            for i in range(3)]
    par = np.array([f.params for f in fits])
    # Birge ratio: where the points scatter more than their standard errors say (the
    # bias wanders between chamber points: flicker, random walk), the coefficients'
    # standard errors grow by sqrt(chi2 / dof); never shrunk below the noise's
    dof = np.array([float(f.dof) for f in fits])
    ratio = np.array([f.chi2 / f.dof if f.dof > 0 else 1.0 for f in fits])
    scaled = ratio > 1.0
    err = np.array([f.stderr for f in fits]) * np.sqrt(np.where(scaled, ratio, 1.0))[:, None]
    zero = np.zeros(3)
    return TemperatureFit(
        "polynomial", float(temp_ref_c), par[:, 0], par[:, 1],
        par[:, 2] if degree == 2 else zero, err[:, 1], err[:, 2] if degree == 2 else zero,
        float(sum(f.chi2 for f in fits)), int(sum(f.dof for f in fits)),
        np.where(scaled, dof, math.inf),
        None if times_s is None else par[:, -1],
    )


__all__ = ["METHODS", "TemperatureFit", "polynomial", "three_point_exact", "three_point_note"]
