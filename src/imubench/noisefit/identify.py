"""Noise identification per tau and the slope table of the application note.

Power-law noise S_y(f) ~ f^alpha. The log-log slopes of the deviations (NIST SP 1065
Table 3 / section 5.2.4; W. J. Riley, "Handbook of Frequency Stability Analysis"; IEEE Std
952 Annex C for the IMU names; TDEV = tau/sqrt(3) MDEV so its slope is MDEV's + 1):

=====  ==================  =====================  ==========  ==========  ==========
alpha  clock name          IMU name               ADEV mu/2   MDEV        TDEV
=====  ==================  =====================  ==========  ==========  ==========
 2     white PM            quantization           -1          -3/2        -1/2
 1     flicker PM          (flicker angle)        -1          -1           0
 0     white FM            angle/velocity RW (N)  -1/2        -1/2        +1/2
-1     flicker FM          bias instability (B)    0           0          +1
-2     random-walk FM      rate random walk (K)   +1/2        +1/2        +3/2
 --    drift               rate ramp (R)          +1          +1          +2
=====  ==================  =====================  ==========  ==========  ==========

ADEV cannot tell white from flicker PM (both -1); MDEV can (-3/2 vs -1). Per tau the
noise exponent is the one :func:`imubench.stats.noise_id.identify_alpha` finds (lag-1
autocorrelation, B1 ratio with R(n) when fewer than 30 points), and the local slopes are
centred log-log differences of the measured ADEV and MDEV.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SLOPE_TABLE: tuple[tuple[int | None, str, str, float, float, float], ...] = (
    (2, "white PM", "quantization", -1.0, -1.5, -0.5),
    (1, "flicker PM", "flicker angle", -1.0, -1.0, 0.0),
    (0, "white FM", "angle/velocity random walk", -0.5, -0.5, 0.5),
    (-1, "flicker FM", "bias instability", 0.0, 0.0, 1.0),
    (-2, "random-walk FM", "rate random walk", 0.5, 0.5, 1.5),
    (None, "drift", "rate ramp", 1.0, 1.0, 2.0),
)
"""(alpha, clock name, IMU name, ADEV slope, MDEV slope, TDEV slope)."""

IMU_NAME = {row[0]: row[2] for row in SLOPE_TABLE if row[0] is not None}


@dataclass(frozen=True)
class NoiseIdRow:
    """Identification at one averaging time."""

    tau_s: float
    alpha: int
    adev_slope: float
    mdev_slope: float
    tdev_slope: float
    name: str


def local_slopes(tau_s: np.ndarray, dev: np.ndarray) -> np.ndarray:
    """d ln(dev) / d ln(tau), centred differences (one-sided at the ends)."""
    lt = np.log(np.asarray(tau_s, dtype=float))
    ld = np.log(np.asarray(dev, dtype=float))
    if lt.size < 2:
        return np.full(lt.size, np.nan)
    return np.gradient(ld, lt)


def name_from_slopes(adev_slope: float, mdev_slope: float) -> str:
    """The table row whose (ADEV, MDEV) slopes are nearest (MDEV splits the PM types)."""
    best = min(SLOPE_TABLE, key=lambda r: (r[3] - adev_slope) ** 2 + (r[4] - mdev_slope) ** 2)
    return best[2]


def identify(y: np.ndarray, rate_hz: float, taus: str | list[float] = "octave"
             ) -> list[NoiseIdRow]:
    """Per tau: alpha (stats' lag-1/B1 identification on the OADEV run), slopes and name."""
    from imubench.stats import mdev, oadev

    a = oadev(y, rate_hz, "freq", taus)
    md = mdev(y, rate_hz, "freq", taus)
    common, ia, im = np.intersect1d(a.m, md.m, return_indices=True)
    tau = a.tau_s[ia]
    s_a = local_slopes(tau, a.dev[ia])
    s_m = local_slopes(tau, md.dev[im])
    rows = []
    for k in range(common.size):
        alpha = int(a.alpha[ia[k]])
        rows.append(NoiseIdRow(float(tau[k]), alpha, float(s_a[k]), float(s_m[k]),
                               float(s_m[k] + 1.0), name_from_slopes(s_a[k], s_m[k])))
    return rows


__all__ = ["IMU_NAME", "SLOPE_TABLE", "NoiseIdRow", "identify", "local_slopes",
           "name_from_slopes"]
