"""Model-file units -> datasheet units and Kalibr ``imu.yaml``; datasheet comparison.

Model units (``docs/noise-model.md``): gyro in dps, accel in g. N unit/sqrt(Hz) (AVAR
N^2/tau), B unit (AVAR (2 ln2/pi) B^2), K unit/sqrt(s) (AVAR K^2 tau/3).

Conversions (g0 = 9.80665 m/s^2, 1 h = 3600 s, so 1/sqrt(Hz) = 1 sqrt(s) = sqrt(h)/60):

=============================  ==========================================
gyro ARW deg/sqrt(h)           N [dps/sqrt(Hz)] * 60
gyro noise density mdps/√Hz    N * 1000
gyro bias instability deg/h    B [dps] * 3600   (IEEE coefficient; ADEV floor = 0.664 B)
gyro RRW deg/h/sqrt(h)         K [dps/sqrt(s)] * 3600 * 60
accel noise density ug/√Hz     N [g/sqrt(Hz)] * 1e6
accel VRW m/s/sqrt(h)          N * g0 * 60
accel bias instability ug      B [g] * 1e6
accel random walk ug/sqrt(s)   K [g/sqrt(s)] * 1e6     (m/s^2/sqrt(h): K g0 60)
=============================  ==========================================

Kalibr (``imu.yaml``, continuous-time densities in SI; Kalibr wiki "IMU Noise Model"): its
white-noise density sigma has discrete std sigma/sqrt(dt) per sample and its bias random
walk sigma_b a discrete std sigma_b sqrt(dt) per sample, which is exactly N and K here:
gyroscope_noise_density = N pi/180 rad/s/sqrt(Hz), gyroscope_random_walk = K pi/180
rad/s^2/sqrt(Hz), accelerometer_noise_density = N g0 m/s^2/sqrt(Hz),
accelerometer_random_walk = K g0 m/s^3/sqrt(Hz), update_rate = the sample rate (Hz).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from imubench.noisefit.errors import FitError

G0: float = 9.80665
"""Standard gravity (m/s^2), the g of the model file."""
DEG: float = math.pi / 180.0
GYRO = ("gx", "gy", "gz")
ACCEL = ("ax", "ay", "az")


def datasheet_units(channel: str, params: Mapping[str, float]) -> dict[str, float]:
    """The fitted N, B, K of one channel in datasheet units (names carry the unit)."""
    n = float(params.get("white", 0.0))
    b = float(params.get("flicker", 0.0))
    k = float(params.get("random_walk", 0.0))
    if channel in GYRO:
        return {
            "arw_deg_per_sqrt_h": n * 60.0,
            "noise_density_mdps_per_sqrt_hz": n * 1000.0,
            "bias_instability_deg_per_h": b * 3600.0,
            "adev_floor_deg_per_h": b * 3600.0 * math.sqrt(2.0 * math.log(2.0) / math.pi),
            "rrw_deg_per_h_per_sqrt_h": k * 3600.0 * 60.0,
        }
    if channel in ACCEL:
        return {
            "noise_density_ug_per_sqrt_hz": n * 1e6,
            "vrw_m_per_s_per_sqrt_h": n * G0 * 60.0,
            "bias_instability_ug": b * 1e6,
            "adev_floor_ug": b * 1e6 * math.sqrt(2.0 * math.log(2.0) / math.pi),
            "random_walk_ug_per_sqrt_s": k * 1e6,
        }
    raise FitError(f"units: unknown channel {channel!r}; channels are gx gy gz ax ay az")


def kalibr_imu(params_by_channel: Mapping[str, Mapping[str, float]], rate_hz: float,
               rostopic: str = "/imu0") -> dict[str, float | str]:
    """Kalibr ``imu.yaml`` values: the worst (largest) axis of each sensor, SI units.

    Kalibr has one density per sensor, so the largest axis value is taken (the usual
    conservative choice); channels that were not fitted are skipped.
    """
    out: dict[str, float | str] = {"rostopic": rostopic, "update_rate": float(rate_hz)}
    gyro = [params_by_channel[c] for c in GYRO if c in params_by_channel]
    accel = [params_by_channel[c] for c in ACCEL if c in params_by_channel]
    if gyro:
        out["gyroscope_noise_density"] = max(float(p.get("white", 0.0)) for p in gyro) * DEG
        out["gyroscope_random_walk"] = max(float(p.get("random_walk", 0.0)) for p in gyro) * DEG
    if accel:
        out["accelerometer_noise_density"] = max(float(p.get("white", 0.0)) for p in accel) * G0
        out["accelerometer_random_walk"] = (
            max(float(p.get("random_walk", 0.0)) for p in accel) * G0)
    return out


def kalibr_yaml(values: Mapping[str, float | str]) -> str:
    """The ``imu.yaml`` text (flat YAML, one key per line, units in comments)."""
    units = {
        "accelerometer_noise_density": "m/s^2/sqrt(Hz)",
        "accelerometer_random_walk": "m/s^3/sqrt(Hz)",
        "gyroscope_noise_density": "rad/s/sqrt(Hz)",
        "gyroscope_random_walk": "rad/s^2/sqrt(Hz)",
        "update_rate": "Hz",
    }
    lines = ["# Kalibr IMU noise parameters written by imubench fit (continuous time, SI)"]
    for key in ("rostopic", "update_rate", "accelerometer_noise_density",
                "accelerometer_random_walk", "gyroscope_noise_density", "gyroscope_random_walk"):
        if key not in values:
            continue
        v = values[key]
        text = v if isinstance(v, str) else f"{float(v):.6e}"
        lines.append(f"{key}: {text}" + (f"  # {units[key]}" if key in units else ""))
    return "\n".join(lines) + "\n"


def datasheet_comparison(chip: str | None,
                         params_by_channel: Mapping[str, Mapping[str, float]]
                         ) -> dict[str, dict[str, float]]:
    """Fitted white density vs the chip's datasheet-typical one (``datasheet:<chip>``).

    Returns ``{channel: {"fitted": N, "typical": N_typ, "ratio": N / N_typ}}``; empty when
    the chip is unknown or has no shipped model. The typicals are those of the shipped
    files (marked unverified there).
    """
    from lsm6ds_sim.model import DATASHEET_PREFIX, datasheet_chips, load_model

    if not chip or chip.lower() not in datasheet_chips():
        return {}
    typical = load_model(DATASHEET_PREFIX + chip)
    out: dict[str, dict[str, float]] = {}
    for ch, p in params_by_channel.items():
        n_typ = float(typical[ch].white)
        n = float(p.get("white", 0.0))
        if n_typ > 0:
            out[ch] = {"fitted": n, "typical": n_typ, "ratio": n / n_typ}
    return out


__all__ = [
    "G0",
    "datasheet_comparison",
    "datasheet_units",
    "kalibr_imu",
    "kalibr_yaml",
]
