"""Weighted linear least squares with the parameter covariance the noise implies.

``y = X theta + e`` with independent errors of known standard deviation ``sigma_k`` (each
observation is the mean of a capture; its standard error comes from that capture's
noise, :mod:`imubench.calibration.capture_stats`). The estimate is
``theta = (X^T W X)^-1 X^T W y`` with ``W = diag(1/sigma^2)``; its covariance is
``(X^T W X)^-1`` (the noise propagated, *not* rescaled by the residuals: with 1 or 2
degrees of freedom per axis a residual-scaled covariance would be meaningless). The
weighted residual sum ``chi2 = sum(r_k^2 / sigma_k^2)`` is then a model check: about
``dof`` when the model holds and the noise is what the captures said.
Confidence intervals are ``theta +- z sqrt(diag cov)`` with the normal quantile ``z``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtri  # the normal quantile (scipy.stats' norm.ppf, lighter)

from imubench.calibration.errors import CalibrationError


@dataclass(frozen=True)
class LinearFit:
    """Result of :func:`weighted_lsq`.

    Attributes:
        params: (p,) estimate.
        cov: (p, p) covariance of the estimate.
        residuals: (k,) ``y - X params``.
        sigma: (k,) standard error of each observation.
        chi2: ``sum((residuals / sigma)^2)``.
        dof: ``k - p``.
    """

    params: np.ndarray
    cov: np.ndarray
    residuals: np.ndarray
    sigma: np.ndarray
    chi2: float
    dof: int

    @property
    def stderr(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))

    def ci(self, confidence: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) of each parameter: ``params -+ z stderr`` (normal quantile)."""
        z = float(ndtri(0.5 + confidence / 2.0))
        return self.params - z * self.stderr, self.params + z * self.stderr


def weighted_lsq(X: np.ndarray, y: np.ndarray, sigma: np.ndarray, what: str) -> LinearFit:
    """Fit ``y = X theta`` weighting each row by ``1/sigma``; ``what`` names the fit in
    errors (a design that cannot determine every parameter is refused, never solved
    with an arbitrary null-space component)."""
    X = np.asarray(X, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    sigma = np.asarray(sigma, dtype=np.float64)
    k, p = X.shape
    if y.shape != (k,) or sigma.shape != (k,):
        raise CalibrationError(f"{what}: need one value and one standard error per row")
    if not np.all(np.isfinite(y)) or not np.all(np.isfinite(sigma)):
        raise CalibrationError(f"{what}: a capture mean or its standard error is not finite")
    if np.any(sigma <= 0):
        raise CalibrationError(
            f"{what}: a capture has a zero standard error (a stuck or saturated output?);"
            " the fit needs noisy, unsaturated data"
        )
    if k < p:
        raise CalibrationError(f"{what}: {k} observations cannot determine {p} parameters")
    w = 1.0 / sigma
    A = X * w[:, None]
    if np.linalg.matrix_rank(A) < p:
        raise CalibrationError(
            f"{what}: the positions or rates do not determine every parameter (rank"
            f" {np.linalg.matrix_rank(A)} < {p}); check the fixture moved the board"
        )
    params, *_ = np.linalg.lstsq(A, y * w, rcond=None)
    cov = np.linalg.inv(A.T @ A)
    residuals = y - X @ params
    chi2 = float(np.sum((residuals / sigma) ** 2))
    return LinearFit(params, cov, residuals, sigma, chi2, k - p)


__all__ = ["LinearFit", "weighted_lsq"]
