"""Measurements from captures, each with its confidence interval and how it was found.

Every function returns a :class:`Value` (value, ``(ci_low, ci_high)``, method text) in
the unit of the limits file. Conventions (IEEE Std 952-1997 Annex C; NIST SP 1065):

* noise density ``N``: the white term of a white + flicker + random-walk GLS fit of the
  overlapping Allan variance (``imubench.noisefit``) at octave taus from ``tau_N`` = 0.1 s
  (long enough to stay above an output low-pass), with the fit's interval; a single
  reading of the deviation takes in the flicker and random walk there;
* angle random walk: ``60 N`` in deg/sqrt(h) (the -1/2 line read at 1 s is N);
* bias instability ``B = min sigma / 0.664`` (flicker floor ``sqrt(2 ln2 / pi) B``).
  The minimum is a floor only when the curve rises significantly after it (a later
  point's lower confidence limit above the minimum); otherwise (the minimum at or near
  the longest averaging time of the capture, the curve still falling or flat within
  its noise) the capture only bounds ``B`` from above (white and random-walk noise add
  to the minimum, never subtract) and the interval is ``[0, upper limit]``: a short
  capture gives INCONCLUSIVE against a limit it cannot resolve, never a silent pass;
* levels (zero-rate level, zero-g offset, temperature): the capture mean with the
  Student-t interval of :func:`imubench.calibration.means.capture_mean`;
* self-test deflection: ``|on - off|`` of ``n`` averaged samples each; its standard
  deviation ``sqrt(2 / n) sqrt(N_typ^2 f_s + LSB^2 / 12)`` from the datasheet-typical
  noise density at the self-test ODR ``f_s`` (the driver's procedure keeps no samples to
  estimate it from), normal quantile.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import norm
from scipy.stats import t as student_t

from imubench import stats
from imubench.batch import CHANNELS
from imubench.calibration.means import MeanEstimate
from imubench.jig.dut import Capture
from imubench.noisefit import FitError, fit_channel
from imubench.stats.result import StatResult

TAU_NOISE_DENSITY_S = 0.1
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)
"""ADEV of flicker noise of coefficient B is 0.664 B (IEEE 952 C.3)."""
SCALE = {
    "gyro_density": 1e3,  # dps/sqrt(Hz) -> mdps/sqrt(Hz)
    "accel_density": 1e6,  # g/sqrt(Hz) -> ug/sqrt(Hz)
    "gyro_bias": 3600.0,  # dps -> deg/h
    "accel_bias": 1e6,  # g -> ug
}


@dataclass(frozen=True)
class Value:
    value: float
    ci: tuple[float, float]
    method: str

    def scaled(self, k: float) -> Value:
        lo, hi = sorted((self.ci[0] * k, self.ci[1] * k))
        return Value(self.value * k, (lo, hi), self.method)


def oadev(y: np.ndarray, rate_hz: float, confidence: float,
          taus: str | list[float] = "octave") -> StatResult:
    return stats.oadev(y, rate_hz, data_type="freq", taus=taus, confidence=confidence)


def _at(y: np.ndarray, rate_hz: float, tau_s: float, confidence: float,
        lsb: float) -> tuple[float, float, float, float, str]:
    """(tau, OADEV, CI low, CI high, how) at the averaging factor nearest ``tau_s``. An
    output that never changes has OADEV 0; its noise is then bounded by what would have
    moved it: white noise below half an LSB per sample, ``OADEV(tau) < (LSB / 2) /
    sqrt(rate tau)`` (an upper limit, not a chi-squared interval)."""
    m = max(1, round(tau_s * rate_hz))
    tau = m / rate_hz
    finite = y[np.isfinite(y)]
    if len(finite) and float(np.ptp(finite)) == 0.0:
        bound = 0.5 * lsb / math.sqrt(rate_hz * tau)
        return tau, 0.0, 0.0, bound, "constant output: OADEV 0, bounded by half an LSB"
    res = stats.oadev(y, rate_hz, data_type="freq", afs=[m], confidence=confidence)
    return (float(res.tau_s[0]), float(res.dev[0]), float(res.ci_low[0]),
            float(res.ci_high[0]), f"chi-squared {confidence:.0%} CI")


def noise_density(cap: Capture, ch: str, confidence: float) -> Value:
    """White-noise density N (unit/sqrt(Hz)) of channel ``ch`` (module docstring): the
    white term of a GLS fit of white, flicker and random walk (:mod:`imubench.noisefit`;
    IEEE 952 C: ``AVAR = N^2 / tau + (2 ln2 / pi) B^2 + K^2 tau / 3``) to the OAVAR at
    octave taus from ``TAU_NOISE_DENSITY_S`` (above an output low-pass), with the fit's
    95 % interval rescaled to ``confidence``. The deviation read at one tau takes in the
    other terms: a board with flicker B = 0.006 dps read N up to 9 % high at 0.1 s and its
    ARW (then OADEV(1 s) x 60) 30-60 % high, outside every interval."""
    y = cap.channel(ch)
    lsb = float(cap.lsb[CHANNELS.index(ch)])
    finite = y[np.isfinite(y)]
    if len(finite) and float(np.ptp(finite)) == 0.0:
        tau, dev, lo, hi, how = _at(y, cap.odr_hz, TAU_NOISE_DENSITY_S, confidence, lsb)
        r = math.sqrt(tau)
        return Value(dev * r, (lo * r, hi * r), f"OADEV at tau = {tau:.3g} s x sqrt(tau), {how}")
    m0 = max(1, round(TAU_NOISE_DENSITY_S * cap.odr_hz))
    afs = [m0 * 2**k for k in range(64) if m0 * 2**k <= (len(y) - 1) // 4]
    terms = "white,flicker,random_walk" if len(afs) >= 5 else "white"
    try:
        fit = fit_channel(y, cap.odr_hz, terms=terms, channel=ch,
                          taus=[m / cap.odr_hz for m in afs])
    except FitError as exc:
        return Value(math.nan, (math.nan, math.nan), f"no fit: {exc}")
    value, ci = fit.coefficient("white")
    if ci is None:
        return Value(value, (math.nan, math.nan), "white term without an interval")
    k = float(norm.ppf(0.5 + confidence / 2.0) / norm.ppf(0.975))
    lo, hi = value - k * (value - ci[0]), value + k * (ci[1] - value)
    return Value(value, (max(lo, 0.0), hi),
                 f"white term of a {terms.replace(',', ' + ')} GLS fit of the OAVAR at "
                 f"{len(afs)} octave taus from {afs[0] / cap.odr_hz:.3g} s; "
                 f"{confidence:.0%} interval")


def angle_random_walk(density: Value) -> Value:
    """ARW (deg/sqrt(h)) from a gyro channel's white density N in dps/sqrt(Hz)
    (:func:`noise_density`): 60 N (IEEE 952: the -1/2 line read at 1 s, which is N, not
    the curve's value there)."""
    v = density.scaled(60.0)
    return Value(v.value, v.ci, v.method + "; x 60 (deg/sqrt(h) per dps/sqrt(Hz))")


def bias_instability(res: StatResult) -> tuple[Value, bool]:
    """(B in the data's unit, resolved): see the module docstring."""
    dev = np.asarray(res.dev, float)
    ok = np.isfinite(dev) & (dev > 0)
    if not ok.any():
        return Value(0.0, (0.0, 0.0), "no Allan deviation (constant output)"), True
    k = int(np.nanargmin(np.where(ok, dev, np.inf)))
    b = dev[k] / FLICKER_FLOOR
    hi = res.ci_high[k] / FLICKER_FLOOR
    later_low = np.asarray(res.ci_low, float)[k + 1 :][ok[k + 1 :]]
    if not np.any(later_low > dev[k]):
        return Value(b, (0.0, float(hi)),
                     f"min OADEV / 0.664 at tau = {res.tau_s[k]:.3g} s, floor not resolved"
                     " (no significant rise after the minimum): interval [0, upper limit]"), False
    return Value(b, (float(res.ci_low[k] / FLICKER_FLOOR), float(hi)),
                 f"min OADEV / 0.664 at tau = {res.tau_s[k]:.3g} s (the curve rises"
                 " significantly after it), chi-squared CI"), True


def mean_value(m: MeanEstimate, confidence: float) -> Value:
    lo, hi = m.ci(confidence)
    return Value(m.mean, (lo, hi), f"mean of {m.n} samples, SE from OADEV (EDF"
                 f" {m.edf:.3g}), Student-t {confidence:.0%} CI")


def self_test_value(deflection: float, density_typ: float, odr_hz: float, lsb: float,
                    n: int, confidence: float) -> Value:
    sigma = math.sqrt(2.0 / n) * math.sqrt(density_typ**2 * odr_hz + lsb**2 / 12.0)
    z = float(norm.ppf(0.5 + confidence / 2.0))
    return Value(deflection, (deflection - z * sigma, deflection + z * sigma),
                 f"|on - off| of {n}-sample means; sigma {sigma:.3g} from the typical noise"
                 f" density at {odr_hz:g} Hz")


def with_extra_uncertainty(v: Value, half_width_uniform: float, confidence: float) -> Value:
    """Widen ``v`` by an independent error uniform in ``+-half_width_uniform`` (e.g. a
    chamber's accuracy), combining standard uncertainties in quadrature."""
    z = float(norm.ppf(0.5 + confidence / 2.0))
    s0 = (v.ci[1] - v.ci[0]) / (2.0 * z)
    s = math.sqrt(s0**2 + half_width_uniform**2 / 3.0)
    return Value(v.value, (v.value - z * s, v.value + z * s),
                 v.method + f"; +-{half_width_uniform:g} uniform added")


def interval_from_stderr(value: float, stderr: float, confidence: float, method: str,
                         dof: float = math.inf) -> Value:
    """``value +- q stderr``: ``q`` the normal quantile, or Student's t quantile with
    ``dof`` degrees of freedom where the standard error was estimated from ``dof``
    residuals."""
    q = float(norm.ppf(0.5 + confidence / 2.0) if math.isinf(dof)
              else student_t.ppf(0.5 + confidence / 2.0, dof))
    return Value(value, (value - q * stderr, value + q * stderr), method)


__all__ = ["FLICKER_FLOOR", "SCALE", "TAU_NOISE_DENSITY_S", "Value",
           "angle_random_walk", "bias_instability", "interval_from_stderr", "mean_value",
           "noise_density", "oadev", "self_test_value", "with_extra_uncertainty"]
