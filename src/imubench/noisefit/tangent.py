"""The classic tangent (slope-line) reading of an Allan deviation curve, for comparison.

Datasheet practice (IEEE Std 952-1997 Annex C; El-Sheimy et al. 2008; what imu_utils,
allan_variance_ros and MATLAB's example do): put a line of slope -1/2 on the ADEV curve
where the curve's own slope is closest to -1/2 (left of the minimum) and read it at
tau = 1 s (N = sigma(t*) sqrt(t*)); put a line of slope +1/2 where the slope is closest
to +1/2 (right of the minimum) and read it at tau = 3 s (K = sigma(t*) sqrt(3/t*)); divide
the flat minimum by sqrt(2 ln2 / pi) = 0.664 (B). Where terms overlap each reading is
biased high (the tangent point carries the neighbouring terms too), and with no +1/2
region K is read off the last point; that bias is what the round-trip benchmark shows.
The 95 % interval of each value is the chi-squared interval of the ADEV point it was read
at (EDF from the stats).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.stats import chi2

from imubench.noisefit.fit import PARAM_KEYS, ChannelFit, avar_points, check_series
from imubench.noisefit.identify import local_slopes

FLICKER_FLOOR: float = math.sqrt(2.0 * math.log(2.0) / math.pi)
"""ADEV of flicker of coefficient B is 0.664 B (IEEE 952 C.3)."""


def _read(values: np.ndarray, edf: np.ndarray, i: int) -> tuple[float, tuple[float, float], int]:
    v = float(values[i])
    e = float(edf[i])
    lo = v * math.sqrt(e / chi2.ppf(0.975, e))
    hi = v * math.sqrt(e / chi2.ppf(0.025, e))
    return v, (lo, hi), i


def fit_tangent(y: np.ndarray, rate_hz: float, *, channel: str = "gx",
                taus: Sequence[float] | None = None) -> ChannelFit:
    """N, B, K by the tangent method (module docstring); other terms are reported 0."""
    arr = check_series(y, rate_hz, channel)
    pts = avar_points(arr, rate_hz, taus, channel)
    dev = np.sqrt(pts.avar)
    tau = pts.tau_s
    params = dict.fromkeys(PARAM_KEYS, 0.0)
    params["filter_order"] = 1
    ci: dict[str, tuple[float, float]] = {}
    notes = []
    slope = local_slopes(tau, dev)
    i_min = int(np.argmin(dev))
    left = np.arange(i_min + 1)
    right = np.arange(i_min, tau.size)
    picks = {
        "white": int(left[np.argmin(np.abs(slope[left] + 0.5))]),
        "flicker": i_min,
        "random_walk": int(right[np.argmin(np.abs(slope[right] - 0.5))]),
    }
    for key, values in (("white", dev * np.sqrt(tau)),
                        ("flicker", dev / FLICKER_FLOOR),
                        ("random_walk", dev * np.sqrt(3.0 / tau))):
        v, lim, i = _read(values, pts.edf, picks[key])
        params[key] = v
        ci[key] = lim
        notes.append(f"{key} read at tau = {tau[i]:.4g} s")
    return ChannelFit(channel, float(rate_hz), "tangent", params, ci,
                      ("white", "flicker", "random_walk"), pts.tau_s, pts.avar, pts.edf,
                      float(np.nanmean(arr)), notes=tuple(notes))


__all__ = ["FLICKER_FLOOR", "fit_tangent"]
