"""Standard errors of a kept effect's parameters: a parametric bootstrap.

The model with every kept effect is the best description of the record there is; its K
realisations (the run's seeds) are K records that this model could have produced. Each
kept effect's estimator, the one that fitted it to the real record, is applied again to
each realisation, against the same reference it was fitted against (the realisations of
the model it was added to), and the standard deviation of the K estimates is the
parameter's standard error (Efron & Tibshirani, An Introduction to the Bootstrap, 1993,
ch. 6, "the parametric bootstrap"). It holds the noise of the record, of the other
effects and of the estimator itself; it does not hold the choice of WHICH effects were
kept (an effect kept because its estimate came out large is biased high by that
selection, and the error does not show it). With K realisations the standard error is
itself uncertain by about 1 / sqrt(2 (K - 1)) (24 % at K = 10). The refits' mean less
the value is the estimator's bootstrap bias on the fitted model (Efron & Tibshirani
1993, sec. 10.2), reported beside the error.

Each effect's estimator, as in :func:`imubench.gap.candidates.fit_candidates`:

* ``flicker``, ``random_walk``, ``quantization``: the added term's 1-D fit to the Allan
  curve (:func:`imubench.gap.avarfit.fit_single`), the total ``sqrt(p0^2 + p^2)``;
* ``markov``, ``telegraph``: the Gauss-Markov fit (:func:`imubench.gap.avarfit.
  fit_markov`; the telegraph's step and dwell are twice its sigma and tau_c);
* ``base_model``: none. The refit picks the closest member of a family of filter
  shapes (:func:`imubench.gap.avarfit.fit_base_model`), and the realisations of that
  member scatter far less than the shape's own error: on the blind set's 2nd-order
  Butterworth filters the bandwidth's bootstrap error was 0.2-0.5 % against errors of
  6-24 % (13 to 52 standard errors);
* ``ramp``: the least-squares slope of the block means against time;
* ``temperature``: the coefficient from the estimator that gave it (the GLS slope of the
  block-mean increments, or least squares of the block-mean levels, linear or quadratic),
  over the fit part, or over the whole realisation less the other kept effects'
  deterministic parts for a response fitted on the whole record
  (:attr:`imubench.gap.candidates.Candidate.whole_record`);
* ``sine``: the zero-padded periodogram's frequency and the least-squares amplitude
  (:func:`imubench.gap.evidence.fit_sine`);
* ``resonance``: the Lorentzian fit to the spectral excess
  (:func:`imubench.gap.evidence.fit_resonance`);
* ``outliers``: the truncated-normal tail fit (:func:`imubench.gap.evidence.fit_outliers`);
* ``bias_step``: the change point and the local size (:func:`imubench.gap.evidence.
  fit_bias_step`) on the whole realisation less the other kept effects' deterministic
  parts. The change point's error is at least its asymptotic one (:func:`step_time_floor`):
  the least-squares change point scatters with heavy tails, and the standard deviation of
  10 refits fell below it (an outside reviewer: 180.135 +- 0.030 s for a step at 180.000
  s, where the floor is 0.14 s).

An estimator that finds nothing on a realisation (no resonance peak, fewer than three
impulses) leaves that realisation out (counted in :attr:`Bootstrap.n`); with fewer than
MIN_REFITS left the error and the bias are NaN (reported as null).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from lsm6ds_sim.model import ChannelModel

from imubench.gap import avarfit, evidence
from imubench.gap.candidates import SLOW_TERMS, Candidate, filter_power_gain, slow_terms_scale
from imubench.gap.curves import SimFeatures, gls_slopes, line_segment
from imubench.gap.parts import PartSetup, RecordTemperature
from imubench.noisefit.spectral_line import SCAN_LOW_FRACTION

MIN_REFITS = 5
"""Fewest realisations on which the estimator must find the effect for a standard error."""


@dataclass(frozen=True)
class Refit:
    """What the bootstrap of one kept effect needs.

    ``final``: the fit part's features of the realisations of the model with every kept
    effect, each less the deterministic parts of the effects kept before this one (as
    the record was when it was fitted); ``reference``: those of the model the effect was
    added to (the effects kept before it, less their deterministic parts), with ``sigma``
    (ln ADEV, per tau) and ``cm`` (its channel model) as the fit of that step saw them;
    ``raw``: the final model's realisations over the whole record (k, n), each less the
    deterministic parts of the OTHER kept effects, made on demand (only the sine,
    outliers and bias-step estimators, and a temperature response fitted on the whole
    record, need samples); ``record_temp``: the whole-record temperature test under the
    covariance of ``cm``'s noise (its blocks, temperature and GLS factor), for a
    temperature response fitted on the whole record."""

    fit: PartSetup
    final: SimFeatures
    reference: SimFeatures
    sigma: np.ndarray
    cm: ChannelModel
    raw: Callable[[], np.ndarray]
    record_temp: RecordTemperature | None = None


@dataclass(frozen=True)
class Bootstrap:
    """The bootstrap of one kept effect, by parameter: ``se`` the standard error,
    ``bias`` the refits' mean less the value (Efron & Tibshirani 1993, sec. 10.2), ``n``
    the refits that gave an estimate (NaN error and bias below MIN_REFITS)."""

    se: dict[str, float]
    bias: dict[str, float]
    n: dict[str, int]


def standard_errors(c: Candidate, r: Refit) -> Bootstrap:
    """The standard error, bootstrap bias and refit count of each fitted parameter of
    ``c`` (the keys of ``c.params`` that its estimator fits; none for the base model's
    refit).

    The bias is what the estimator does on the fitted model, e.g. a random walk kept
    before a temperature response, refitted beside the response it took part of (an
    outside reviewer: K 4.52e-4 +- 0.49e-4 for 3e-4, refits averaging 5.41e-4)."""
    out = Bootstrap({}, {}, {})
    for key, values in _refits(c, r).items():
        v = np.asarray([x for x in values if math.isfinite(x)])
        ok = len(v) >= MIN_REFITS
        out.se[key] = float(np.std(v, ddof=1)) if ok else math.nan
        out.bias[key] = float(np.mean(v)) - c.params[key] if ok else math.nan
        out.n[key] = len(v)
    if c.effect == "bias_step" and math.isfinite(out.se.get("step_time_s", math.nan)):
        out.se["step_time_s"] = max(out.se["step_time_s"], step_time_floor(
            c.params["step_size"], r.raw(), r.fit.series.rate_hz))
    return out


STEP_TIME_VARIANCE = 26.0
"""Variance of ``argmax_u (W(u) - |u| / 2)``, W a two-sided standard Wiener process: the
limit law of the least-squares change point of a mean shift delta in white noise sigma,
in units of sigma^2 / delta^2 samples (Yao 1987, Ann. Statist. 15, 1321-1328; a Monte
Carlo of the limit process here gave 25.7). On finite white-noise records the change
point's standard deviation is 0.87-0.96 of the limit's at delta / sigma 0.4-1.0
(``tests/test_gap_uncertainty.py``), so the floor errs on the safe side."""


def step_time_floor(step_size: float, noise: np.ndarray, rate_hz: float) -> float:
    """Asymptotic standard error (s) of the change point of a step ``step_size`` in the
    noise of ``noise`` (K x n realisations, the record's model): ``sqrt(26) sigma^2 /
    delta^2`` samples, sigma the per-sample white noise (the median over the
    realisations of the robust standard deviation of first differences, over sqrt 2; the
    noise near a change point is that of a few to a few hundred samples, where white
    noise rules). For a step several sigma high the limit law overstates the error (the
    point is then found to the sample), and the floor is below a sample there."""
    if not step_size:
        return math.nan
    sigma2 = float(np.median([evidence.mad_sigma(d) ** 2 / 2.0
                              for d in np.diff(noise, axis=1)]))
    return math.sqrt(STEP_TIME_VARIANCE) * sigma2 / step_size**2 / rate_hz


def _refits(c: Candidate, r: Refit) -> dict[str, list[float]]:
    """Each parameter's estimate on each realisation of the final model."""
    fit, s = r.fit, r.fit.series
    ref_avar = r.reference.avar.mean(axis=0)
    eff = c.effect
    if eff in avarfit.BASES:
        p0 = float(getattr(r.cm, eff))
        return {eff: [math.hypot(p0, avarfit.fit_single(eff, fit.tau_s, a, ref_avar, r.sigma))
                      for a in r.final.avar]}
    if eff in ("markov", "telegraph"):
        fits = [avarfit.fit_markov(fit.tau_s, a, ref_avar, r.sigma) for a in r.final.avar]
        if eff == "markov":
            return {"markov_sigma": [f[0] for f in fits], "markov_tau": [f[1] for f in fits]}
        return {"telegraph_step": [2.0 * f[0] for f in fits],
                "telegraph_dwell_s": [2.0 * f[1] for f in fits]}
    if eff == "base_model":
        return {}
    if eff == "ramp":
        return {"ramp": list(r.final.trend_slope)}
    if eff == "temperature" and c.whole_record:
        return {**_temperature_on_record(c, r), **_slow_terms(c, r)}
    if eff == "temperature":
        return {**_temperature(c, fit, r.final, r.cm), **_slow_terms(c, r)}
    if eff == "resonance":
        ref_psd = r.reference.psd.mean(axis=0)
        g2 = c.output_gain2
        out: dict[str, list[float]] = {"resonance_freq_hz": [], "resonance_width_hz": [],
                                       "resonance_height": []}
        for p in r.final.psd:
            rf = evidence.fit_resonance(fit.f_hz, p, ref_psd, SCAN_LOW_FRACTION * s.rate_hz)
            if rf is not None:
                out["resonance_freq_hz"].append(rf.resonance_freq_hz)
                out["resonance_width_hz"].append(rf.resonance_width_hz)
                out["resonance_height"].append(rf.resonance_height / g2)
        return out
    n_fit = len(s.y)
    raw = r.raw()
    if eff == "sine":
        bin_hz = s.rate_hz / line_segment(n_fit)
        f0 = c.params["sine_freq"]
        sines = [evidence.fit_sine(y[:n_fit], s.rate_hz, f0, bin_hz) for y in raw]
        gain = math.sqrt(filter_power_gain(f0, r.cm, s.rate_hz))
        return {"sine_amplitude": [f.sine_amplitude / gain for f in sines],
                "sine_freq": [f.sine_freq for f in sines]}
    if eff == "outliers":
        false_hits = float(r.reference.impulses.mean())
        found = [evidence.fit_outliers(y[:n_fit], s.rate_hz, false_hits) for y in raw]
        return {"outlier_rate": [f.outlier_rate for f in found if f is not None],
                "outlier_amplitude": [f.outlier_amplitude for f in found if f is not None]}
    if eff == "bias_step":
        steps = [evidence.fit_bias_step(y, s.rate_hz) for y in raw]
        return {"step_time_s": [f.step_time_s for f in steps],
                "step_size": [f.step_size for f in steps]}
    raise ValueError(f"standard_errors: no estimator for the effect {eff!r}")


def _temperature(c: Candidate, fit: PartSetup, final: SimFeatures, cm: ChannelModel
                 ) -> dict[str, list[float]]:
    """The temperature coefficients of each realisation's block means (the blocks of
    :func:`imubench.gap.curves.temperature_blocks`), by the estimator that fitted ``c``:
    ``gls`` (:meth:`imubench.gap.parts.RecordTemperature.slopes`: increments, the
    covariance of the noise of ``cm``, the model the effect was added to), ``levels`` or
    ``levels_quadratic`` (least squares of the levels on dT, and dT^2, beside a
    constant, :func:`imubench.gap.evidence.fit_temperature`)."""
    yb, tb = final.temp_yb, fit.real.temp_tb
    fitted = ["temp_coeff"] + ["temp_coeff2"] * (c.estimator == "levels_quadratic")
    empty: dict[str, list[float]] = {k: [] for k in fitted}
    if yb is None or tb is None or yb.shape[1] != len(tb):
        return empty
    if c.estimator == "gls":
        temp = RecordTemperature(cm, fit.series)
        if temp.chol is None or temp.tb is None or len(temp.tb) != len(tb):
            return empty
        return {"temp_coeff": list(gls_slopes(np.diff(yb, axis=1), np.diff(tb),
                                              temp.chol)[0])}
    coef = evidence.temperature_levels(yb.T, tb, cm.temp_ref,
                                       quadratic=c.estimator == "levels_quadratic")
    out = {"temp_coeff": list(coef[1])}
    if c.estimator == "levels_quadratic":
        out["temp_coeff2"] = list(coef[2])
    return out


def _slow_terms(c: Candidate, r: Refit) -> dict[str, list[float]]:
    """The slow terms a temperature response took the place of
    (:attr:`Candidate.slow_scale` < 1), refitted on each realisation's fit part less its
    own GLS temperature response (:func:`imubench.gap.candidates.slow_terms_scale`);
    empty when it took none."""
    if c.slow_scale >= 1.0:
        return {}
    fit, s = r.fit, r.fit.series
    keys = [k for k in SLOW_TERMS if k in c.params]
    out: dict[str, list[float]] = {k: [] for k in keys}
    temp = np.asarray(s.temp_c)
    ys = r.raw()[:, :len(s.y)]
    ref_avar = r.reference.avar.mean(axis=0)
    for y, b in zip(ys, RecordTemperature(r.cm, s).slopes(ys), strict=True):
        added = b - r.cm.temp_coeff  # the real record's fit took out the added slope
        sc = (slow_terms_scale(r.cm, fit, y - added * temp, ref_avar, r.sigma)
              if math.isfinite(b) else None)
        if sc is None:
            continue
        for k in keys:
            out[k].append(sc * float(getattr(r.cm, k)))
    return out


def _temperature_on_record(c: Candidate, r: Refit) -> dict[str, list[float]]:
    """The temperature coefficients of each whole realisation (less the other kept
    effects' deterministic parts), by the estimator that fitted ``c`` on the whole record:
    the GLS slope of the block-mean increments under the covariance of ``r.cm``'s noise
    (:meth:`imubench.gap.parts.RecordTemperature.slopes`), or the least squares of the
    block-mean levels (:func:`imubench.gap.evidence.fit_temperature`)."""
    fitted = ["temp_coeff"] + ["temp_coeff2"] * (c.estimator == "levels_quadratic")
    temp = r.record_temp
    if temp is None or temp.temp_c is None:
        return {k: [] for k in fitted}
    raw = r.raw()
    if c.estimator == "gls":
        return {"temp_coeff": list(temp.slopes(raw))}
    fits = [evidence.fit_temperature(y, temp.temp_c, temp.rate_hz, r.cm.temp_ref)
            for y in raw]
    out = {"temp_coeff": [math.nan if f is None else (
        f.temp_coeff if c.estimator == "levels_quadratic" else f.temp_coeff_linear)
        for f in fits]}
    if c.estimator == "levels_quadratic":
        out["temp_coeff2"] = [math.nan if f is None else f.temp_coeff2 for f in fits]
    return out
