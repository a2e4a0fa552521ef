"""The mean of a static capture and its standard error, from the capture's own noise.

A calibration point is the mean ``y_bar`` of ``n`` samples taken over ``T = n tau0``
seconds. Its standard error is not ``s / sqrt(n)`` unless the noise is white; it is read
off the overlapping Allan deviation of the capture itself (``imubench.stats.oadev``, NIST
SP 1065) at the longest averaging time it supports, ``tau = m tau0`` with
``m = floor(n / 4)``, and extrapolated to ``T`` along the power law of the noise type
``alpha`` identified there (Stable32's rule, ``imubench.stats.noise_id``):

    SE(T) = ADEV(tau) (T / tau)^(-(alpha + 1) / 2),   alpha clipped to [-2, 0]

White FM (alpha = 0) gives ``ADEV(tau) sqrt(tau / T)``, exact for white noise since
``AVAR(tau) = sigma^2 tau0 / tau`` and ``Var(y_bar) = sigma^2 / n``; flicker FM (-1)
keeps the deviation flat, random walk (-2) lets it grow as ``sqrt(T / tau)``; faster
falling noise (alpha > 0) is treated as white (conservative). The confidence interval of
the mean uses Student's t with the EDF of that Allan deviation (Greenhall-Riley): with
few averages at ``tau`` the interval widens honestly.

Quantisation floor: when the sample scatter is below one LSB the output is not dithered
and the mean carries a systematic error uniform within +-LSB/2 (variance LSB^2/12),
which no averaging removes; it is added in quadrature (a stuck axis then still has a
finite, honest standard error).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import stdtrit  # Student's t quantile stdtrit(df, p) = t.ppf(p, df)

from imubench import stats
from imubench.calibration.errors import CalibrationError
from imubench.stats.result import StatResult

MIN_SAMPLES = 16
"""Fewest finite samples a capture mean is computed from."""


class TooFewSamplesError(CalibrationError):
    """A capture holds too few samples for a mean: the capture's length (a station
    setting) or the data lost decide it, not the board; the jig reports INCONCLUSIVE."""


@dataclass(frozen=True)
class MeanEstimate:
    """Mean of one capture channel.

    Attributes:
        mean: the sample mean (unit of the data).
        stderr: its standard error (see the module docstring).
        edf: equivalent degrees of freedom of ``stderr`` (inf for the LSB floor alone).
        n: finite samples averaged.
        duration_s: ``n / rate``.
    """

    mean: float
    stderr: float
    edf: float
    n: int
    duration_s: float

    def ci(self, confidence: float = 0.95) -> tuple[float, float]:
        """Two-sided interval ``mean -+ t_{(1+c)/2}(edf) stderr``."""
        q = float(stdtrit(self.edf, 0.5 + confidence / 2.0)) if math.isfinite(
            self.edf
        ) else float(stdtrit(1e9, 0.5 + confidence / 2.0))
        return self.mean - q * self.stderr, self.mean + q * self.stderr


def capture_mean(y: np.ndarray, rate_hz: float, lsb: float, what: str) -> MeanEstimate:
    """Mean and standard error of the samples ``y`` (NaN = lost) taken at ``rate_hz``;
    ``lsb`` is the output resolution (same unit); ``what`` names the capture in errors."""
    y = np.asarray(y, dtype=np.float64)
    finite = np.isfinite(y)
    n = int(finite.sum())
    if n < MIN_SAMPLES:
        raise TooFewSamplesError(
            f"{what}: {n} samples; a capture mean needs at least {MIN_SAMPLES}"
        )
    mean = float(np.mean(y[finite]))
    duration_s = n / rate_hz
    floor_var = lsb**2 / 12.0 if float(np.std(y[finite])) < lsb else 0.0
    se_noise, edf = 0.0, math.inf
    if float(np.ptp(y[finite])) > 0:
        res = _longest_oadev(y, rate_hz)
        if res is None:
            raise TooFewSamplesError(
                f"{what}: the samples lost leave no stretch long enough for a standard "
                f"error ({n} of {len(y)} samples)")
        adev = float(res.dev[0])
        alpha = int(res.alpha[0]) if int(res.alpha[0]) != -99 else 0
        alpha = min(0, max(-2, alpha))
        tau = float(res.tau_s[0])
        se_noise = adev * (duration_s / tau) ** (-(alpha + 1) / 2.0)
        edf = float(res.edf[0]) if np.isfinite(res.edf[0]) and res.edf[0] > 0 else 1.0
    stderr = math.sqrt(se_noise**2 + floor_var)
    if stderr == 0.0:  # constant without a known LSB: nothing says how good it is
        raise CalibrationError(f"{what}: constant samples and no output resolution given")
    return MeanEstimate(mean, stderr, edf, n, duration_s)


def _longest_oadev(y: np.ndarray, rate_hz: float) -> StatResult | None:
    """OADEV of ``y`` at the longest averaging factor it gives a finite value at, from
    ``m = floor((len - 1) / 4)`` down by halves (None below m = 1). Lost samples (NaN)
    remove every term whose span holds one: a hole in the middle of a capture leaves no
    term at m = N/4 (the standard error came out NaN, and every fit that used the capture
    failed with "not finite"), but some at m = N/8 or N/16."""
    m = (len(y) - 1) // 4
    while m >= 1:
        res = stats.oadev(y, rate_hz, data_type="freq", afs=[m], confidence=0.683)
        if len(res) and math.isfinite(float(res.dev[0])) and float(res.dev[0]) > 0:
            return res
        m //= 2
    return None


__all__ = ["MIN_SAMPLES", "MeanEstimate", "TooFewSamplesError", "capture_mean"]
