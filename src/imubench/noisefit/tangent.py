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


def _read(values: np.ndarray, edf: np.ndarray, i: int) -> tuple[float, tuple[float, float]]:
    v = float(values[i])
    e = float(edf[i])
    lo = v * math.sqrt(e / chi2.ppf(0.975, e))
    hi = v * math.sqrt(e / chi2.ppf(0.025, e))
    return v, (lo, hi)


def tangent_readings(tau_s: np.ndarray, dev: np.ndarray
                     ) -> dict[str, tuple[np.ndarray, int]]:
    """The tangent rule on an ADEV curve (module docstring), without its intervals.

    Returns ``{"white": (N per point, i), "flicker": (B per point, i), "random_walk":
    (K per point, i)}``: each term's value as it would be read at every point
    (N = sigma sqrt(tau), B = sigma / 0.664, K = sigma sqrt(3 / tau)) and the index ``i``
    of the point the rule reads it at: the slope nearest -1/2 left of the minimum, the
    minimum, the slope nearest +1/2 right of the minimum. ``tau_s`` ascending, ``dev`` > 0,
    at least two points.
    """
    tau = np.asarray(tau_s, dtype=float)
    dev = np.asarray(dev, dtype=float)
    slope = local_slopes(tau, dev)
    i_min = int(np.argmin(dev))
    left = np.arange(i_min + 1)
    right = np.arange(i_min, tau.size)
    return {
        "white": (dev * np.sqrt(tau), int(left[np.argmin(np.abs(slope[left] + 0.5))])),
        "flicker": (dev / FLICKER_FLOOR, i_min),
        "random_walk": (dev * np.sqrt(3.0 / tau),
                        int(right[np.argmin(np.abs(slope[right] - 0.5))])),
    }


def fit_tangent(y: np.ndarray, rate_hz: float, *, channel: str = "gx",
                taus: Sequence[float] | None = None) -> ChannelFit:
    """N, B, K by the tangent method (module docstring); other terms are reported 0.

    A term is present only where the curve shows it, by the rule of the live readouts
    (:func:`imubench.fleet.readouts.read_terms`): N needs a point of slope within 0.2 of
    -1/2, K one of +1/2 with a significant rise, B a floor the curve rises from
    significantly (without a rise the minimum holds the white noise and random walk
    too: B is at most it). Otherwise the term is absent with the reading as its upper limit (the
    other terms only add to the curve): on white noise alone the rule read flicker and
    random walk, with intervals excluding 0, off a curve still falling at -0.6."""
    from imubench.fleet.readouts import read_terms

    arr = check_series(y, rate_hz, channel)
    pts = avar_points(arr, rate_hz, taus, channel)
    tau = pts.tau_s
    dev = np.sqrt(pts.avar)
    bounds = [_read(dev, pts.edf, i)[1] for i in range(tau.size)]
    shown = read_terms(tau.tolist(), dev.tolist(), [b[0] for b in bounds],
                       [b[1] for b in bounds])  # the live view's rule, exactly
    params = dict.fromkeys(PARAM_KEYS, 0.0)
    params["filter_order"] = 1
    ci: dict[str, tuple[float, float]] = {}
    notes = []
    present = []
    for (key, (values, i)), term in zip(tangent_readings(tau, dev).items(), ("N", "B", "K"),
                                        strict=True):
        value, interval = _read(values, pts.edf, i)
        reading = shown[term]
        if reading["kind"] == "value":
            params[key], ci[key] = value, interval
            present.append(key)
            notes.append(f"{key} read at tau = {tau[i]:.4g} s")
        else:
            limit = (float(reading["value"]) if reading["kind"] == "upper"
                     and reading["value"] is not None else interval[1])
            ci[key] = (0.0, limit)
            notes.append(f"{key} not read: {reading['note']}; upper limit {limit:.4g}")
    return ChannelFit(channel, float(rate_hz), "tangent", params, ci, tuple(present),
                      pts.tau_s, pts.avar, pts.edf, float(np.nanmean(arr)),
                      notes=tuple(notes))


__all__ = ["FLICKER_FLOOR", "fit_tangent", "tangent_readings"]
