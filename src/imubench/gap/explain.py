"""Plain-language reasons behind a channel's verdict, from its JSON result.

``explain_channel(c, realisations)`` turns one ``channels[<ch>]`` entry of ``imubench gap``
into sentences a user can check against the plots: what fired on the fit part and how far
above its threshold, why the verdict is what it is (the share of the excess chi-squared
the best candidate removes against :data:`~imubench.gap.diagnose.MIN_CLOSURE`, and its
score against the runner-up's), how the issue's gap splits into the scatter a perfect
model would also show and the systematic part, and what the held-out part and the
replicates say. It reads only the JSON keys, so it explains a saved result as well.

The first sentence is in plain words (:func:`headline`): what the sensor does that the
model does not, its size, and how much of the gap modelling it closes on the held-out
part; the numbers behind it follow.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, NamedTuple

from scipy.stats import chi2 as chi2_dist
from scipy.stats import t as student_t

from imubench.gap.candidates import DENSE_TAIL, MARKOV_NO_TURNOVER, SLOW_TERMS
from imubench.gap.curves import (
    POOLED_DOF,
    POOLED_STATS,
    STAT_TESTS,
    Z_SLOPE,
    stat_dof,
    stat_fired,
    t_threshold,
)
from imubench.gap.diagnose import (
    HOLDOUT_ALPHA,
    LOOK_ALIKE_SCORE,
    MAX_EFFECTS,
    MIN_CLOSURE,
    REPLACED,
    exchanged_by,
    removes,
    spans_text,
)
from imubench.gap.line_across import Z_ACROSS


def _f(v: float | None, digits: int = 3) -> str:
    """``digits`` significant digits; 1e3 to 1e6 without an exponent (2048 s reads
    '2050', not '2.05e+03')."""
    if v is None or not math.isfinite(v):
        return "-"
    if 1e3 <= abs(v) < 1e6:
        return f"{float(f'{v:.{digits}g}'):.0f}"
    return f"{v:.{digits}g}"


def _pct(v: float | None) -> str:
    """'42%'; '0%' for a share that rounds to zero from below (it read '-0%')."""
    if v is None or not math.isfinite(v):
        return "-"
    return "0%" if round(v * 100.0) == 0 else f"{v:.0%}"


def _span(lo: float, hi: float, unit: str) -> str:
    """'over lo-hi unit', or 'at lo unit' for a single tau (or band)."""
    a, b = _f(lo), _f(hi)
    return f"at {a} {unit}" if a == b else f"over {a}-{b} {unit}"


def _range(lo: float | None, hi: float | None, unit: str) -> str:
    """'lo-hi unit', or 'lo unit' for a single tau (an outside reviewer read "(1020-1020 s
    real above)")."""
    a, b = _f(lo), _f(hi)
    return f"{a} {unit}" if a == b else f"{a}-{b} {unit}"


def _with_error(v: float, err: float) -> str:
    """'v +- err' in one notation: the error to 2 significant digits and the value to the
    same decimal place (a sine's 7.299983 Hz with 7.9e-06 Hz reads 7.2999831 +-
    0.0000079), fixed-point from 1e-6 to 1e6, else '(m +- e)e-07' with a shared
    exponent."""
    place = math.floor(math.log10(err)) - 1  # the error's last printed digit
    if v == 0 or 1e-6 <= abs(v) < 1e6:
        d = max(0, -place)
        return f"{v:.{d}f} +- {err:.{d}f}"
    exp = math.floor(math.log10(abs(v)))
    d = max(0, exp - place)
    return f"({v / 10**exp:.{d}f} +- {err / 10**exp:.{d}f})e{exp:+03d}"


def _value_only(text: str) -> str:
    """The value of a :func:`_with_error` text: ``1.23`` of ``1.23 +- 0.04``, ``8.8e-07``
    of ``(8.8 +- 2.7)e-07`` (the bracket was cut in half: "(corrected (8.8)")."""
    value, _, rest = text.partition(" +- ")
    if value.startswith("("):
        return value[1:] + rest[rest.index(")") + 1:]
    return value


BIAS_SHOWN = 2.0 / math.sqrt(10.0)
"""A bootstrap bias is said when it exceeds this many standard errors: twice its own
scatter, SE / sqrt(K), at the default K = 10 (an outside reviewer: an outliers rate's
bias of 0.8 SE, 3.6 times its scatter, went unsaid at the old one-SE threshold)."""


Uncertainty = Mapping[str, float | None]
"""A kept effect's ``params_se`` or ``params_bias`` (by parameter; null where none)."""


def _number(p: Mapping[str, Any], key: str, digits: int, se: Uncertainty | None,
            bias: Uncertainty | None) -> tuple[str, str]:
    """(value, note) of ``p[key]``: the value to ``digits`` significant digits, or with
    ``+- SE`` to the SE's precision when ``se`` has one; the note (after the unit) gives
    the bootstrap bias where it exceeds the SE, or '(the model's, not fitted)' for a key
    the estimator did not fit (absent from a non-empty ``se``)."""
    v, err = p.get(key), (se or {}).get(key)
    if se and key not in se:
        return _f(v, digits), " (the model's, not fitted)"
    if v is None or err is None or not (math.isfinite(v) and math.isfinite(err) and err > 0):
        return _f(v, digits), ""
    b = (bias or {}).get(key)
    note = ""
    if b is not None and math.isfinite(b) and abs(b) > BIAS_SHOWN * err:
        note = (f", refits read {_f(abs(b), 2)} {'high' if b > 0 else 'low'} (corrected "
                f"{_value_only(_with_error(float(v) - b, float(err)))})")
    return _with_error(float(v), float(err)), note


def _valued(p: Mapping[str, Any], key: str, units: Mapping[str, str] | None,
            digits: int = 3, se: Uncertainty | None = None,
            bias: Uncertainty | None = None) -> str:
    """``p[key]`` followed by its unit from ``units`` (none for a dimensionless '1'), with
    ``+- SE`` (and a bias beyond it) when ``se`` (the JSON's ``params_se``) holds one
    for ``key`` (:func:`_number`)."""
    unit = (units or {}).get(key, "1")
    value, note = _number(p, key, digits, se, bias)
    return value + ("" if unit == "1" else f" {unit}") + note


def params_text(p: dict[str, Any], units: Mapping[str, str] | None,
                entry: Mapping[str, Any] | None = None, digits: int = 4) -> str:
    """``key = value unit, ...`` of an effect's parameters (no filter: said so), each
    with ``+- SE`` where ``entry`` (a kept effect's JSON entry) has ``params_se`` for it
    (:func:`_number`), else to ``digits`` significant digits."""
    se, bias = (entry or {}).get("params_se"), (entry or {}).get("params_bias")
    out = []
    for k, v in p.items():
        if k == "filter_order" and not (p.get("bandwidth_hz") or 0) > 0:
            continue
        if k == "bandwidth_hz" and not (v or 0) > 0:
            out.append("no output filter")
            continue
        out.append(f"{k} = {_valued(p, k, units, digits, se, bias)}")
    return ", ".join(out)


def _detections(c: dict[str, Any], dof: int) -> list[str]:
    """The fit part's statistics beyond their thresholds (Student t with ``dof``)."""
    out = []
    for r in c["regions"]:
        out.append(f"Allan curve {r['direction'].replace('_', ' ')} "
                   f"{_span(r['tau_min_s'], r['tau_max_s'], 's')} (largest |z| "
                   f"{abs(r['z_max']):.1f}, region gap {_f(r['gap'])})")
    for b in c.get("bands", []):
        out.append(f"spectrum {b['direction'].replace('_', ' ')} "
                   f"{_span(b['f_min_hz'], b['f_max_hz'], 'Hz')}")
    names = {"line_z": f"a spectral line at {_f(c['line']['f_hz'], 4)} Hz",
             "tail_z": "impulsive tails", "temp_z": "correlation with temperature",
             "temp_level_z": "a temperature response of the block means",
             "trend_z": "a time trend"}
    for key, kind, z, thr, nd in _fired_stats(c, dof):
        out.append(f"{names[key]} ({kind} {z:.{nd}f} against the threshold {thr:.{nd}f})")
    g = c.get("global") or {}
    if g.get("fired"):
        out.append(f"the whole Allan curve's shape (chi-squared {g['chi2_smooth']:.1f} "
                   f"against {g['threshold_smooth']:.1f}; {g['chi2']:.1f} against "
                   f"{g['threshold']:.1f} over all {g['dof']} taus)")
    return out


def _fired_stats(c: dict[str, Any], dof: int
                 ) -> list[tuple[str, str, float, float, int]]:
    """Each :data:`STAT_TESTS` statistic of the entry beyond its threshold (Student t with
    ``dof``): (key, 'z' or 't', value, threshold, decimals to print them with: 1, or 2
    where the value rounds to its threshold, 3.60 over 3.56 rather than 3.6 / 3.6)."""
    out = []
    for key, z_norm, one_sided in STAT_TESTS:
        z = _stat(c, key)
        if stat_fired(z, z_norm, one_sided, stat_dof(key, dof)):
            thr = t_threshold(z_norm, stat_dof(key, dof))
            nd = 1 if f"{abs(z):.1f}" != f"{thr:.1f}" else 2
            out.append((key, "z" if key in POOLED_STATS else "t", z, thr, nd))
    return out


def _whole_record(c: dict[str, Any]) -> list[str]:
    """The whole-record tests (bias step, drift, temperature) that fired."""
    whole = c.get("whole_record") or {}
    out = []
    if whole.get("step_fired"):
        out.append(f"a bias step (step statistic {c['bias_step_z']:.1f} against the "
                   "realisations)")
    if whole.get("drift_fired"):
        out.append(f"a drift (t {c['drift_t']:.1f})")
    if whole.get("temperature_fired"):
        out.append(f"a temperature response (z {c['temperature_record_z']:.1f} against "
                   f"{t_threshold(Z_SLOPE, POOLED_DOF):.1f})")
    a = c.get("line_across") or {}
    if whole.get("line_across_fired"):
        out.append(f"a spectral line at {_f(a['f_fit_hz'], 4)} Hz on the fit part found "
                   f"again at {_f(a['f_hz'], 4)} Hz on the held-out part (z {a['z']:.1f} "
                   f"against {a['threshold']:.1f})")
    return out


def _after_kept(c: dict[str, Any], dof: int) -> str:
    """'After the kept effects: name before -> after, ...' for each Allan region (its
    gap), spectral band run (its largest |z|), single statistic and whole-record test that
    fired at the first step (empty
    without a kept effect or the JSON's ``statistics_after``): how far the kept effects
    explain each detection."""
    after, whole_after = c.get("statistics_after"), c.get("whole_record_after")
    if not c.get("kept") or after is None or whole_after is None:
        return ""
    names = {"line_z": "the spectral line", "tail_z": "the tails",
             "temp_z": "the correlation with temperature",
             "temp_level_z": "the temperature response of the block means",
             "trend_z": "the time trend"}
    out = [f"the Allan curve {r['direction'].replace('_', ' ')} "
           f"{_span(r['tau_min_s'], r['tau_max_s'], 's')}, region gap {_f(r['gap'])} -> "
           f"{_f(r['gap_after'])}" for r in c["regions"] if r.get("gap_after") is not None]
    out += [f"the spectrum {b['direction'].replace('_', ' ')} "
            f"{_span(b['f_min_hz'], b['f_max_hz'], 'Hz')}, largest |z| {b['z_max']:.1f} -> "
            f"{b['z_max_after']:.1f}" for b in c.get("bands") or []
            if b.get("z_max_after") is not None and math.isfinite(b["z_max_after"])]
    g, ga = c.get("global") or {}, c.get("global_after") or {}
    if g.get("fired") and ga.get("chi2_smooth") is not None:
        out.append(f"the whole Allan curve's shape chi-squared {g['chi2_smooth']:.1f} -> "
                   f"{ga['chi2_smooth']:.1f} (threshold {ga['threshold_smooth']:.1f})")
    for key, kind, z, _, nd in _fired_stats(c, dof):
        a = after.get(key)
        out.append(f"{names[key]} {kind} {z:.{nd}f} -> "
                   + ("-" if a is None else f"{a:.{nd}f}"))
    whole = c.get("whole_record") or {}
    for fired, key, name in (("step_fired", "bias_step_z", "the whole-record bias step z"),
                             ("drift_fired", "drift_t", "the whole-record drift t"),
                             ("temperature_fired", "temperature_record_z",
                              "the whole-record temperature response z")):
        if whole.get(fired) and c.get(key) is not None:
            a = whole_after.get(key)
            out.append(f"{name} {c[key]:.1f} -> " + ("-" if a is None else f"{a:.1f}"))
    if whole.get("line_across_fired"):
        a = whole_after.get("line_across_z")
        out.append(f"the held-out part's line z {c['line_across']['z']:.1f} -> "
                   + ("- (no other peak to test)" if a is None or not math.isfinite(a)
                      else f"{a:.1f}"))
    return ("After the kept effects, the tests that fired read: " + "; ".join(out)
            + ".") if out else ""


def _stat(c: dict[str, Any], key: str) -> float:
    """A :data:`STAT_TESTS` statistic from the JSON entry (NaN when absent or null)."""
    v = {"line_z": c["line"]["z"], "tail_z": c["impulses_z"],
         "temp_z": c["temperature_slope_z"], "trend_z": c["trend_z"],
         "temp_level_z": c.get("temperature_level_z")}[key]
    return float("nan") if v is None else float(v)


def _has_temp(c: dict[str, Any]) -> bool:
    """Whether the channel entry ``c`` has temperature tests (a recording without
    temperature readings has none: an outside reviewer's misspelt ``tmep`` column read
    "Nothing exceeds its threshold (... temperature ...)" with every one of them null)."""
    return any(v is not None and math.isfinite(v) for v in
               (c.get(k) for k in ("temperature_slope_z", "temperature_record_z",
                                   "temperature_level_z")))


def _strongest(c: dict[str, Any], dof: int) -> str:
    """The single statistic closest to its threshold, as 'name t/threshold' (for `none`;
    the Allan, band, whole-curve, whole-record step and drift tests are not ranked with
    them). The whole-record temperature z is: an outside reviewer's response of 8 mdps/degC
    on an ADIS16405 hour read z 2.5 there while the text named the line at t 1.2."""
    names = {"line_z": "line", "tail_z": "tails", "temp_z": "temperature", "trend_z": "trend",
             "temp_level_z": "temperature level"}
    ratios = []
    for key, z_norm, one_sided in STAT_TESTS:
        z = _stat(c, key)
        z = z if one_sided else abs(z)
        if math.isfinite(z):
            thr = t_threshold(z_norm, stat_dof(key, dof))
            ratios.append((z / thr, names[key], z, thr, "z" if key in POOLED_STATS else "t"))
    z_rec = c.get("temperature_record_z")
    if z_rec is not None and math.isfinite(z_rec):
        thr = t_threshold(Z_SLOPE, POOLED_DOF)
        ratios.append((abs(z_rec) / thr, "the whole-record temperature", abs(z_rec), thr, "z"))
    across = c.get("line_across") or {}
    z_across = across.get("z")
    if z_across is not None and math.isfinite(z_across):  # an outside reviewer: 3.497
        # against 3.5 went unsaid, "line (t 1.1 against 5.9)" being named instead
        ratios.append((z_across / across["threshold"],
                       f"the line on both parts at {_f(across['f_hz'], 4)} Hz", z_across,
                       across["threshold"], "z"))
    if not ratios:
        return ""
    _, n, z, thr, kind = max(ratios)
    stats = ("line, line on both parts, tails, temperature, temperature level, trend, "
             "whole-record temperature" if _has_temp(c)
             else "line, line on both parts, tails, trend")
    return (f"; of the single statistics ({stats}) the closest to its "
            f"threshold is {n} ({kind} {z:.1f} against {thr:.1f})"
            + (" (beyond it, but not beyond every realisation of the model at those "
               "frequencies)" if n.startswith("the line on both") and z > thr else ""))


def _filter_text(p: Mapping[str, Any]) -> str:
    """'output filter 15 Hz, order 2' or 'no output filter' of a model's parameters."""
    bw = p.get("bandwidth_hz")
    return (f"output filter {_f(bw, 3)} Hz, order {_f(p.get('filter_order'), 3)}"
            if bw is not None and bw > 0 else "no output filter")


def _base_model_text(p: Mapping[str, Any], white: str, own: Mapping[str, Any]) -> str:
    """The base model's refit in words, each part beside the model's own (``own``, the
    JSON's ``model_params``): a refit that moves the white level by 0.5 % read as "the
    base model is off ... refit the model's white level" (an outside reviewer's null)."""
    w, w0 = p.get("white"), own.get("white")
    change = (f" ({(w / w0 - 1.0):+.1%} on the model's {_f(w0, 4)})"
              if w is not None and w0 else "")
    filt, filt0 = _filter_text(p), _filter_text(own) if own else ""
    if filt0:
        filt += ", as the model" if filt == filt0 else f", where the model has {filt0}"
    return (f"the base model is off (refit: white {white}{change}; {filt}); refit the "
            "model's white level and filter")


def describe(effect: str, p: dict[str, Any], units: Mapping[str, str] | None = None,
             entry: Mapping[str, Any] | None = None) -> str:
    """What an effect with parameters ``p`` does, in plain words; each value is followed
    by its unit from ``units`` (the JSON's ``units.params.<channel>``) when given.
    ``entry``: the effect's JSON entry, whose ``temp_slope_at_mean`` states a curved
    temperature response at the record's mean temperature rather than at temp_ref, and
    whose ``sine_amplitude_at_output`` a line as recorded beside the model file's
    amplitude before the output filter; a kept effect's ``params_se`` puts ``+- SE``
    after each value that has one."""
    def g(k: str) -> str:
        return _valued(p, k, units, se=e.get("params_se"), bias=e.get("params_bias"))

    def num(k: str, unit: str, digits: int = 3) -> str:  # in a unit of the sentence's
        value, note = _number(p, k, digits, e.get("params_se"), e.get("params_bias"))
        return f"{value} {unit}{note}"

    def like(value: Any, key: str) -> str:  # another value in the unit of ``key``
        return _valued({key: value}, key, units)

    e = entry or {}
    # what the channel reads: an accelerometer's (unit g) is no rate (an outside reviewer
    # read "The rate drifts with temperature, 0.00157 g/degC")
    what = "the acceleration" if (units or {}).get("ramp", "").startswith("g/") else "the rate"
    if effect == "sine" and e.get("sine_amplitude_at_output") is not None:
        return (f"a sinusoidal disturbance of amplitude "
                f"{like(e['sine_amplitude_at_output'], 'sine_amplitude')} at "
                f"{num('sine_freq', 'Hz')} as recorded ({g('sine_amplitude')} before "
                "the model's output filter, the model file's value)")
    slow = ""
    if effect == "temperature" and e.get("slow_terms_scale") is not None:
        terms = [k for k in SLOW_TERMS if k in p]
        slow = (f", in place of part of the model's slow terms ({', '.join(terms)} scaled "
                f"by {e['slow_terms_scale']:.2g} to " + ", ".join(g(k) for k in terms)
                + "): this record's slow noise is weaker than the model's beside the "
                "response. A model fitted on a record whose temperature moved carries that "
                "record's response as such noise (then refit it from a recording with "
                "temperature readings, with `imubench fit --fit-temperature`); a model "
                "fitted without one does not, and a slow term's realisation over one "
                "record also varies this much by chance")
    if effect == "temperature" and p.get("temp_coeff2") and \
            e.get("temp_slope_at_mean") is not None:
        return (f"{what} drifts with temperature, "
                f"{like(e['temp_slope_at_mean'], 'temp_coeff')} at the record's mean "
                f"{_f(e.get('temp_mean_c'), 3)} degC, curving by {g('temp_coeff2')} "
                f"(model-file coefficients at temp_ref: temp_coeff {g('temp_coeff')})"
                + slow)

    if effect in ("flicker", "random_walk") and (e.get("model_params") or {}).get(effect) == 0:
        name = {"flicker": "a bias instability (flicker)", "random_walk":
                "a bias that wanders as a random walk"}[effect]
        return (f"the record has {name} that the model lacks "
                f"({'B' if effect == 'flicker' else 'K'} = {g(effect)}); a model fitted "
                "(imubench fit) on an hour or so of a sensor can leave out a slow term this "
                "weak, and that fit's notes then say that its model under-predicts the "
                "longest taus (docs/noise-fit.md)")
    if effect == "base_model":
        return _base_model_text(p, g("white"), e.get("model_params") or {})
    return {
        "temperature": f"{what} drifts with temperature, {g('temp_coeff')}{slow}",
        "sine": f"a sinusoidal disturbance of amplitude {g('sine_amplitude')} at "
                f"{num('sine_freq', 'Hz')}",
        "random_walk": f"the bias wanders as a random walk (K = {g('random_walk')})",
        "flicker": f"the bias instability (flicker) is larger than modelled (B = "
                   f"{g('flicker')})",
        "ramp": f"{what} drifts linearly in time, {g('ramp')}",
        "quantization": f"quantization noise is larger than modelled (Q = "
                        f"{g('quantization')})",
        "markov": f"a correlated bias (Gauss-Markov) of sigma {g('markov_sigma')} with "
                  f"correlation time {num('markov_tau', 's')}",
        "telegraph": f"the bias jumps between two levels {g('telegraph_step')} apart "
                     f"(telegraph noise), mean dwell {num('telegraph_dwell_s', 's')}",
        "resonance": f"a narrowband resonance at {num('resonance_freq_hz', 'Hz')}, "
                     f"width {num('resonance_width_hz', 'Hz')}, peak PSD "
                     f"{g('resonance_height')} above the model",
        "outliers": f"impulsive outliers, {num('outlier_rate', 'per s')} of amplitude "
                    f"{g('outlier_amplitude')}",
        "bias_step": f"the bias steps by {g('step_size')} at t = "
                     f"{num('step_time_s', 's', 4)}",
    }.get(effect, effect)


STEP_NOT_INDEPENDENT = ("a bias step is located on the whole record, the held-out part "
                        "included, so for it this is not an independent check")
RECORD_NOT_INDEPENDENT = ("the temperature response is fitted on the whole record, the "
                          "held-out part included, so for it this is not an independent "
                          "check")


def on_record(k: dict[str, Any] | None) -> bool:
    """Whether the effect entry ``k`` was fitted on the whole record rather than the fit
    part (a bias step; a temperature response where the parts' temperature spans are too
    unequal, JSON ``fitted_on``)."""
    return (k or {}).get("effect") == "bias_step" or (k or {}).get("fitted_on") == "whole_record"


def _not_independent(k: dict[str, Any] | None) -> str:
    """Why the held-out figures are no independent check of the whole-record effect
    ``k``."""
    return STEP_NOT_INDEPENDENT if (k or {}).get("effect") == "bias_step" \
        else RECORD_NOT_INDEPENDENT


UNMOVED = 0.05
"""A held-out gap that moves by less than this share is said not to close (or to
widen beyond it): one rule for the headline and the held-out check lines."""


def _closed(h: dict[str, Any] | None, after: dict[str, Any] | None) -> str:
    """What modelling the effect does on the held-out part, in words: 'closes N % of the
    systematic gap' (or of the gap, when it has no systematic part), or, when the
    held-out Allan gap does not close, that it does not, with where the held-out
    evidence is (a line, a step or a tail barely moves the Allan curve)."""
    if not h or h.get("gap_before") is None:
        return ""
    eb = h.get("gap_excess_before")
    if after is not None:
        ea, ga = after.get("holdout_gap_excess_after"), after.get("holdout_gap_after")
    else:
        ea, ga = h.get("gap_excess_after"), h.get("gap_after")
    if eb is not None and eb > 0.05 and ea is not None:
        frac, what = 1.0 - ea / eb, "the systematic Allan-curve gap"
    elif eb is not None and ea is not None and not on_record(after):
        # nothing systematic to close there: a share of the raw gap would be of scatter
        after_too = "before and after " if ea <= 0.05 else "without it and departs with it "
        text = (f"; the held-out Allan curve is within its scatter {after_too}"
                f"(systematic gap {_f(eb)} -> {_f(ea)}")
        gb = h.get("gap_before")
        if ga is not None and gb and ga > (1.0 + UNMOVED) * gb:
            text += f"; its gap widens {_f(gb)} -> {_f(ga)}"
        return text + ")" + _holdout_evidence(after)
    elif ga is not None and h["gap_before"]:
        frac, what = 1.0 - ga / h["gap_before"], "the Allan-curve gap"
    else:
        return ""
    if frac >= UNMOVED:
        return f"; modelling it closes {_pct(frac)} of {what} on the held-out part"
    if on_record(after):
        what = ("the step is located" if (after or {}).get("effect") == "bias_step"
                else "the response is fitted")
        return f"; {what} on the whole record, so the held-out part is not its test"
    ga = ga if ga is not None else h.get("gap_after")
    moves = ("widens" if ga is not None and ga > (1.0 + UNMOVED) * h["gap_before"]
             else "does not close")
    text = (f"; on the held-out part the Allan-curve gap {moves} "
            f"({_f(h['gap_before'])} -> {_f(ga)})")
    return text + _holdout_evidence(after)


def _holdout_evidence(after: dict[str, Any] | None) -> str:
    """Where the held-out check's evidence for a kept effect is (its largest chi-squared
    drop), or empty."""
    line_z = (after or {}).get("held_out_line_z")
    if line_z is not None:  # the check that passed it (its chi-squared may not fall)
        return (f"; the held-out check's evidence for it is its line, found again on the "
                f"held-out part (z {line_z:.1f})")
    parts = (after or {}).get("holdout_chi2_drop_parts") or {}
    best = max(parts, key=lambda k: parts[k]) if parts else ""
    if not (best and parts[best] > 0):
        return ""
    text = (f"; the held-out check's evidence for it is in the {PART_NAMES[best]} "
            f"(chi-squared falls by {parts[best]:.1f}")
    return text + ")"


def headline(c: dict[str, Any], realisations: int,
             units: Mapping[str, str] | None = None) -> str:
    """The verdict in plain words, numbers after (values with ``units``, see
    :func:`describe`)."""
    verdict, reason = c["verdict"], c.get("reason", "")
    kept = c.get("kept", [])
    if verdict == "none":
        bg = c.get("background") or {}
        if reason == "replicate variation":
            src = {"replicates": "its replicates"}.get(
                str(bg.get("source")), "the two halves of the record")
            every = (" (the whole-curve test fired, so every tau is counted)"
                     if (c.get("global") or {}).get("fired") else "")
            return ("No unmodelled effect: the recording departs from the model at "
                    f"{_range(bg.get('tau_min_s'), bg.get('tau_max_s'), 's')}{every} by no "
                    f"more than {src} differ (replicate variation).")
        h = c.get("holdout") or {}
        if h.get("significant"):
            return (f"No unmodelled effect on the fit part (within the scatter of "
                    f"{realisations} realisations), but the held-out part departs from the "
                    "model.")
        above = [f"the {name} part (systematic gap {_f(x['gap_excess_before'])} above its "
                 f"floor {_f(x['gap_excess_floor'])})" for name, x in (("fit", c), ("held-out", h))
                 if (x.get("gap_excess_before") or 0.0) > 0.0 and x.get("gap_excess_floor")]
        if above:
            return (f"No test finds an unmodelled effect (within the scatter of "
                    f"{realisations} realisations), but the Allan curve departs more than "
                    f"scatter usually takes it on " + " and ".join(above) + ", which a "
                    "perfect model passes 4-9 % of the time.")
        return (f"No unmodelled effect: the model explains the recording within the scatter "
                f"of {realisations} realisations.")
    if verdict == "unexplained":
        return ("The model departs from the recording, but no candidate effect explains it "
                "on both the fit and the held-out part.")
    main = next((k for k in kept if k["effect"] == verdict), None)
    ranked = next((e for e in c.get("effects", []) if e["effect"] == verdict), None)
    text = describe(verdict, (main or ranked or {}).get("params", {}), units, main or ranked)
    # the held-out figures of the verdict's effect alone (kept dicts are cumulative)
    alone = _closed(c.get("holdout"), main) if kept and kept[0] is main else ""
    others = [k for k in kept if k is not main]
    if others and alone.startswith("; on the held-out part"):  # the others close the rest
        alone = alone.replace("; on the held-out part", "; on its own, on the held-out part",
                              1)
    if on_record(main) and alone.startswith("; modelling it closes "):
        alone += f" ({_not_independent(main)})"
    if others and alone.startswith("; modelling it closes "):  # read as all of them (a reviewer)
        alone = alone.replace("; modelling it closes ", "; modelling it on its own closes ", 1)
    text = (text[0].upper() + text[1:] + alone + "." + _look_alike_text(c, units)
            + _covered_tests(c) + _markov_beyond_span(c))
    if others:
        text += " Also kept: " + "; ".join(describe(k["effect"], k["params"], units, k)
                                           + _unfixed(k, c) for k in others)
        together = _closed(c.get("holdout"), None)
        if together.startswith("; modelling it closes "):
            text += (" (all kept effects together close "
                     + together.removeprefix("; modelling it closes ")
                     + "".join(f"; {_not_independent(k)}" for k in kept if on_record(k))
                     + ").")

        elif together:
            text += " (with all kept effects" + together.lstrip(";").replace(";", ",") + ")."
        else:
            text += "."
    return text


class RecordTest(NamedTuple):
    """A whole-record test of a deterministic effect, as the JSON reports it."""

    flag: str
    """Its ``whole_record`` flag (fired at the first step)."""
    key: str
    """Its statistic's key (named in words by :data:`RECORD_WORDS`)."""
    symbol: str
    effect: str
    words: str
    """The effect in words."""


COVERED = (RecordTest("temperature_fired", "temperature_record_z", "z", "temperature",
                      "a temperature response"),
           RecordTest("drift_fired", "drift_t", "t", "ramp", "a ramp"),
           RecordTest("step_fired", "bias_step_z", "z", "bias_step", "a bias step"))
"""The whole-record tests of the deterministic effects."""
NOISE_WORDS = frozenset({"random_walk", "flicker", "markov", "telegraph"})
"""Kept noise processes whose slow wander widens the whole-record tests' null spread."""


def _covered_tests(c: dict[str, Any]) -> str:
    """' The whole-record temperature test fired (z 7.0) and no temperature response is
    kept: ...' for each whole-record test of a deterministic effect that fired at the
    first step while its effect is not kept (an outside reviewer's Markov process beside
    a temperature response, kept as a random walk alone, read as if the temperature
    had never been seen); empty without one."""
    fired = c.get("whole_record") or {}
    after = c.get("whole_record_after") or {}
    kept = {k["effect"] for k in c.get("kept", [])}
    still = set(c.get("fired_after") or [])
    noise = sorted(kept & NOISE_WORDS)
    out = ""
    for rt in COVERED:
        if not fired.get(rt.flag) or rt.effect in kept:
            continue
        test = RECORD_WORDS[rt.key]
        out += (f" {test[0].upper()}{test[1:]} fired ({rt.symbol} {_f(c.get(rt.key))}) and "
                f"no {rt.words.removeprefix('a ')} is kept: with the kept effects it reads "
                f"{_f(after.get(rt.key))}")
        if rt.key in still:
            out += ", still firing."
        elif noise:
            out += (f" ({' and '.join(noise)} widens the realisations' spread of it, so "
                    f"{rt.words} beside a noise process of shorter memory is another reading "
                    "of this record).")
        else:
            out += "."
    return out


def _markov_beyond_span(c: dict[str, Any]) -> str:
    """' A Gauss-Markov process was fitted as well and refused: ...' when a random walk is
    kept and the first step refused the Markov candidate because its correlation time is
    beyond what the fit part shows with a turnover: there the two are look-alikes, which
    the whole record can tell apart (an outside reviewer's Markov processes of 75-120 s
    beside a temperature response on a 30 min fit part, each kept as a random walk, the
    text silent on the Markov; with --holdout-fraction 0, 6 of 6 named right). Empty
    otherwise."""
    why = (c.get("not_fitted") or {}).get("markov", "")
    if not why.startswith(MARKOV_NO_TURNOVER) or \
            "random_walk" not in {k["effect"] for k in c.get("kept", [])}:
        return ""
    whole = ("the whole record (--holdout-fraction 0, without a held-out check) or "
             if c.get("holdout") else "")
    return (f" A Gauss-Markov process was fitted as well and refused ({why}): on a fit part "
            "this short a Gauss-Markov process whose correlation time is that long and a "
            f"random walk look alike; {whole}a longer recording can show its turnover.")


RECORD_WORDS = {"bias_step_z": "the whole-record bias-step test",
                "drift_t": "the whole-record drift test",
                "temperature_record_z": "the whole-record temperature test",
                "line_across_z": "the held-out part's line test"}
"""The whole-record tests of the JSON's ``fired_after``, in words."""


def _still_firing(c: dict[str, Any]) -> str:
    """' (still firing: ...)': the tests that fire against the model with the kept
    effects (the JSON's ``fired_after``, the Allan regions from ``regions_after``); empty
    without them."""
    words = []
    for name in c.get("fired_after") or []:
        if name == "regions":
            words += [f"the Allan curve {r['direction'].replace('_', ' ')} "
                      f"{_span(r['tau_min_s'], r['tau_max_s'], 's')} (largest |z| "
                      f"{r['z_max']:.1f})" for r in c.get("regions_after") or []]
        else:
            words.append(FIRED_WORDS.get(name) or RECORD_WORDS.get(name, name))
    return f" (still firing: {'; '.join(words)})" if words else ""


def _look_alike_text(c: dict[str, Any], units: Mapping[str, str] | None) -> str:
    """' A look-alike fits nearly as well ...' for the JSON's ``look_alike`` (empty
    without one): another effect that scores within 2 (times the step's overdispersion)
    of the verdict's on the fit part and passes the same checks, so that the fit part
    does not tell the two apart."""
    la = c.get("look_alike")
    if not la:
        return ""
    held = ""
    if la.get("holdout_chi2_drop") is not None and la.get("holdout_chi2_drop_verdict") is not None:
        held = (f"; the held-out chi-squared falls by {la['holdout_chi2_drop']:.1f} with it, "
                f"by {la['holdout_chi2_drop_verdict']:.1f} with the verdict")
    decided = (", the held-out part decided" if la["score"] < la["score_verdict"] else "")
    c_hat = la.get("overdispersion") or 1.0
    below = (f"{LOOK_ALIKE_SCORE:g}" if c_hat <= 1.0 else
             f"{LOOK_ALIKE_SCORE * c_hat:.1f} ({LOOK_ALIKE_SCORE:g} times the fit's "
             f"chi-squared per term, {c_hat:.1f}: a fit this far from a perfect one makes "
             "score differences that much weaker as evidence)")
    at = (f" at step {la['step']}, beside the effects kept before it"
          if (la.get("step") or 1) > 1 else "")
    return (f" A look-alike fits nearly as well{at}, and the fit part does not tell the "
            f"two apart: {describe(la['effect'], la['params'], units, la)} (score "
            f"{la['score']:.1f} against {la['score_verdict']:.1f} on the fit part, lower is "
            f"better; a difference below {below} is no evidence either way{decided}), and "
            f"it passes the same checks{held}.")


PART_NAMES = {"allan": "Allan curve", "bands": "spectrum bands", "statistics":
              "line, tail, temperature, trend and level statistics"}


def _check_lines(kept: list[dict[str, Any]], h: dict[str, Any],
                 spans: dict[str, float] | None = None) -> list[str]:
    """What the held-out check measured for each kept effect, and why the held-out gap
    shown may not move when the check passes (each effect's gap after it against the gap
    after the effects before it).

    The check is a chi-squared over the Allan curve (whole-curve statistic, each tau once
    with the correlation of the estimates), the spectrum bands and the single statistics;
    the gap is the Allan curve's RMS of ln(ADEV_real / ADEV_sim) alone, every tau weighted
    equally (the long taus' scatter dominates it), against the realisations' mean Allan
    variance. An effect seen in the spectrum or a statistic
    (temperature, outliers, a line, a step) or a base-model refit at short taus can pass
    the check and leave the gap as it was; a random walk can pass it and RAISE the gap,
    because the mean Allan variance of realisations with a random walk lies above a
    typical single record's at the longest taus."""
    out = []
    before = h.get("gap_before")
    for k in kept:
        after = k.get("holdout_gap_after")
        prev, before = before, after if after is not None else before
        drop, parts = k.get("holdout_chi2_drop"), k.get("holdout_chi2_drop_parts") or {}
        if drop is None or not math.isfinite(drop):
            continue
        if k["effect"] == "bias_step":
            out.append("Held-out check of bias_step: not applied (the step is located and "
                       "tested on the whole record).")
            continue
        if on_record(k):
            where = (spans_text((spans["fit_part"], spans["held_out"], spans["record"]))
                     + ": one part holds too little of it to fit a response there or "
                     "check it there; " if spans else "")
            out.append(f"Held-out check of {k['effect']}: not applied ({where}it is fitted "
                       "on the whole record and tested there, by the whole-record "
                       "temperature test).")
            continue
        limit = (f"{chi2_dist.isf(HOLDOUT_ALPHA, k['n_params']):.1f} for {k['n_params']} "
                 f"parameter{'s' * (k['n_params'] > 1)}" if "n_params" in k else "")
        line_z = k.get("held_out_line_z")
        need = ("" if not limit else f"; must not rise by more than {limit}"
                if line_z is not None else f"; needs more than {limit}")
        txt = (f"Held-out check of {k['effect']}: "
               + (f"the held-out part's spectrum at the fit part's peak (a line on both "
                  f"parts, z {line_z:.1f} against {Z_ACROSS:.1f}); the held-out "
                  if line_z is not None else "")
               + f"chi-squared fell by {drop:.1f}"
               + (" (" + ", ".join(f"{PART_NAMES.get(n, n)} {v:.1f}"
                                   for n, v in parts.items()) + f"{need})" if parts else ""))
        if (parts and prev is not None and after is not None and drop > 0
                and after >= (1.0 - UNMOVED) * prev):
            main = max(parts, key=lambda n: parts[n])
            left = k.get("holdout_gap_excess_after") or 0.0
            dominated = (f"here dominated by a systematic departure this effect does not "
                         f"touch (held-out systematic part {_f(left)} after it"
                         + (", closed by the effects kept after it)"
                            if k is not kept[-1] and not h.get("gap_excess_after")
                            else ")")
                         if left > 0 else "which the scatter of the long taus dominates")
            txt += (f"; the held-out gap ({_f(prev)} -> {_f(after)}) "
                    + ("did not fall" if after <= (1.0 + UNMOVED) * prev else "rose")
                    + ": it is the Allan curve's RMS of ln ratios with every tau weighted "
                    f"equally, {dominated}, while the check "
                    "weighs each term by its precision (the Allan curve's on the scatter "
                    "of the model without the effect) and adds the spectrum and the "
                    f"statistics; its largest drop is in the {PART_NAMES.get(main, main)}")
            if main == "allan" and after > (1.0 + UNMOVED) * prev:
                txt += (" (the whole-curve statistic compares with the realisations' mean "
                        "ln ADEV and counts correlated taus once; the gap compares with "
                        "their mean Allan variance, which a few realisations with large "
                        "long-tau excursions raise)")
        out.append(txt + ".")
    return out


ESTIMATOR_WORDS = {"gls": "GLS of the block-mean increments on the temperature's",
                   "levels": "least squares of the block-mean levels, linear",
                   "levels_quadratic": "least squares of the block-mean levels, quadratic"}
"""A kept temperature response's ``estimator``, in words."""


def _fewer_refits(kept: list[dict[str, Any]], k: int) -> str:
    """' Fewer refits gave an estimate for: X n of K, ...' (the JSON's ``params_n``; an
    estimator that finds nothing on a realisation leaves it out), or nothing."""
    few = [f"{e['effect']} {key} {n} of {k}" for e in kept
           for key, n in (e.get("params_n") or {}).items() if n < k]
    return (" Fewer refits gave an estimate for: " + ", ".join(few) + ".") if few else ""


SIZE_KEYS = {"bias_step": "step_size", "temperature": "temp_coeff", "ramp": "ramp",
             "sine": "sine_amplitude"}
"""The size of a kept effect that is zero without it (a noise term's value is the model's
total with it, not an increment)."""


def _unfixed(k: Mapping[str, Any], c: Mapping[str, Any]) -> str:
    """'; its size is within two standard errors of zero: ...' for a kept effect whose
    size (:data:`SIZE_KEYS`; a curved temperature response's linear coefficient says
    nothing alone) is that small, else empty. Outside reviewers: a bias step of -0.0040
    +- 0.0026 dps kept beside a ramp where the record held none; a temperature response
    of 0.00077 +- 0.00078 dps/degC kept beside a random walk with no response in the
    record. When the effect's own whole-record test fired (channel entry ``c``) and a
    noise process is kept beside it, both are said: a response of 0.0046 +- 0.0041
    dps/degC beside a random walk, where the whole-record temperature test had read z 8.6
    under the model without the walk (an outside reviewer's Markov process of 120 s kept
    as the walk)."""
    key = SIZE_KEYS.get(k["effect"])
    if key is None or (k["params"].get("temp_coeff2") or 0.0) != 0.0:
        return ""
    size, se = k["params"].get(key), (k.get("params_se") or {}).get(key)
    if size is None or se is None or not math.isfinite(se) or abs(size) >= 2.0 * se:
        return ""
    own = next((rt for rt in COVERED if rt.effect == k["effect"]), None)
    noise = sorted({x["effect"] for x in c.get("kept", [])} & NOISE_WORDS)
    if own is None or not (c.get("whole_record") or {}).get(own.flag) or not noise:
        return "; its size is within two standard errors of zero: the record does not fix it"
    return (f"; its size is within two standard errors of zero beside {' and '.join(noise)}, "
            f"whose realisations' wander widens its refits, though {RECORD_WORDS[own.key]} "
            f"read {own.symbol} {_f(c.get(own.key))} under the model without "
            f"{' and '.join(noise)}")


def _kept_lines(c: dict[str, Any], units: Mapping[str, str] | None = None) -> list[str]:
    kept = c.get("kept", [])
    if not kept:
        return []
    h = c.get("holdout") or {}
    dropped = [f"{d['effect']} ({_refused_params(d, units)}), {d['reason']}"
               for d in c.get("dropped", [])]
    parts = []
    for i, k in enumerate(kept, 1):
        how = (f"; by {ESTIMATOR_WORDS[k['estimator']]}" if k.get("estimator") in
               ESTIMATOR_WORDS else "")
        txt = (f"{i}. {k['effect']} ({params_text(k['params'], units, k)}{how}{_unfixed(k, c)}): "
               f"fit-part gap {_f(k['gap_after'])}")
        if k.get("holdout_gap_after") is not None:
            txt += f", held-out gap {_f(k['holdout_gap_after'])}"
        parts.append(txt)
    # the sequential replacement puts the newcomer last: the list is the final model's
    lead = ("Effects kept, in the final model's order after the replacement below"
            if any(str(d.get("reason", "")).startswith(REPLACED)
                   for d in c.get("dropped", []))
            else "Effects kept in order")
    notes = []
    if h:
        notes.append(f"held-out gap before: {_f(h.get('gap_before'))}")
    if any(k.get("params_se") for k in kept):
        notes.append("values +- one standard error")
    first = lead + (f" ({', '.join(notes)})" if notes else "") + ": "
    out = [first + "; ".join(parts) + "."]
    out.extend(_check_lines(kept, h, c.get("temperature_spans_c")))
    if dropped:
        out.append("Kept at a step of the forward selection, then dropped: "
                   + "; ".join(dropped) + ".")
    if c.get("residual_significant") and c["verdict"] not in ("none",):
        tried = [f"{d['effect']} ({_refused_params(d, units)}): {d['reason']}"
                 for d in c.get("not_kept", [])]
        if tried:
            why = "; tried next and not kept: " + "; ".join(tried)
        elif len(kept) >= MAX_EFFECTS:
            why = f" (the selection keeps at most {MAX_EFFECTS} effects)"
        else:
            why = ""
        out.append(f"A significant departure remains after the kept effects"
                   f"{_still_firing(c)}{why}.")
    alt = _alternative_line(c, units)
    if alt:
        out.append(alt)
    refused = c.get("fired_first_refused") or []
    if refused:
        out.append("Examined first because its own whole-record test fired, and not kept: "
                   + "; ".join(f"{d['effect']} ({_refused_params(d, units)}): {d['reason']}"
                               for d in refused) + ".")
    return out


def _refused_params(d: dict[str, Any], units: Mapping[str, str] | None) -> str:
    """A dropped or not-kept candidate's parameters, saying so when a noise term it raises
    was fitted at no more than the model's own value (JSON ``model_params``): such a
    candidate adds nothing to the model (an outside reviewer read a tried flicker equal
    to the model's own as an effect)."""
    txt = params_text(d["params"], units)
    own = (d.get("model_params") or {}).get(d["effect"])
    v = d["params"].get(d["effect"])
    if own is not None and v is not None and v <= own * (1.0 + 1e-6):
        txt += ", no more than the model's own: it adds nothing"
    return txt


def _alternative_line(c: dict[str, Any], units: Mapping[str, str] | None = None) -> str:
    """'Examined and not kept: ...' for the JSON's ``alternative``
    (the selection that examined the fired deterministic effects first and kept other
    effects), with why it was not taken; empty without one."""
    a = c.get("alternative")
    if not a:
        return ""
    names = " + ".join(f"{k['effect']} ({params_text(k['params'], units)})" for k in a["kept"])
    worse_score = a["score"] >= a["score_kept"]
    if a["score"] >= a["score_kept"] + LOOK_ALIKE_SCORE:
        why = (f"it scores higher on the fit part by {LOOK_ALIKE_SCORE:g} or more and its "
               "held-out gap's excess is not below the kept effects' by more than the "
               "scatter (where it is, the held-out part decides)")
    elif worse_score:
        why = (f"it scores higher on the fit part (by less than {LOOK_ALIKE_SCORE:g}, which "
               "the fit part does not tell apart) and its held-out gap's excess is not "
               "lower")
    else:
        why = ("its held-out gap's excess is above the kept effects' by more than the "
               "scatter")
    favour = ("; the held-out part favours it" if a["holdout_excess"] < a["holdout_excess_kept"]
              and worse_score else "")
    return (f"Examined and not kept: {names}, the effects that the other selection (the "
            f"one that examines first the effects whose own whole-record tests fired) "
            f"kept. It scores {a['score']:.1f} "
            f"against {a['score_kept']:.1f} for the kept effects on the fit part, both as "
            f"the selections end, refitted ("
            f"{a['n_params']} parameters against {a['n_params_kept']}; lower is better), "
            f"held-out gap's excess over its scatter (moment estimate, without the floor "
            f"of gap_excess) {_f(a['holdout_excess'])} against "
            f"{_f(a['holdout_excess_kept'])} (scatter {_f(a['holdout_scatter'])}){favour}; "
            f"not taken because {why}.")


FIRED_WORDS = {"regions": "the Allan curve", "bands": "the spectrum",
               "global": "the whole Allan curve's shape", "line_z": "a spectral line",
               "tail_z": "impulses", "temp_z": "a correlation with temperature",
               "trend_z": "a time trend", "temp_level_z": "the temperature level test"}
"""The held-out tests of :attr:`imubench.gap.curves.Comparison.fired`, in words."""


def _kept_step(c: dict[str, Any], effect: str) -> int | None:
    """The index of ``effect`` among the channel entry ``c``'s kept effects (None: not
    kept)."""
    return next((i for i, k in enumerate(c.get("kept") or []) if k["effect"] == effect),
                None)


def _better_runner_up(effect: str, c: dict[str, Any]) -> str:
    """Why the first step's better-scoring ``effect`` is not the verdict: kept later (the
    selection that examines first the effects whose own whole-record tests fired kept the
    effects in another order, :func:`imubench.gap.diagnose._better_start`), or dropped or
    not kept, with that reason."""
    at = _kept_step(c, effect)
    if at is not None:
        return (f", and is kept as well (step {at + 1}, fitted "
                "again there): the selection that examines first the effects whose own "
                "whole-record tests fired kept the same effects in this order, with a "
                "lower score on the fit part")
    gone = next((x for x in [*c.get("dropped", []), *c.get("not_kept", [])]
                 if x["effect"] == effect), None)
    return (f", but is not kept: {gone['reason']}"
            if gone is not None and gone.get("reason") else "")


def _floor(part: dict[str, Any]) -> str:
    """' (0 below F before, G after)': the floors under which a part's systematic gap is
    reported as 0 (``gap_excess_floor``, ``_after``: the model without and with the kept
    effects), or nothing when the JSON lacks them."""
    f, fa = part.get("gap_excess_floor"), part.get("gap_excess_floor_after")
    if f is None:
        return ""
    return f" (0 below {_f(f)})" if fa is None else f" (0 below {_f(f)} before, {_f(fa)} after)"


SHORT_TAU_S = 1.0
"""Held-out departures all below this tau (s), or only in the spectrum, a line or the
tails, are not a slow process's (:func:`_held_out_causes`)."""


def _held_out_causes(h: dict[str, Any]) -> str:
    """What can leave the held-out part departing after the kept effects, by where it
    departs: at short taus, in the spectrum, a line or the tails, a line or the noise
    level that changes between the parts; at longer taus (or by the level, trend or
    temperature tests), a slow process or a weak effect."""
    regs = h.get("regions_after", [])
    fired = set(h.get("fired_after", [])) - {"regions", "global"}
    fast = (all(r["tau_max_s"] < SHORT_TAU_S for r in regs)
            and fired <= {"bands", "line_z", "tail_z"} and (regs or fired))
    if fast:
        return ("a line, the short-tau noise or the impulses differ between the parts: a "
                "kept line whose amplitude or frequency changes in time, a resonance that "
                "moves, a white level or output filter that changes")
    return ("a slow process's realisation differs from part to part, or an effect is too "
            "weak in the fit part to be kept")


def _held_out_departure(h: dict[str, Any], after: bool) -> str:
    """'The held-out part departs from the model (its regions) where the fit part does not
    (systematic gap, scatter)', before any effect or (``after``) after all kept ones."""
    regs = "; ".join(f"{_range(r['tau_min_s'], r['tau_max_s'], 's')} "
                     f"{r['direction'].replace('_', ' ')}"
                     for r in h.get("regions_after" if after else "regions", []))
    lead = ("The held-out part still departs from the model with the kept effects" if after
            else "The held-out part departs from the model")
    gap = h.get("gap_excess_after" if after else "gap_excess_before")
    tests = [FIRED_WORDS[t] for t in h.get("fired_after" if after else "fired", [])
             if t != "regions"]
    where = f" where the fit part {'no longer does' if after else 'does not'}"
    scatter = f"{_f(gap)} against a scatter of {_f(h.get('gap_null'))}"
    if not regs and tests:  # another test than the Allan taus' regions: the Allan gap
        # may be at its floor (an outside reviewer read "departs (by a time trend) ...
        # (systematic gap 0 against a scatter of 0.111)" as a contradiction)
        return (f"{lead} by {', '.join(tests)}{where}; its Allan curve's systematic gap is "
                + scatter)
    return lead + (f" ({regs})" if regs else "") + where + f" (systematic gap {scatter})"


def _limits_sentence(lim: dict[str, Any], units: Mapping[str, str] | None) -> str:
    """The detection limits (JSON ``limits``, :mod:`imubench.gap.limits`) in words: how
    they were measured, then each effect's limit with its unit and the sizes tried
    (identified / injections, largest first)."""
    parts = []
    for eff, e in lim["effects"].items():
        v = e.get("smallest_identified")
        unit = f" {units[e['key']]}" if units and units.get(e["key"]) else ""
        name = eff if e["key"] == eff else f"{eff} ({e['key']})"
        order = sorted(e["tried"], key=lambda t: -t["size"])  # largest first
        tried = ", ".join(f"{_f(t['size'])} {t['identified']}/{t['of']}" for t in order)
        if e.get("not_searched"):
            parts.append(f"{eff} not searched ({e['not_searched']})")
        elif v is None:
            parts.append(f"{name} not identified up to {_f(order[0]['size'])}{unit} "
                         f"(tried {tried})")
        else:
            bound = ("at most " if e.get("smallest_tried_identified") else "")
            parts.append(f"{name} {bound}{_f(v)}{unit} (tried {tried})")
    n = lim["injections_per_size"] + lim["confirmations"]
    return ("Detection limits on this recording: each effect was added to this recording "
            f"at sizes a factor 2 apart and diagnosed again ({lim['realisations']} "
            "realisations); a limit is the smallest size at which the effect was kept "
            f"(named or not) in {n} of {n} injections, {lim['injections_per_size']} per "
            f"size and {lim['confirmations']} more at the limit: " + "; ".join(parts)
            + f" ({lim['note']}).")


def explain_channel(c: dict[str, Any], realisations: int,
                    units: Mapping[str, str] | None = None) -> list[str]:
    """Sentences explaining the verdict of one channel's JSON entry; ``units``: the
    JSON's ``units.params.<channel>`` (each value is followed by its unit)."""
    dof = max(int(realisations) - 1, 1)
    lines: list[str] = [headline(c, realisations, units)]
    if any(k.get("params_se") for k in c.get("kept", [])):
        k = max(int(realisations), 2)
        whole = [x["effect"].replace("_", " ") for x in c["kept"] if on_record(x)]
        on_whole = (f" (a {' and a '.join(whole)} over the whole record)".replace(
            "a temperature", "a temperature response") if whole else "")
        lines.append(
            f"Values +- one standard error: each kept effect refitted the same way on {k} "
            f"simulated records of the fitted model, over the fit part{on_whole}. The error "
            "is "
            f"itself uncertain by about {1 / math.sqrt(2 * (k - 1)):.0%}, so +-2 of them "
            f"cover the truth about {1 - 2 * student_t.sf(2.0, k - 1):.0%} of the time; it "
            "leaves out which effects were chosen and any error of the model's form. "
            "'Refits read ... high (or low)' is the refits' mean less the value where that "
            "bias is beyond its own scatter, with the value less it (a first-order "
            "correction); an effect that took part of another, or the estimator itself, "
            "biases it." + _fewer_refits(c["kept"], k))
    found = _detections(c, dof)
    verdict = c["verdict"]
    whole = _whole_record(c)
    if found or whole:
        lines.append("; ".join(
            [f"Significant on the fit part: {'; '.join(found)}"] * bool(found)
            + [f"on the whole record: {'; '.join(whole)}"] * bool(whole)) + ".")
        lines[-1] = lines[-1][0].upper() + lines[-1][1:]
    else:
        lines.append("Nothing exceeds its threshold (family-wise Allan and band limits, "
                     + ("whole-curve test, line, tails, temperature, temperature level, "
                        "trend, whole-record step, drift and temperature)" if _has_temp(c)
                        else "whole-curve test, line, tails, trend, whole-record step and "
                        "drift; no temperature test: the recording has no temperature "
                        "readings)")
                     + _strongest(c, dof) + ".")
    if c.get("temperature_note"):
        lines.append(f"Temperature: {c['temperature_note']}.")
    held = c.get("held_samples")
    if held:
        lines.append(
            f"The record holds its output: {held['share']:.0%} of its samples repeat the "
            f"previous one, each value held for a median of {held['median_hold_samples']:g} "
            "samples, and the model's realisations do not. The shortest taus and the upper "
            "spectrum depart for that reason alone: a base_model verdict may be the hold, "
            "and an effect that acts there (a sine, resonance, telegraph or quantization) "
            "can be missed or misnamed.")
    alias = c.get("ramp_temperature_alias")
    if alias:
        lines.append(
            f"The temperature drifted in step with time (r {alias['r_time']:+.2f} over the "
            f"record, {alias['temp_rate_c_per_s'] * 3600.0:.3g} degC/h): the kept ramp's "
            "drift is what a temperature response of "
            + _valued({"temp_coeff": alias["temp_coeff_equivalent"]}, "temp_coeff", units)
            + " would give; a record over a temperature cycle tells the two apart.")
    effects = c["effects"]
    if verdict == "none":
        lines.append("Verdict none: " + (
            "the departure is within the recording's own variation."
            if c.get("reason") == "replicate variation" else
            f"no test on the fit part departs beyond the scatter of {realisations} "
            "realisations."))
        h = c.get("holdout") or {}
        if h.get("significant") and c.get("reason") != "replicate variation":
            lines.append(
                _held_out_departure(h, after=False) + ": the recording changes within "
                "itself; candidates are fitted on the fit part only, so this is not "
                "diagnosed (try --holdout-fraction 0 to diagnose the whole record).")
    elif verdict == "unexplained":
        best = effects[0] if effects else None
        if best is None:
            lines.append("Verdict unexplained: no candidate effect applies to this evidence"
                         + "".join(f"; {e}: {why}" for e, why in
                                   (c.get("not_fitted") or {}).items()) + ".")
        else:
            why = best.get("rejected_because") or (
                f"{removes(best.get('evidence_closed'))} the significant excess "
                f"chi-squared (the verdict needs {MIN_CLOSURE:.0%}, without raising the "
                "total)")
            lines.append(
                f"Verdict unexplained: the best candidate, {best['effect']}, {why}; the "
                "departure comes from an effect outside the candidate list, or from a part "
                "of the base model its refit (white level, output filter) cannot change "
                "(e.g. a Markov or flicker term of the wrong size).")
        tails = next((e["rejected_because"] for e in effects if e["effect"] == "outliers"
                      and (e.get("rejected_because") or "").startswith(DENSE_TAIL)), None)
        if tails is not None:
            lines.append(
                f"The recording's tails are heavy ({tails}). Such tails also raise the white "
                "level of a Gaussian noise fit of the recording (imubench fit warns of "
                "them), which a model fitted on it carries.")
    else:
        kept = c.get("kept") or []
        step = next((i for i, k in enumerate(kept) if k["effect"] == verdict), 0)
        w = (next((e for e in effects if e["effect"] == verdict), None) if step == 0
             else None) or (kept[step] if kept else {})
        ec = w.get("evidence_closed")
        left = ("" if step == 0 else " left by " + ", ".join(k["effect"] for k in kept[:step]))
        share = (f"it {removes(ec)} the significant excess chi-squared{left} (the "
                 f"share criterion is {MIN_CLOSURE:.0%}")
        share += ((f"; {_pct(w.get('chi2_closed'))} of the fit part's total"
                   + (", the step test being on the whole record" if verdict == "bias_step"
                      else "") + ")") if "chi2_closed" in w else ")")
        if ec is None or not ec >= MIN_CLOSURE:
            share += (", and it passed on the other criterion: its chi-squared drop on the "
                      "fit part beats the likelihood-ratio level (p 0.001)")
        after = ("" if step == 0 else " kept at step " + str(step + 1) + ", after "
                 + ", ".join(k["effect"] for k in kept[:step]))
        swapped = [d["effect"] for d in c.get("dropped", [])
                   if str(d.get("reason", "")).startswith(exchanged_by(verdict))]
        if swapped:  # the sequential replacement puts the newcomer last
            after += (f"{',' if after else ''} in place of {' and '.join(swapped)}, kept "
                      "first and then replaced (below)")
        rises = [f"{k['chi2_rise_without']:.1f} for {k['effect']}" for k in kept
                 if "chi2_rise_without" in k and k["effect"] not in (verdict, "base_model")]
        if rises and "chi2_rise_without" in w:
            after += (f" (named as the verdict: taking it out of the kept effects raises the "
                      f"fit part's chi-squared by {w['chi2_rise_without']:.1f}, against "
                      + ", ".join(rises) + ")")
        shown = kept[step] if kept and kept[step]["effect"] == verdict else w
        params = shown["params"]
        if params != w["params"]:  # the base model's refit, fitted again beside a later one
            moved = {key: v for key, v in w["params"].items() if params.get(key) != v}
            after += (" (as kept: fitted again beside the effects kept after it; the "
                      "share and score that follow are of its first fit, "
                      f"{params_text(moved, units, digits=6)})")
        txt = f"Verdict {verdict} ({params_text(params, units, shown)}){after}: {share}"
        if "score" in w:
            txt += f"; score {w['score']:.1f}"
        # the effects list ranks the first step's candidates: a verdict kept at a later
        # step had other rivals, chosen beside the effects kept before it (an outside
        # reviewer read "the runner-up sine" for a sine kept at step 1)
        r = (next((e for e in effects if e["effect"] != verdict), None) if step == 0
             else None)
        if r is not None and "n_params" in w:
            # the first step's best score is not called a runner-up (an outside reviewer)
            lead = ("the runner-up" if "score" not in w or r["score"] >= w["score"]
                    else "the first step's best score was")
            txt += (f"; {lead} {r['effect']}, {r['score']:.1f} (lower is better; "
                    f"BIC penalty ln(n) per parameter, {w['n_params']} against "
                    f"{r['n_params']})")
            why = str(r.get("rejected_because") or "")
            if why.startswith(REPLACED):
                txt += f", was kept first, then {why}"
            elif why:
                txt += f" but was refused: {why}"
            elif "score" in w and r["score"] < w["score"]:
                txt += _better_runner_up(r["effect"], c)
            if not why.startswith(REPLACED) and ("score" not in w
                                                 or r["score"] >= w["score"]):
                # a runner-up kept at a later step (an outside reviewer read "the
                # runner-up temperature" with the response kept at step 2)
                at = _kept_step(c, r["effect"])
                if at is not None and at > 0:
                    txt += f", kept as well at step {at + 1} (below)"
        lines.append(txt + ".")
    lines.extend(_kept_lines(c, units))
    if followed := _after_kept(c, dof):
        lines.append(followed)
    g0, ge = c.get("gap_null"), c.get("gap_excess_before")
    if g0 is not None and ge is not None:
        lines.append(
            f"Gap (RMS over all taus of ln ADEV_real/ADEV_sim) {_f(c['gap_before'])} -> "
            f"{_f(c['gap_after'])}. A perfect model would still show about {_f(g0)} "
            f"(the taus' scatter); the systematic part{_floor(c)} is {_f(ge)} -> "
            f"{_f(c.get('gap_excess_after'))}"
            + ("; a departure confined to a few taus, the spectrum or a statistic is "
               "significant by its own test while the RMS over all taus stays within the "
               "scatter" if ge == 0 and c.get("significant") else "") + ".")
    h = c.get("holdout")
    if h and h.get("gap_before") is not None and "region_gap_before" in h:
        whole = [("to locate the kept bias step" if k["effect"] == "bias_step"
                  else "to fit the kept temperature response")
                 for k in c.get("kept", []) if on_record(k)]
        used = ("never used for the fit" if not whole else
                f"used only {' and '.join(whole)}, on the whole record")
        txt = (f"Held-out part ({used}): gap {_f(h['gap_before'])} -> "
               f"{_f(h['gap_after'])}, systematic{_floor(h)} {_f(h['gap_excess_before'])} "
               f"-> {_f(h['gap_excess_after'])}")
        if c["regions"]:
            txt += (f", over the fit part's regions {_f(h['region_gap_before'])} -> "
                    f"{_f(h['region_gap_after'])}")
        lines.append(txt + ".")
        if c.get("kept") and h.get("significant_after") and not c.get("residual_significant"):
            lines.append(
                _held_out_departure(h, after=True) + ": an effect the fit part does not "
                "show is left there (the kept effects, fitted on the fit part, do not "
                f"describe it: {_held_out_causes(h)}), not diagnosed; "
                "--holdout-fraction 0 diagnoses the whole record, without a held-out "
                "check.")
    reps = (h or {}).get("recordings", [])
    for r in reps:
        txt = f"Replicate {r['recording']}: gap {_f(r['gap_before'])} -> {_f(r['gap_after'])}"
        if r.get("gap_null") is not None:
            txt += (f" (a perfect model ~{_f(r['gap_null'])}, systematic "
                    f"{_f(r.get('gap_excess_before'))}; "
                    f"{'significant' if r.get('significant') else 'not significant'} "
                    "departures from the model)")
        ra, rb, r0 = r.get("gap_after"), r.get("gap_before"), r.get("gap_null")
        if ra is not None and rb is not None and r0 is not None and ra - rb > r0:
            txt += (": the kept effects widen the replicate's gap beyond its scatter, so "
                    "the replicate does not share them; they belong to this recording "
                    "(recording-to-recording variation), not to every recording of the "
                    "sensor")
        lines.append(txt + ".")
    lim = c.get("limits")
    if lim:
        lines.append(_limits_sentence(lim, units))
    if verdict in ("none", "unexplained") and any(r.get("significant") for r in reps):
        lines.append("Replicates depart from the model beyond their scatter"
                     + (" although this recording does not" if verdict == "none" else "")
                     + ": recording-to-recording variation of the sensor, which no single "
                     "effect fitted to this recording captures.")
    return lines
