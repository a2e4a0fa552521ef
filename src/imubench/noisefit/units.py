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

N here is the **white-equivalent density** (:func:`white_equivalent`): every term whose
AVAR follows N^2/tau at the taus a datasheet reads it (1 s and beyond), i.e. the white
noise before the output filter (``white``, unity DC gain), the white noise after it
(``output_white``) and a Gauss-Markov term of correlation time <= :data:`SHORT_MARKOV_S`
(AVAR -> 2 sigma^2 tau_c / tau for tau >> tau_c, IEEE 952 C.6) and a resonance's
spectrum at 0 Hz (:func:`resonance_floor`; the ADIS16405 gz 20 Hz peak carries a third of
the -1/2 line at 1-10 s). The split between these
is often poorly determined (ADIS16405 gyros: ``white`` 0.029 and ``output_white`` 0.029
dps/sqrt(Hz)); their sum is what the -1/2 slope of the measured curve shows.

Kalibr (``imu.yaml``, continuous-time densities in SI; Kalibr wiki "IMU Noise Model"): its
white-noise density sigma has discrete std sigma/sqrt(dt) per sample and its bias random
walk sigma_b a discrete std sigma_b sqrt(dt) per sample, which is exactly N and K here:
gyroscope_noise_density = N pi/180 rad/s/sqrt(Hz), gyroscope_random_walk = K pi/180
rad/s^2/sqrt(Hz) (K with a slower Gauss-Markov term folded in,
:func:`kalibr_random_walk`), accelerometer_noise_density = N g0 m/s^2/sqrt(Hz),
accelerometer_random_walk = K g0 m/s^3/sqrt(Hz), update_rate = the sample rate (Hz).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from imubench.noisefit.errors import FitError

G0: float = 9.80665
"""Standard gravity (m/s^2), the g of the model file."""
DEG: float = math.pi / 180.0
GYRO = ("gx", "gy", "gz")
ACCEL = ("ax", "ay", "az")


@dataclass(frozen=True)
class Quantity:
    """A datasheet quantity: ``factor`` times the model-file value of ``term`` (dps or g
    based), shown as ``label`` in ``unit``; ``key`` names it in ``fit.json``."""

    key: str
    label: str
    unit: str
    term: str
    factor: float


_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)  # ADEV of flicker B is 0.664 B (IEEE 952 C.3)
WHITE_EQUIVALENT: str = "white_equivalent"
"""Name of the white-equivalent density N (:func:`white_equivalent`) in quantities, in a
fit's ``ci`` and in the readouts; not a model-file key."""
SHORT_MARKOV_S: float = 10.0
"""A Gauss-Markov term with tau_c up to this (s) counts in N: its AVAR follows the -1/2
line 2 sigma^2 tau_c / tau from ~10 tau_c (within 15 %), so by 100 s, inside the decades
where IEEE 952 reads N off that line and extrapolates it to tau = 1 s (C.1, C.6). It is
white noise seen through a low-pass filter (a first-order filter of white noise IS a
Gauss-Markov process, DC gain 1): the Samsung S5 gyros, filtered in the phone, fit a
Markov term of sigma 0.036 dps, tau_c 1.4 s and no white term, and N was 0 (ARW 0 deg/sqrt
h) under the earlier limit of 0.1 s while the measured curve lies on 0.065 dps/sqrt(Hz)
from 10 to 200 s. A slower term is bias wander, not angle random walk. For tau_c above
0.1 s the curve at tau = 1 s lies below the N line, where the term has not yet reached
its asymptote."""


def resonance_floor(freq_hz: float, width_hz: float, rate_hz: float) -> float:
    """Density N^2 (per unit of ``resonance_height``, unit^2/Hz) that a resonance sampled
    at ``rate_hz`` adds to the -1/2 line: its two-sided spectrum at 0 Hz
    (:func:`lsm6ds_sim.noise.resonance_shape`, the line pair at +-f0 of the damped cosine
    the fit's column and the simulator share, aliasing included; N^2 = S(0) as for white
    noise). In continuous time about 1 / (1 + (2 f0 / w)^2); the sampled value is 14 %
    above that at 20 Hz of 100 Hz and twice it near Nyquist. 0 when the resonance decays
    slower than :data:`SHORT_MARKOV_S` (1 / (pi w) > SHORT_MARKOV_S) or has no width."""
    from lsm6ds_sim.noise import resonance_shape

    if not (width_hz > 0.0 and 1.0 / (math.pi * width_hz) <= SHORT_MARKOV_S):
        return 0.0
    return 0.5 * float(resonance_shape(np.zeros(1), freq_hz, width_hz, rate_hz)[0])


def white_equivalent(params: Mapping[str, float], rate_hz: float | None = None) -> float:
    """White-equivalent density N (unit/sqrt(Hz)) of a channel's model-file values:
    sqrt(white^2 + output_white^2 + 2 markov_sigma^2 markov_tau + resonance_height x
    :func:`resonance_floor`) where the Markov term counts only when markov_tau <=
    :data:`SHORT_MARKOV_S` (module docstring). ``rate_hz``: the sample rate, needed when
    the model has a resonance (its floor depends on it)."""
    n2 = float(params.get("white", 0.0)) ** 2 + float(params.get("output_white", 0.0)) ** 2
    tau_c = float(params.get("markov_tau", 0.0))
    if 0.0 < tau_c <= SHORT_MARKOV_S:
        n2 += 2.0 * float(params.get("markov_sigma", 0.0)) ** 2 * tau_c
    height = float(params.get("resonance_height", 0.0))
    if height > 0.0:
        if rate_hz is None:
            raise FitError("white-equivalent density of a model with a resonance: the "
                           "sample rate is needed (the resonance's floor depends on it)")
        n2 += height * resonance_floor(float(params.get("resonance_freq_hz", 0.0)),
                                       float(params.get("resonance_width_hz", 0.0)), rate_hz)
    return math.sqrt(n2)


def white_equivalent_weights(terms: Sequence[str], tau_c_s: float, res_freq_hz: float = 0.0,
                             res_width_hz: float = 0.0, rate_hz: float = 0.0) -> np.ndarray:
    """d(N^2)/d(theta_j) for squared amplitudes theta_j of ``terms`` (names ``white``,
    ``output_white``, ``markov``, ``resonance`` (its height, with its centre, width and
    the sample rate); others 0): the gradient of the delta-method interval of
    :func:`white_equivalent`."""
    short = 0.0 < tau_c_s <= SHORT_MARKOV_S
    floor = (resonance_floor(res_freq_hz, res_width_hz, rate_hz) if "resonance" in terms
             else 0.0)
    return np.array([1.0 if t in ("white", "output_white") else
                     2.0 * tau_c_s if (t == "markov" and short) else
                     floor if t == "resonance" else 0.0 for t in terms])


def white_equivalent_interval(n2: float, var_n2: float, z: float = 1.959964
                              ) -> tuple[float, float]:
    """95 % interval of N from N^2 and its variance (normal in N^2, clipped at 0)."""
    half = z * math.sqrt(max(var_n2, 0.0))
    return math.sqrt(max(n2 - half, 0.0)), math.sqrt(n2 + half)


def term_value(params: Mapping[str, float], term: str, rate_hz: float | None = None
               ) -> float:
    """A quantity's coefficient: a model-file key's value, or :func:`white_equivalent`
    (``rate_hz`` as there)."""
    if term == WHITE_EQUIVALENT:
        return white_equivalent(params, rate_hz)
    return float(params.get(term, 0.0))

GYRO_QUANTITIES: tuple[Quantity, ...] = (
    Quantity("noise_density_mdps_per_sqrt_hz", "rate noise density", "mdps/√Hz",
             WHITE_EQUIVALENT, 1000.0),
    Quantity("arw_deg_per_sqrt_h", "angle random walk", "°/√h", WHITE_EQUIVALENT, 60.0),
    Quantity("bias_instability_deg_per_h", "bias instability", "°/h", "flicker", 3600.0),
    Quantity("adev_floor_deg_per_h", "flicker floor of the fit (0.664 B)", "°/h", "flicker",
             3600.0 * _FLOOR),
    Quantity("rrw_deg_per_h_per_sqrt_h", "rate random walk", "°/h/√h", "random_walk",
             3600.0 * 60.0),
)
"""Gyro quantities (model unit dps); the table of the module docstring."""

ACCEL_QUANTITIES: tuple[Quantity, ...] = (
    Quantity("noise_density_ug_per_sqrt_hz", "acceleration noise density", "µg/√Hz",
             WHITE_EQUIVALENT, 1e6),
    Quantity("vrw_m_per_s_per_sqrt_h", "velocity random walk", "m/s/√h", WHITE_EQUIVALENT,
             G0 * 60.0),
    Quantity("bias_instability_ug", "bias instability", "µg", "flicker", 1e6),
    Quantity("adev_floor_ug", "flicker floor of the fit (0.664 B)", "µg", "flicker",
             1e6 * _FLOOR),
    Quantity("random_walk_ug_per_sqrt_s", "acceleration random walk", "µg/√s",
             "random_walk", 1e6),
)
"""Accel quantities (model unit g); the table of the module docstring."""


def quantities(channel: str) -> tuple[Quantity, ...]:
    """The datasheet quantities of ``channel`` (gx gy gz: gyro, ax ay az: accel)."""
    if channel in GYRO:
        return GYRO_QUANTITIES
    if channel in ACCEL:
        return ACCEL_QUANTITIES
    raise FitError(f"units: unknown channel {channel!r}; channels are gx gy gz ax ay az")


def datasheet_units(channel: str, params: Mapping[str, float], rate_hz: float | None = None
                    ) -> dict[str, float]:
    """The fitted N, B, K of one channel in datasheet units (names carry the unit;
    ``rate_hz`` as in :func:`white_equivalent`)."""
    return {q.key: term_value(params, q.term, rate_hz) * q.factor
            for q in quantities(channel)}


def param_units(channel: str) -> dict[str, str]:
    """The unit of every noise-model parameter of ``channel`` (gx..az; docs/noise-model.md)
    and of the white-equivalent density, for the JSON outputs: ``u`` is the channel's unit
    (dps or g)."""
    from imubench.batch import UNITS

    if channel not in (*GYRO, *ACCEL):
        raise FitError(f"units: unknown channel {channel!r}; channels are gx gy gz ax ay az")
    u = UNITS[channel]
    return {
        "white": f"{u}/sqrt(Hz)", "flicker": u, "random_walk": f"{u}/sqrt(s)",
        "ramp": f"{u}/s", "quantization": f"{u}*s", "markov_sigma": u, "markov_tau": "s",
        "sine_amplitude": u, "sine_freq": "Hz", "bandwidth_hz": "Hz", "filter_order": "1",
        "resonance_freq_hz": "Hz", "resonance_width_hz": "Hz",
        "resonance_height": f"{u}^2/Hz",
        "output_white": f"{u}/sqrt(Hz)", WHITE_EQUIVALENT: f"{u}/sqrt(Hz)",
        "temp_coeff": f"{u}/degC",
        "temp_coeff2": f"{u}/degC^2", "outlier_rate": "1/s", "outlier_amplitude": u,
        "bias": u,
    }


KALIBR_UNITS: dict[str, str] = {
    "update_rate": "Hz", "gyroscope_noise_density": "rad/s/sqrt(Hz)",
    "gyroscope_random_walk": "rad/s^2/sqrt(Hz)",
    "accelerometer_noise_density": "m/s^2/sqrt(Hz)",
    "accelerometer_random_walk": "m/s^3/sqrt(Hz)",
}
"""The units of Kalibr's ``imu.yaml`` values (SI, continuous-time densities)."""


KALIBR_TERMS: dict[str, tuple[str, str]] = {
    "gyroscope_noise_density": ("gyro", WHITE_EQUIVALENT),
    "gyroscope_random_walk": ("gyro", "random_walk"),
    "accelerometer_noise_density": ("accel", WHITE_EQUIVALENT),
    "accelerometer_random_walk": ("accel", "random_walk"),
}
"""Kalibr key -> (sensor, model-file key of the fitted term)."""


def check_kalibr_request(inflate: float, channels: Iterable[str] | None = None) -> None:
    """Refuse a Kalibr export that cannot be complete (callable before any fitting):
    ``inflate`` must be >= 1 and ``channels`` (when known) must hold a gyro and an
    accelerometer axis (Kalibr needs all four densities; no placeholder values are made
    up)."""
    if not (math.isfinite(inflate) and inflate >= 1.0):
        raise FitError(f"--kalibr-inflate {inflate}: must be a number >= 1")
    if channels is None:
        return
    have = set(channels)
    missing = [key for key, (sensor, _) in KALIBR_TERMS.items()
               if not have & set(GYRO if sensor == "gyro" else ACCEL)]
    if missing:
        sensors = sorted({KALIBR_TERMS[k][0] for k in missing})
        names = " and ".join("accelerometer (ax ay az)" if s == "accel" else "gyro (gx gy gz)"
                             for s in sensors)
        raise FitError(f"Kalibr imu.yaml needs {', '.join(missing)}, but no {names} axis "
                       "was fitted; fit both sensors")


def kalibr_random_walk(params: Mapping[str, float]) -> float:
    """The bias random walk written for Kalibr: K with a Gauss-Markov term slower than
    :data:`SHORT_MARKOV_S` (bias wander, not in N) folded in as sigma sqrt(2 / tau_c).
    Kalibr's model has white noise and a bias random walk only. Over times short against
    tau_c a Gauss-Markov process diffuses as a random walk of that coefficient, and its
    spectrum 2 sigma^2 tau_c / (1 + (2 pi f tau_c)^2) never exceeds the random walk's
    (2 sigma^2 / tau_c) / (2 pi f)^2: the folded walk bounds it at every frequency and
    equals it in any filter's band (f >> 1 / (2 pi tau_c)). Folded into the density
    instead, as sigma sqrt(2 tau_c), a tau_c of 16-200 s made the density 10-27x the
    measured white level and left the walk 11x low."""
    k = float(params.get("random_walk", 0.0))
    tau_c = float(params.get("markov_tau", 0.0))
    if tau_c > SHORT_MARKOV_S:
        k = math.hypot(k, float(params.get("markov_sigma", 0.0)) * math.sqrt(2.0 / tau_c))
    return k


def kalibr_imu(params_by_channel: Mapping[str, Mapping[str, float]], rate_hz: float,
               rostopic: str = "/imu0", *,
               upper_limits: Mapping[str, Mapping[str, float]] | None = None,
               inflate: float = 1.0) -> dict[str, Any]:
    """Kalibr ``imu.yaml`` values: the worst (largest) axis of each sensor, SI units.

    Kalibr has one density per sensor, so the largest axis value is taken (the usual
    conservative choice); channels that were not fitted are skipped. A term that was not
    detected on an axis (absent from ``params_by_channel``, or zero) contributes its
    upper 95 % confidence limit from ``upper_limits`` instead, and the key is listed in
    ``upper_limits`` of the result: a zero random walk would make Kalibr and every VIO
    filter that reads the file trust the bias forever. ``not_detected`` / ``detected`` of
    the result map each such key to the axes that gave an upper limit / their estimate,
    and ``axis`` maps every key to the axis whose value was written.
    ``inflate`` multiplies every noise value (a safety factor for real-world use; recorded
    as ``inflate``).

    Kalibr needs all four densities: when no gyro or no accelerometer axis was fitted,
    :class:`FitError` names the missing keys (no placeholder values are made up).
    """
    check_kalibr_request(inflate, params_by_channel)
    limits = upper_limits or {}
    out: dict[str, Any] = {"rostopic": rostopic, "update_rate": float(rate_hz)}
    marked: list[str] = []
    not_detected: dict[str, list[str]] = {}
    detected: dict[str, list[str]] = {}
    axis: dict[str, str] = {}
    folded: dict[str, list[str]] = {}
    for key, (sensor, term) in KALIBR_TERMS.items():
        chans = GYRO if sensor == "gyro" else ACCEL
        scale = DEG if sensor == "gyro" else G0
        values: list[tuple[float, bool, str]] = []  # (value, is an upper limit, axis)
        for ch in chans:
            if ch not in params_by_channel:
                continue
            v = (kalibr_random_walk(params_by_channel[ch]) if term == "random_walk"
                 else term_value(params_by_channel[ch], term, rate_hz))
            if term == "random_walk" and v > term_value(params_by_channel[ch], term):
                folded.setdefault(key, []).append(ch)
            if v <= 0.0 and term in limits.get(ch, {}):
                values.append((float(limits[ch][term]), True, ch))
            else:
                values.append((v, False, ch))
        worst, limited, worst_ch = max(values)
        if worst <= 0.0:
            raise FitError(f"Kalibr {key}: no axis has a value or an upper limit for "
                           f"{term}; refusing to write zero")
        out[key] = worst * scale * inflate
        axis[key] = worst_ch
        if limited:
            marked.append(key)
            not_detected[key] = [ch for _, lim, ch in values if lim]
            detected[key] = [ch for _, lim, ch in values if not lim]
    out["upper_limits"] = marked
    out["not_detected"] = not_detected
    out["detected"] = detected
    out["axis"] = axis
    out["markov_folded"] = folded
    out["inflate"] = float(inflate)
    return out


def kalibr_yaml(values: Mapping[str, Any]) -> str:
    """The ``imu.yaml`` text (flat YAML, one key per line, units in comments; a value that
    is an upper confidence limit says so on its line and in the header)."""
    units = {
        "accelerometer_noise_density": "m/s^2/sqrt(Hz)",
        "accelerometer_random_walk": "m/s^3/sqrt(Hz)",
        "gyroscope_noise_density": "rad/s/sqrt(Hz)",
        "gyroscope_random_walk": "rad/s^2/sqrt(Hz)",
        "update_rate": "Hz",
    }
    limits = list(values.get("upper_limits", []))
    inflate = float(values.get("inflate", 1.0))
    lines = ["# Kalibr IMU noise parameters written by imubench fit (continuous time, SI)"]
    if inflate != 1.0:
        lines.append(f"# imubench: every noise value multiplied by {inflate:g} "
                     "(--kalibr-inflate)")
    if limits:
        lines.append("# imubench: below detection, written as the upper 95 % confidence "
                     f"limit (never zero): {', '.join(limits)}")
    for key, chans in dict(values.get("markov_folded", {})).items():
        lines.append(f"# imubench: {key} holds the Gauss-Markov term of {', '.join(chans)} "
                     "(Kalibr's model has none) as sigma sqrt(2 / tau_c), the random walk "
                     "it is over times short against tau_c, which bounds its spectrum")
    for key in ("rostopic", "update_rate", "accelerometer_noise_density",
                "accelerometer_random_walk", "gyroscope_noise_density", "gyroscope_random_walk"):
        if key not in values:
            continue
        v = values[key]
        text = v if isinstance(v, str) else f"{float(v):.6e}"
        note = f"  # {units[key]}" if key in units else ""
        if key in limits:
            note += ", upper 95 % limit: not detected"
        lines.append(f"{key}: {text}{note}")
    return "\n".join(lines) + "\n"


def kalibr_limit_message(path: object, values: Mapping[str, Any], key: str) -> str:
    """The one-line stderr note for a Kalibr key written as an upper confidence limit:
    the axes that did not detect the term, those that did, and that the value written is
    the largest over the axes (estimates where detected, upper limits elsewhere), in
    Kalibr's unit."""
    term = KALIBR_TERMS[key][1]
    missed = list(values.get("not_detected", {}).get(key, []))
    detected = list(values.get("detected", {}).get(key, []))
    axis = values.get("axis", {}).get(key, "?")
    where = f"on {', '.join(missed) or '?'}"
    if detected:
        where += f" (detected on {', '.join(detected)})"
    return (f"imubench fit: {path}: {key} ({term}) was not detected {where}; wrote the "
            f"largest value over the axes, the upper 95 % confidence limit of {axis}: "
            f"{float(values[key]):.3e} {KALIBR_UNITS[key]} (marked in the file), not zero")


def datasheet_comparison(chip: str | None,
                         params_by_channel: Mapping[str, Mapping[str, float]],
                         rate_hz: float | None = None) -> dict[str, dict[str, Any]]:
    """Fitted white-equivalent density vs the chip's datasheet-typical one (``datasheet:<chip>``).

    Returns ``{channel: {"fitted": N, "typical": N_typ, "ratio": N / N_typ, "unit": the
    unit of N and N_typ}}``; empty when
    the chip is unknown or has no shipped model. The typicals are those of the shipped
    files (marked unverified there). ``rate_hz``: the fitted record's sample rate (as in
    :func:`white_equivalent`).
    """
    from lsm6ds_sim.model import DATASHEET_PREFIX, datasheet_chips, load_model

    if not chip or chip.lower() not in datasheet_chips():
        return {}
    typical = load_model(DATASHEET_PREFIX + chip)
    out: dict[str, dict[str, Any]] = {}
    for ch, p in params_by_channel.items():
        n_typ = white_equivalent(typical[ch].to_dict())
        n = white_equivalent(p, rate_hz)
        if n_typ > 0:
            out[ch] = {"fitted": n, "typical": n_typ, "ratio": n / n_typ,
                       "unit": param_units(ch)["white"]}
    return out


__all__ = [
    "ACCEL_QUANTITIES",
    "G0",
    "GYRO_QUANTITIES",
    "KALIBR_UNITS",
    "SHORT_MARKOV_S",
    "WHITE_EQUIVALENT",
    "Quantity",
    "check_kalibr_request",
    "datasheet_comparison",
    "datasheet_units",
    "kalibr_imu",
    "kalibr_limit_message",
    "kalibr_yaml",
    "param_units",
    "quantities",
    "resonance_floor",
    "term_value",
    "white_equivalent",
    "white_equivalent_interval",
    "white_equivalent_weights",
]
