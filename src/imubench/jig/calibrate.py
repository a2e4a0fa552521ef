"""The board's calibration from the run's captures (:mod:`imubench.jig.procedures`):
six-position accelerometer fit (12 parameters, and 15 with the quadratic term),
rate-table gyro fit, offset-versus-temperature fits of both sensors over the sweep (the
note's three points, the exact quadratic through them, the least-squares polynomial),
and the :class:`~imubench.calibration.Calibration` file built from them.

The temperature reference ``T_ref`` is the die temperature during the six-position and
rate-table captures (ambient); the sweep's fits are taken about it, so the file's
temperature terms correct towards the conditions the offsets and matrices were measured
in.

Weights. The captures of one procedure have equal durations and see the same sensor
noise, so the standard errors of their means are pooled per axis (root mean square over
the captures) before the least squares: each capture's own standard error rests on few
degrees of freedom (an Allan deviation at a quarter of the capture), and weighting by it
would make the estimate follow that estimation noise (measured: 20-35 % more scatter in
the recovered parameters than with the pooled weights). The fits' chi-squared then checks
the shared-noise assumption.
"""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import dataclass, field, replace

import numpy as np

from imubench import __version__, stats
from imubench.batch import CHANNELS
from imubench.calibration import temperature as tcal
from imubench.calibration.accel import six_position
from imubench.calibration.file import Calibration, SensorCalibration
from imubench.calibration.gyro import rate_table
from imubench.calibration.sensor import AXES, SensorFit
from imubench.jig.procedures import Point, Procedures, TemperaturePoint
from imubench.jig.station import CalibrationSection, TiltSection
from imubench.tilt.budget import AxisErrors, ErrorBudget, budget_from_states, multiplier_for

GYRO = slice(0, 3)
ACCEL = slice(3, 6)
SENSOR_COLS = {"gyro": GYRO, "accel": ACCEL}


def pooled(stderr: np.ndarray) -> np.ndarray:
    """(k, m) standard errors replaced by their root mean square per column (axis)."""
    se = np.asarray(stderr, dtype=np.float64)
    return np.broadcast_to(np.sqrt(np.mean(se**2, axis=0)), se.shape).copy()


def bias_wander(static: Point, cols: slice, spacing_s: float) -> np.ndarray:
    """(3,) variance (unit^2) the bias's wander (flicker, random walk) adds to each mean of
    a sequence of captures ``spacing_s`` apart: the static capture's Allan variance at that
    spacing less its white part (the variance at one sample, times tau0 / tau). AVAR(tau)
    is half the mean square difference of adjacent tau-averages (NIST SP 1065 eq. 5), so
    each capture's departure from a constant bias has about that variance.

    The capture means' own errors hold the noise within a capture only; without the
    wander between the sequential six positions the 15-parameter fit's chi2/dof exceeded
    its 99.9 % limit on a healthy datasheet-typical board (seed 12: 6.05 against 5.42) and
    4 of 13 boards exceeded the 95 % point."""
    cap = static.capture
    m_max = (len(cap) - 1) // 4
    out = np.zeros(3)
    for k, ch in enumerate(CHANNELS[cols]):
        y = cap.channel(ch)
        m = min(max(2, round(spacing_s * cap.odr_hz)), m_max)
        if m < 2 or not float(np.ptp(y[np.isfinite(y)])) > 0:
            continue
        res = stats.oadev(y, cap.odr_hz, data_type="freq", afs=[1, m])
        if len(res.dev) == 2 and np.all(np.isfinite(res.dev)):
            out[k] = max(0.0, float(res.dev[1]) ** 2 - float(res.dev[0]) ** 2 / m)
    return out


def accel_fits(proc: Procedures) -> tuple[SensorFit, SensorFit]:
    """(12-parameter fit, 15-parameter fit with the quadratic term) of the six positions,
    each mean's error with the bias wander between the positions (:func:`bias_wander`)."""
    six = proc.six_position()
    wander = bias_wander(proc.static(), ACCEL, proc.cfg.position_s + proc.cfg.settle_s)
    faces = [p.label.split()[1] for p in six]
    means = np.array([p.mean(ACCEL) for p in six])
    se = np.sqrt(pooled(np.array([p.stderr(ACCEL) for p in six])) ** 2 + wander)
    return (six_position(faces, means, se, quadratic=False),
            six_position(faces, means, se, quadratic=True))


def gyro_fit(proc: Procedures, quadratic: bool) -> SensorFit:
    """The rate-table fit, each mean's error with the bias wander between the sequential
    rate captures (:func:`bias_wander`; without it the sensitivity's 95 % intervals
    covered the truth in 64 of 72 simulated channel fits)."""
    rates = proc.rate_table()
    wander = bias_wander(proc.static(), GYRO, proc.cfg.rate_s + proc.cfg.settle_s)
    inputs = np.array([p.rate_dps for _, _, p in rates])
    means = np.array([p.mean(GYRO) for _, _, p in rates])
    se = np.sqrt(pooled(np.array([p.stderr(GYRO) for _, _, p in rates])) ** 2 + wander)
    return rate_table(inputs, means, se, quadratic=quadratic)


@dataclass(frozen=True)
class SweepData:
    """Offsets of one sensor over the sweep."""

    temps_c: np.ndarray
    offsets: np.ndarray
    stderr: np.ndarray
    fits: dict[str, tcal.TemperatureFit] = field(default_factory=dict)


def _drift_measured(sweep: list[TemperaturePoint]) -> bool:
    """Whether the polynomial can take a drift term: the sweep revisits a set point (which
    measures the drift) and keeps a degree of freedom beside the four parameters."""
    sets = [p.set_point_c for p in sweep]
    return len(set(sets)) < len(sets) and len(sweep) >= 5


def temperature_fits(proc: Procedures, cols: slice) -> SweepData:
    """The sweep's offsets of one sensor and the three temperature fits about the static
    capture's die temperature. Each offset's error holds the bias wander between the
    sweep's points (:func:`bias_wander` at their spacing, which the static capture can
    only measure up to a quarter of its length: a flicker floor, flat beyond; the random
    walk's part is what the polynomial's drift term takes)."""
    sweep, cfg = proc.temperature_sweep(), proc.cfg
    static = proc.static()
    temps = np.array([p.die_temp_c for p in sweep])
    off = np.array([p.offsets(cols)[0] for p in sweep])
    times = np.array([p.time_s for p in sweep])
    spacing = float(np.median(np.diff(times))) if len(sweep) > 1 else 0.0
    se = np.sqrt(pooled(np.array([p.offsets(cols)[1] for p in sweep])) ** 2
                 + bias_wander(static, cols, spacing))
    # the three-point procedures use the sweep points at the ambient, hot and cold set
    # points (by set point, then their measured die temperatures)
    by_set: dict[float, int] = {}
    for i, p in enumerate(sweep):
        by_set.setdefault(p.set_point_c, i)  # the first visit of a repeated set point
    idx = [by_set[cfg.ambient_c], by_set[cfg.hot_c], by_set[cfg.cold_c]]
    t3, y3 = temps[idx], off[idx]
    fits = {
        "three-point-note": tcal.three_point_note(t3, y3, t3[0], t3[1], t3[2]),
        "three-point-exact": tcal.three_point_exact(t3, y3, t3[0], t3[1], t3[2]),
        "polynomial": tcal.polynomial(temps, off, se, static.die_temp_c, degree=2,
                                      times_s=times if _drift_measured(sweep) else None),
    }
    return SweepData(temps, off, se, fits)


def sensor_calibration(unit: str, fit: SensorFit, method: str, temp_ref_c: float,
                       sweep: SweepData | None, temp_method: str,
                       full_scale: float | None = None) -> SensorCalibration:
    """One sensor's table of the calibration file; ``full_scale`` (unit) is the range it
    was made at, and the sweep's die temperatures bound where its temperature terms
    hold (``temp_range_c``)."""
    residuals: dict[str, object] = {
        "fit_inputs": fit.inputs.tolist(),
        "fit_residuals": fit.residuals.tolist(),
    }
    c1 = c2 = np.zeros(3)
    if sweep is not None:
        tf = sweep.fits[temp_method]
        # re-centre the chosen fit on T_ref: b(T) = c0 + c1 d + c2 d^2 about its own
        # reference; expand about temp_ref_c
        shift = temp_ref_c - tf.temp_ref_c
        c1 = tf.coeff1 + 2.0 * tf.coeff2 * shift
        c2 = tf.coeff2
        residuals["sweep_temps_c"] = sweep.temps_c.tolist()
        for name, f in sweep.fits.items():
            residuals[f"sweep_{name}"] = f.residuals(sweep.temps_c, sweep.offsets).tolist()
    span = (None if sweep is None
            else (float(np.min(sweep.temps_c)), float(np.max(sweep.temps_c))))
    return SensorCalibration(unit=unit, method=method, temp_ref_c=temp_ref_c,
                             offset=fit.offset, matrix=fit.matrix,
                             nonlinearity=fit.nonlinearity,
                             temp_method=temp_method if sweep is not None else "",
                             temp_coeff1=c1, temp_coeff2=c2, residuals=residuals,
                             full_scale=full_scale or 0.0, temp_range_c=span)


def provenance(serial: str, station: str, chip: str, uri: str, run_id: str) -> dict[str, str]:
    return {
        "serial": serial,
        "date_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "station": station,
        "chip": chip,
        "software": f"imubench {__version__}",
        "source_uri": uri,
        "run_id": run_id,
    }


@dataclass(frozen=True)
class BoardFits:
    """Every fit of one board: accelerometer (12 and 15 parameters), gyro, and the
    temperature fits of both sensors (None without a sweep)."""

    accel_linear: SensorFit
    accel: SensorFit
    gyro: SensorFit
    temp_ref_c: float
    sweep: dict[str, SweepData] | None


def fit_board(proc: Procedures, cal: CalibrationSection, *, sweep: bool = True) -> BoardFits:
    """Take (or reuse) the captures and fit everything (see the module docstring)."""
    temp_ref = proc.static().die_temp_c
    linear, quad = accel_fits(proc)
    gyro = gyro_fit(proc, cal.nonlinearity)
    sweeps = None
    if sweep:
        sweeps = {name: temperature_fits(proc, cols) for name, cols in SENSOR_COLS.items()}
    return BoardFits(linear, quad if cal.nonlinearity else linear, gyro, temp_ref, sweeps)


def build_calibration(fits: BoardFits, cal: CalibrationSection,
                      prov: dict[str, str], fs_dps: float | None = None,
                      fs_g: float | None = None) -> Calibration:
    """The calibration file's content from the fits (``cal.temperature_method`` chooses
    the temperature fit), made at the full scales ``fs_dps`` and ``fs_g``."""
    method = cal.temperature_method
    tail = " + quadratic" if cal.nonlinearity else ""
    sw = fits.sweep
    return Calibration(
        prov,
        gyro=sensor_calibration("dps", fits.gyro, "rate-table least squares (offset, scale,"
                                f" cross-axis{tail})", fits.temp_ref_c,
                                None if sw is None else sw["gyro"], method, fs_dps),
        accel=sensor_calibration("g", fits.accel, "six-position least squares (offset, gain,"
                                 f" cross-axis{tail})", fits.temp_ref_c,
                                 None if sw is None else sw["accel"], method, fs_g),
    )


__all__ = ["ACCEL", "GYRO", "SENSOR_COLS", "BoardFits", "SweepData", "accel_fits",
           "build_calibration", "fit_board", "gyro_fit", "provenance", "sensor_calibration",
           "temperature_fits", "tilt_budget"]


def tilt_budget(fits: BoardFits, noise_density_g: float, odr_hz: float,
                zero_g_stderr_g: float, tilt: TiltSection, cal: CalibrationSection,
                title: str) -> ErrorBudget:
    """The tilt error budget of one accelerometer axis of this board, before and after
    each calibration step, from its own fits (``calibration.md``, "Error budget"):

    * before: gain and cross-axis error ``|M_ii - 1| + sum |M_ij|``, offset ``|b_i|``,
      nonlinearity ``|q_i|`` (x range used), offset change over the sweep
      ``max |b(T) - b(T_ref)|``;
    * after the one-point offset: offset to 3 SE of a level capture;
    * after the +-1 g flip: gain to 3 SE, offset to ``|q_i|`` + 3 SE (the flip takes the
      nonlinearity for offset); cross-axis unchanged;
    * after six positions (with the quadratic term): every static term to 3 SE of its fit;
    * after the temperature calibration: the offset change to the largest residual of
      the station's temperature fit over the sweep.

    Noise: the ``average_samples`` mean, ``N / sqrt(n / odr)``, times the multiplier for
    the station's mission (``tilt.uses``, ``tilt.expected_exceedances``).
    """
    i = AXES.index(tilt.axis)
    f = fits.accel
    se_scale = f.stderr_of("scale_error")[i]
    se_cross = sum(f.fits[i].stderr[j] for j in range(3) if j != i)
    cross = sum(abs(f.matrix[i, j]) for j in range(3) if j != i)
    q = abs(f.nonlinearity[i])
    se_q = f.stderr_of("nonlinearity")[i] if f.quadratic else q
    sigma = noise_density_g / math.sqrt(tilt.average_samples / odr_hz)
    temp_before = temp_after = 0.0
    if fits.sweep is not None:
        sw = fits.sweep["accel"]
        ref = sw.fits["polynomial"].model(np.array([fits.temp_ref_c]))[0, i]
        temp_before = float(np.max(np.abs(sw.offsets[:, i] - ref)))
        temp_after = float(np.max(np.abs(
            sw.fits[cal.temperature_method].residuals(sw.temps_c, sw.offsets)[:, i])))
    before = AxisErrors(abs(f.matrix[i, i] - 1.0) + cross, abs(f.offset[i]), q,
                        temp_before, sigma)
    one_point = replace(before, offset_g=3.0 * zero_g_stderr_g)
    flip = replace(one_point, sensitivity_error=3.0 * se_scale + cross,
                   offset_g=q + 3.0 * zero_g_stderr_g)
    six = replace(flip, sensitivity_error=3.0 * (se_scale + se_cross),
                  offset_g=3.0 * f.stderr_of("offset")[i], nonlinearity=3.0 * se_q)
    states = [("before", before), ("one-point offset", one_point), ("+-1 g flip", flip),
              ("six positions", six)]
    if fits.sweep is not None:
        states.append(("temperature", replace(six, offset_change_g=temp_after)))
    k = multiplier_for(tilt.uses, tilt.expected_exceedances)
    return budget_from_states(
        title, states, tilt.range_used_g, k, (tilt.uses, tilt.expected_exceedances),
        notes=(f"axis a{tilt.axis}, range used {tilt.range_used_g:g} g, readings of"
               f" {tilt.average_samples} samples at {odr_hz:g} Hz; each column includes the"
               " steps before it; residuals are 3 standard errors of the fits",))
