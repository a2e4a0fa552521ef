"""IEEE Std 952-1997 Annex C readouts of a channel for the report: N, B, K with intervals.

The three numbers a datasheet quotes, read as Annex C reads them on the sigma-tau plot:

- **N** (angle / velocity random walk): the slope -1/2 line read at tau = 1 s. The line is
  the fitted white-equivalent density, sigma(tau) = N / sqrt(tau) (C.2): white before and
  after the output filter and a Gauss-Markov term of short correlation time
  (:func:`imubench.noisefit.units.white_equivalent`), so the reading is that N and its
  interval the fit's 95 % interval of it.
- **B** (bias instability): the flat minimum of the *measured* Allan deviation divided by
  sqrt(2 ln2 / pi) = 0.664 (C.3), at the tau where it occurs. Its 95 % interval is the
  chi-squared interval of that OADEV point (EDF from :mod:`imubench.stats`, NIST SP 1065
  eq. 45) divided by the same factor. When the curve has no established floor (still
  falling, or no significant rise after the minimum) the reading is an upper bound
  (rule shared with the live readouts, :func:`imubench.fleet.readouts.read_terms`).
- **K** (rate / acceleration random walk): the slope +1/2 line read at tau = 3 s, the
  fitted random-walk term sigma(tau) = K sqrt(tau / 3) (C.4), so the fitted K with the
  fit's interval.

A term the fit judged absent is reported as ``upper`` with the fit's upper 95 % limit, or
``none`` when the fit carries no interval (a model file read with ``--model``: its values
have no intervals, and none are made up here).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imubench.fleet.readouts import read_terms
from imubench.noisefit.fit import ChannelFit
from imubench.noisefit.tangent import FLICKER_FLOOR
from imubench.noisefit.units import WHITE_EQUIVALENT, Quantity, quantities
from imubench.stats.result import StatResult

READ_TAU_S: dict[str, float] = {"N": 1.0, "K": 3.0}
"""Averaging time (s) at which Annex C reads the -1/2 (N) and +1/2 (K) lines."""
TERM_OF: dict[str, str] = {"N": WHITE_EQUIVALENT, "B": "flicker", "K": "random_walk"}
"""Readout symbol -> the coefficient (a model-file key, or the white-equivalent density)."""


@dataclass(frozen=True)
class Readout:
    """One IEEE 952 reading in model units (dps or g based).

    ``value`` the coefficient (N unit/sqrt(Hz), B unit, K unit/sqrt(s)); ``tau_s`` and
    ``dev`` the point of the sigma-tau plot it is read at (the marker); ``interval`` the
    95 % interval of ``value`` or None; ``kind`` ``value``, ``upper`` (value is an upper
    limit) or ``none`` (nothing to read); ``source`` where it comes from.
    """

    symbol: str
    value: float | None
    tau_s: float | None
    dev: float | None
    interval: tuple[float, float] | None
    kind: str
    source: str
    note: str = ""

    def scaled(self, quantity: Quantity) -> tuple[float | None, tuple[float, float] | None]:
        """Value and interval in ``quantity``'s datasheet unit."""
        f = quantity.factor
        value = None if self.value is None else self.value * f
        interval = None if self.interval is None else (self.interval[0] * f,
                                                       self.interval[1] * f)
        return value, interval

    def text(self, quantity: Quantity, *, unit: bool = True) -> str:
        """``value [low, high] unit`` in ``quantity``'s unit; an upper limit as
        ``< value``; ``no interval`` when there is none; ``-`` when nothing was read."""
        value, interval = self.scaled(quantity)
        u = f" {quantity.unit}" if unit else ""
        if value is None:
            return "-"
        if self.kind == "upper":
            return f"< {fmt(value)}{u}"
        if interval is None:
            return f"{fmt(value)} (no interval){u}"
        return f"{fmt_interval(value, *interval)}{u}"


def fmt(value: float) -> str:
    """Four significant digits (``%.4g``)."""
    return f"{value:.4g}"


def fmt_interval(value: float, low: float, high: float) -> str:
    """``value [low, high]`` with one number of decimals for all three, enough to give the
    narrower half of the interval two significant digits (so 0.2401 [0.2389, 0.2413], not
    0.24 [0.239, 0.241]); ``%.3g`` for values outside 1e-3 .. 1e6."""
    if not all(np.isfinite((value, low, high))) or not 1e-3 <= abs(value) < 1e6:
        return f"{fmt(value)} [{fmt(low)}, {fmt(high)}]"
    halves = [h for h in (value - low, high - value) if h > 0]
    spread = min(halves) if halves else abs(value) * 1e-3
    decimals = int(min(max(1 - np.floor(np.log10(spread)), 0), 6))
    if (low != 0 and float(f"{low:.{decimals}f}") == 0) or (
            high != 0 and float(f"{high:.{decimals}f}") == 0):
        # an interval over decades ([0.0076, 24.8]): fixed decimals would print 0.0
        return f"{fmt(value)} [{fmt(low)}, {fmt(high)}]"
    return f"{value:.{decimals}f} [{low:.{decimals}f}, {high:.{decimals}f}]"


def _line_reading(symbol: str, fit: ChannelFit) -> Readout:
    """N or K from the fitted terms' line (module docstring)."""
    key = TERM_OF[symbol]
    tau = READ_TAU_S[symbol]
    source = "model file" if fit.method == "model file" else "fit"
    v, ci = fit.coefficient(key)
    if v > 0:
        return Readout(symbol, v, tau, v, ci, "value", source,
                       f"{key} line read at tau = {tau:g} s")
    if ci is not None and ci[1] > 0:
        return Readout(symbol, ci[1], None, None, None, "upper", source,
                       f"{key} not detected: upper 95 % limit")
    return Readout(symbol, None, None, None, None, "none", source,
                   f"{key} not in the {source}")


def _floor_reading(curve: StatResult) -> Readout:
    """B from the flat minimum of the measured OADEV (module docstring)."""
    r = read_terms(curve.tau_s.tolist(), curve.dev.tolist(), curve.ci_low.tolist(),
                   curve.ci_high.tolist(), curve.alpha.tolist())["B"]
    if r["value"] is None or r["tau_s"] is None:
        return Readout("B", None, None, None, None, "none", "measured OADEV", r["note"])
    i = int(np.argmin(np.abs(curve.tau_s - r["tau_s"])))
    if r["kind"] == "upper":  # the bound read_terms made: the least upper limit / 0.664
        return Readout("B", float(r["value"]), float(curve.tau_s[i]), None, None, "upper",
                       "measured OADEV", r["note"])
    dev = float(curve.dev[i])
    lo, hi = float(curve.ci_low[i]), float(curve.ci_high[i])
    interval = (lo / FLICKER_FLOOR, hi / FLICKER_FLOOR) if np.isfinite(lo + hi) else None
    return Readout("B", dev / FLICKER_FLOOR, float(curve.tau_s[i]), dev, interval,
                   r["kind"], "measured OADEV minimum", r["note"])


def ieee952_readouts(fit: ChannelFit, curve: StatResult) -> dict[str, Readout]:
    """N, B, K of one channel: ``fit`` (fitted or read from a model file) and the
    channel's measured OADEV ``curve`` with its 95 % limits (``confidence=0.95``)."""
    return {"N": _line_reading("N", fit), "B": _floor_reading(curve),
            "K": _line_reading("K", fit)}


def readout_quantities(channel: str) -> dict[str, tuple[Quantity, ...]]:
    """Datasheet quantities each readout is shown in: N as density and random walk
    (mdps/sqrt(Hz) and deg/sqrt(h); ug/sqrt(Hz) and m/s/sqrt(h)), B in deg/h or ug, K in
    deg/h/sqrt(h) or ug/sqrt(s) (:mod:`imubench.noisefit.units`)."""
    qs = [q for q in quantities(channel) if not q.key.startswith("adev_floor")]
    return {sym: tuple(q for q in qs if q.term == term) for sym, term in TERM_OF.items()}


__all__ = ["READ_TAU_S", "TERM_OF", "Readout", "fmt", "fmt_interval", "ieee952_readouts",
           "readout_quantities"]
