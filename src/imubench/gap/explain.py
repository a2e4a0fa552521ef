"""Plain-language reasons behind a channel's verdict, from its JSON result.

``explain_channel(c, realisations)`` turns one ``channels[<ch>]`` entry of ``imubench gap``
into sentences a user can check against the plots: what fired on the fit part and how far
above its threshold, why the verdict is what it is (the share of the excess chi-squared
the best candidate removes against :data:`~imubench.gap.diagnose.MIN_CLOSURE`, and its
score against the runner-up's), how the issue's gap splits into the scatter a perfect
model would also show and the systematic part, and what the held-out part and the
replicates say. It reads only the JSON keys, so it explains a saved result as well.
"""

from __future__ import annotations

import math
from typing import Any

from imubench.gap.curves import STAT_TESTS, stat_fired, t_threshold
from imubench.gap.diagnose import MIN_CLOSURE


def _f(v: float | None, digits: int = 3) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v:.{digits}g}"


def _pct(v: float | None) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v:.0%}"


def _detections(c: dict[str, Any], dof: int) -> list[str]:
    """The fit part's statistics beyond their thresholds (Student t with ``dof``)."""
    out = []
    for r in c["regions"]:
        out.append(f"Allan curve {r['direction'].replace('_', ' ')} over "
                   f"{_f(r['tau_min_s'])}-{_f(r['tau_max_s'])} s (largest |z| "
                   f"{abs(r['z_max']):.1f}, region gap {_f(r['gap'])})")
    for b in c.get("bands", []):
        out.append(f"spectrum {b['direction'].replace('_', ' ')} over "
                   f"{_f(b['f_min_hz'])}-{_f(b['f_max_hz'])} Hz")
    names = {"line_z": f"a spectral line at {_f(c['line']['f_hz'], 4)} Hz",
             "tail_z": "impulsive tails", "temp_z": "correlation with temperature",
             "trend_z": "a time trend"}
    for key, z_norm, one_sided in STAT_TESTS:
        z = _stat(c, key)
        if stat_fired(z, z_norm, one_sided, dof):
            out.append(f"{names[key]} (t {z:.1f} against the threshold "
                       f"{t_threshold(z_norm, dof):.1f})")
    return out


def _stat(c: dict[str, Any], key: str) -> float:
    """A :data:`STAT_TESTS` statistic from the JSON entry (NaN when absent or null)."""
    v = {"line_z": c["line"]["z"], "tail_z": c["impulses_z"],
         "temp_z": c["temperature_slope_z"], "trend_z": c["trend_z"]}[key]
    return float("nan") if v is None else float(v)


def _strongest(c: dict[str, Any], dof: int) -> str:
    """The statistic closest to its threshold, as 'name t/threshold' (for `none`)."""
    names = {"line_z": "line", "tail_z": "tails", "temp_z": "temperature", "trend_z": "trend"}
    ratios = []
    for key, z_norm, one_sided in STAT_TESTS:
        z = _stat(c, key)
        z = z if one_sided else abs(z)
        if math.isfinite(z):
            thr = t_threshold(z_norm, dof)
            ratios.append((z / thr, names[key], z, thr))
    if not ratios:
        return ""
    _, n, z, thr = max(ratios)
    return f"; the closest to its threshold is {n} (t {z:.1f} against {thr:.1f})"


def explain_channel(c: dict[str, Any], realisations: int) -> list[str]:
    """Sentences explaining the verdict of one channel's JSON entry."""
    dof = max(int(realisations) - 1, 1)
    lines: list[str] = []
    found = _detections(c, dof)
    verdict = c["verdict"]
    if found:
        lines.append("Significant on the fit part: " + "; ".join(found) + ".")
    else:
        lines.append("Nothing on the fit part exceeds its threshold (family-wise Allan and "
                     "band limits, line, tails, temperature, trend)"
                     + _strongest(c, dof) + ".")
    effects = c["effects"]
    if verdict == "none":
        lines.append("Verdict none: the model explains the recording within the scatter of "
                     f"{realisations} realisations.")
    elif verdict == "unexplained":
        best = effects[0] if effects else None
        if best is None:
            lines.append("Verdict unexplained: no candidate effect applies to this evidence.")
        else:
            lines.append(
                f"Verdict unexplained: the best candidate, {best['effect']}, removes "
                f"{_pct(best.get('evidence_closed'))} of the significant excess chi-squared "
                f"(the verdict needs {MIN_CLOSURE:.0%}, without raising the total); an "
                "effect outside the candidate list, or two at once, is likely.")
    else:
        w = effects[0]
        params = ", ".join(f"{k} = {_f(v, 4)}" for k, v in w["params"].items())
        txt = (f"Verdict {verdict} ({params}):"
               f" it removes {_pct(w.get('evidence_closed'))} of the significant excess "
               f"chi-squared (the verdict needs {MIN_CLOSURE:.0%}; "
               f"{_pct(w['chi2_closed'])} of the total) with score {w['score']:.1f}")
        if len(effects) > 1:
            r = effects[1]
            txt += (f"; the runner-up {r['effect']} scores {r['score']:.1f} (lower is better; "
                    f"BIC penalty ln(n) per parameter, {w['n_params']} against "
                    f"{r['n_params']})")
        lines.append(txt + ".")
    g0, ge = c.get("gap_null"), c.get("gap_excess_before")
    if g0 is not None and ge is not None:
        lines.append(
            f"Gap (RMS over all taus of ln ADEV_real/ADEV_sim) {_f(c['gap_before'])} -> "
            f"{_f(c['gap_after'])}. A perfect model would still show about {_f(g0)} "
            f"(the taus' scatter); the systematic part is {_f(ge)} -> "
            f"{_f(c.get('gap_excess_after'))}.")
    h = c.get("holdout")
    if h and h.get("gap_before") is not None and "region_gap_before" in h:
        txt = (f"Held-out part (never used for the fit): gap {_f(h['gap_before'])} -> "
               f"{_f(h['gap_after'])}, systematic {_f(h['gap_excess_before'])} -> "
               f"{_f(h['gap_excess_after'])}")
        if c["regions"]:
            txt += (f", over the fit part's regions {_f(h['region_gap_before'])} -> "
                    f"{_f(h['region_gap_after'])}")
        lines.append(txt + ".")
    reps = (h or {}).get("recordings", [])
    for r in reps:
        txt = f"Replicate {r['recording']}: gap {_f(r['gap_before'])} -> {_f(r['gap_after'])}"
        if r.get("gap_null") is not None:
            txt += (f" (a perfect model ~{_f(r['gap_null'])}, systematic "
                    f"{_f(r.get('gap_excess_before'))}; "
                    f"{'significant' if r.get('significant') else 'not significant'} "
                    "departures from the model)")
        lines.append(txt + ".")
    if verdict in ("none", "unexplained") and any(r.get("significant") for r in reps):
        lines.append("Replicates depart from the model beyond their scatter"
                     + (" although this recording does not" if verdict == "none" else "")
                     + ": recording-to-recording variation of the sensor, which no single "
                     "effect fitted to this recording captures.")
    return lines
