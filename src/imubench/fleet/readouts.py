"""Noise readouts of a live Allan deviation curve, in datasheet units.

The tangent (slope-line) reading of IEEE Std 952-1997 Annex C, the same rule as
:func:`imubench.noisefit.tangent.tangent_readings` (one implementation):

- N (angle/velocity random walk): the line of slope -1/2 through the point whose local
  slope is nearest -1/2 left of the minimum, read at tau = 1 s: N = sigma(t) sqrt(t);
- B (bias instability): the flat minimum divided by sqrt(2 ln2 / pi) = 0.664;
- K (rate random walk): the line of slope +1/2 through the point whose local slope is
  nearest +1/2 right of the minimum, read at tau = 3 s: K = sigma(t) sqrt(3 / t).

A live curve is often incomplete and its long-tau end noisy, so each reading says what it
is (``kind``): ``value``; ``upper`` for B while the floor is not established: the curve
is still falling, or rises from its first tau, or its rise after the minimum is within
the confidence intervals (no later point has ``ci_low`` above the minimum's
``ci_high``): B is then at most the least upper confidence limit over the curve / 0.664
(the least point itself lies below the true curve by chance); ``none`` for N or K when no
point's slope is within :data:`SLOPE_TOLERANCE` of -1/2 or +1/2, and for K also when the
rise it would be read on is not significant in that sense. A number is never shown for a
term the curve does not show; without confidence limits B is only an upper bound and K is
not read.

Datasheet units come from :func:`imubench.noisefit.units.datasheet_units` (gyro in dps:
N mdps/sqrt(Hz) and deg/sqrt(h), B deg/h, K deg/h/sqrt(h); accel in g: N ug/sqrt(Hz),
B ug, K ug/sqrt(s)).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from imubench.noisefit.identify import local_slopes
from imubench.noisefit.tangent import FLICKER_FLOOR, tangent_readings
from imubench.noisefit.units import ACCEL, GYRO, datasheet_units

SLOPE_TOLERANCE: float = 0.2
"""Largest |local slope - (-1/2 or +1/2)| at which N or K is read."""

MIN_POINTS: int = 3
"""Fewest finite taus before anything is read."""

# (term, datasheet_units key, display unit, second key or None, second unit)
_GYRO_UNITS = (
    ("N", "noise_density_mdps_per_sqrt_hz", "mdps/√Hz", "arw_deg_per_sqrt_h", "°/√h"),
    ("B", "bias_instability_deg_per_h", "°/h", None, ""),
    ("K", "rrw_deg_per_h_per_sqrt_h", "°/h/√h", None, ""),
)
_ACCEL_UNITS = (
    ("N", "noise_density_ug_per_sqrt_hz", "µg/√Hz", "vrw_m_per_s_per_sqrt_h", "m/s/√h"),
    ("B", "bias_instability_ug", "µg", None, ""),
    ("K", "random_walk_ug_per_sqrt_s", "µg/√s", None, ""),
)
_PARAM = {"N": "white", "B": "flicker", "K": "random_walk"}


def _column(values: Sequence[Any] | None, n: int) -> np.ndarray:
    """A JSON list as float64 of length ``n`` (None, missing or short -> NaN)."""
    out = np.full(n, np.nan)
    if values is not None:
        for i, v in enumerate(list(values)[:n]):
            if v is not None:
                out[i] = float(v)
    return out


def read_terms(tau_s: Sequence[Any], dev: Sequence[Any],
               ci_low: Sequence[Any] | None = None, ci_high: Sequence[Any] | None = None,
               alpha: Sequence[Any] | None = None) -> dict[str, dict[str, Any]]:
    """N, B, K of one channel's ADEV curve in its own units (module docstring).

    ``tau_s``, ``dev``, ``ci_low``, ``ci_high``: the published lists (JSON nulls allowed);
    ``alpha``: the noise type identified at each tau, when known: B's upper bound leaves
    out points identified as phase noise (alpha > 0), whose chi-squared intervals assume a
    noise that decorrelates within a few samples (a flicker-dominated long tau identified
    as white PM got 101 degrees of freedom where the record held ~5 averages, and the
    bound fell below the true B on 1 of 20 2 h records; 0 of 20 without such points).
    Returns ``{"N"|"B"|"K": {"value": float | None, "kind": "value"|"upper"|"none",
    "tau_s": the tau read at | None, "slope": local slope there | None, "note": str}}``.
    """
    n = len(tau_s)
    cols = np.vstack([_column(tau_s, n), _column(dev, n), _column(ci_low, n),
                      _column(ci_high, n), _column(alpha, n)])
    keep = np.isfinite(cols[0]) & np.isfinite(cols[1]) & (cols[0] > 0) & (cols[1] > 0)
    tau, dev_arr, lo, hi, ids = cols[:, keep][:, np.argsort(cols[0, keep])]
    if tau.size < MIN_POINTS:
        note = f"{tau.size} tau(s) so far; readouts need {MIN_POINTS}"
        return {t: {"value": None, "kind": "none", "tau_s": None, "slope": None, "note": note}
                for t in _PARAM}
    slope = local_slopes(tau, dev_arr)
    picks = tangent_readings(tau, dev_arr)
    i_min = picks["flicker"][1]
    risen = lo > hi[i_min]  # significantly above the minimum (NaN compares False)
    out: dict[str, dict[str, Any]] = {}
    for term, key in _PARAM.items():
        values, i = picks[key]
        s = float(slope[i])
        entry = {"value": float(values[i]), "kind": "value", "tau_s": float(tau[i]),
                 "slope": s, "note": f"read at tau = {tau[i]:.4g} s (slope {s:+.2f})"}
        if term == "N" and abs(s + 0.5) > SLOPE_TOLERANCE:
            entry.update(value=None, kind="none",
                         note=f"no -1/2 slope region (nearest {s:+.2f} at {tau[i]:.4g} s)")
        elif term == "B" and (i == 0 or not risen[i + 1:].any()):
            where = ("rising from the first tau" if i == 0 else "still falling"
                     if i == tau.size - 1 else "not significantly rising after its minimum")
            # the bound is the least upper confidence limit, not the least point: the
            # lowest of many points (the last ones of few degrees of freedom) lies below
            # the true curve by chance, and B = min / 0.664 read 0.37-0.75 of the truth
            ok = np.isfinite(hi) & ~(ids > 0)  # NaN (not known) compares False
            j = int(np.argmin(np.where(ok, hi, np.inf))) if ok.any() else i
            bound = float(hi[j]) if ok.any() else float(dev_arr[i])
            entry.update(kind="upper", value=bound / FLICKER_FLOOR, tau_s=float(tau[j]),
                         slope=float(slope[j]),
                         note=f"curve {where}: floor not established; B at most the "
                              f"least upper confidence limit / 0.664 (at tau = "
                              f"{tau[j]:.4g} s)")
        elif term == "K" and (abs(s - 0.5) > SLOPE_TOLERANCE or not risen[i]):
            entry.update(value=None, kind="none",
                         note=f"no significant +1/2 slope region yet (nearest {s:+.2f} at "
                              f"{tau[i]:.4g} s)")
        out[term] = entry
    return out


def _fmt(value: float) -> str:
    return f"{value:.3g}" if math.isfinite(value) else "-"


def channel_readouts(channel: str, curve: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Display rows for one channel's published curve (``tau_s``, ``dev``, ``ci_low``,
    ``ci_high``, ``units``): ``[{"term", "kind", "value", "unit", "text", "note",
    "tau_s"}]`` with values in datasheet units when ``units`` is the model unit of the
    channel (dps for gyro, g for accel), else in the curve's own units."""
    terms = read_terms(curve.get("tau_s") or [], curve.get("dev") or [],
                       curve.get("ci_low"), curve.get("ci_high"), curve.get("alpha"))
    units = str(curve.get("units"))
    table = (_GYRO_UNITS if channel in GYRO and units == "dps"
             else _ACCEL_UNITS if channel in ACCEL and units == "g" else None)
    rows: list[dict[str, Any]] = []
    if table is None:
        native = {"N": f"{units}/√Hz", "B": units, "K": f"{units}/√s"}
        for term, r in terms.items():
            v = r["value"]
            rows.append({"term": term, "kind": r["kind"], "value": v, "unit": native[term],
                         "text": "-" if v is None else f"{_fmt(v)} {native[term]}",
                         "note": r["note"], "tau_s": r["tau_s"]})
        return rows
    params = {_PARAM[t]: (r["value"] or 0.0) for t, r in terms.items()}
    ds = datasheet_units(channel, params)
    for term, key, unit, key2, unit2 in table:
        r = terms[term]
        if r["value"] is None:
            rows.append({"term": term, "kind": "none", "value": None, "unit": unit,
                         "text": "-", "note": r["note"], "tau_s": None})
            continue
        text = ("≤ " if r["kind"] == "upper" else "") + f"{_fmt(ds[key])} {unit}"
        if key2 is not None:
            text += f" ({_fmt(ds[key2])} {unit2})"
        rows.append({"term": term, "kind": r["kind"], "value": ds[key], "unit": unit,
                     "text": text, "note": r["note"], "tau_s": r["tau_s"]})
    return rows


READOUT_STATS: tuple[str, ...] = ("oadev", "adev")
"""Statistics the readouts are taken from, in order of preference (IEEE 952 uses ADEV)."""


def sensor_readouts(statistics: Mapping[str, Mapping[str, Mapping[str, Any]]]
                    ) -> dict[str, Any]:
    """Readouts of every channel from the first of :data:`READOUT_STATS` published:
    ``{"statistic": name | None, "channels": {ch: rows}, "note": str}``."""
    for stat in READOUT_STATS:
        chans = statistics.get(stat)
        if chans:
            return {"statistic": stat, "note": f"tangent readings on {stat.upper()}",
                    "channels": {ch: channel_readouts(ch, c) for ch, c in chans.items()}}
    return {"statistic": None, "channels": {},
            "note": "no OADEV or ADEV published: add oadev to allan.stats for readouts"}


__all__ = ["MIN_POINTS", "READOUT_STATS", "SLOPE_TOLERANCE", "channel_readouts",
           "read_terms", "sensor_readouts"]
