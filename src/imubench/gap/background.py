"""How much a real recording differs from itself, and whether a gap is within that.

A model fitted on one stretch of a sensor's output never matches another stretch (or
another recording of the same sensor) to the scatter of K realisations: real sensors
change a little between power-ups, and slowly within a record. Those differences are
not an unmodelled effect. Two estimates of their size, per Allan tau and per spectral
band, in units of the comparison's own one-sigma band (z units):

* **replicates** (``--holdout REC``): other recordings of the same sensor compared with
  the same model. Two recordings of one stationary sensor give ``z_this - z_rep`` of
  variance ~2, so ``v^2 = mean_r max(0, (z_this - z_rep)^2 - 2) / 2`` is the excess
  recording-to-recording variation. A departure the replicates share (the same sign at
  the same taus: a consistent model error, or an effect of the sensor) gives ``v ~ 0``
  and stays significant; only departures that differ between recordings are absorbed.
* **halves**: the fit part against the held-out part of the same record, the same
  formula with ``z_hold`` for ``z_rep`` (zero for a stationary record, however far it is
  from the model).

A difference is **within** the background when, at every term that fired (the taus of the
regions, or every tau when the whole-curve test fired, and the bands of the band runs),
``|z| / sqrt(1 + v^2) <= Z_WITHIN`` and no single-statistic test (line, tails,
temperature, trend) fired: those are not covered by a curve-level background.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from imubench.gap.curves import STAT_TESTS, Comparison, stat_dof, stat_fired

Z_WITHIN = 2.0
"""|z| against the background-inflated band below which a fired term counts as
recording variation (the region edge level of :data:`imubench.gap.curves.Z_EDGE`)."""


def _match(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (i, j) with a[i] ~ b[j] (log ratio below 0.2), nearest first."""
    ia, ib = [], []
    for i, x in enumerate(a):
        if not (np.isfinite(x) and x > 0) or b.size == 0:
            continue
        r = np.abs(np.log(np.maximum(b, 1e-300) / x))
        j = int(np.argmin(r))
        if r[j] < 0.2:
            ia.append(i)
            ib.append(j)
    return np.asarray(ia, dtype=int), np.asarray(ib, dtype=int)


@dataclass
class Background:
    """Excess self-variation (z units) per tau and per band of one comparison's grid."""

    source: str
    """``replicates`` or ``halves``."""
    v_tau: np.ndarray
    v_band: np.ndarray

    def merge(self, other: Background | None) -> Background:
        if other is None:
            return self
        return Background(f"{self.source}+{other.source}", np.maximum(self.v_tau, other.v_tau),
                          np.maximum(self.v_band, other.v_band))


def _excess(this_z: np.ndarray, this_x: np.ndarray, other: list[tuple[np.ndarray, np.ndarray]]
            ) -> np.ndarray:
    """sqrt(mean over ``other`` of max(0, (z_this - z_other)^2 - 2) / 2) on this grid."""
    acc = np.zeros(this_x.size)
    cnt = np.zeros(this_x.size)
    for x, z in other:
        i, j = _match(this_x, x)
        dz = np.nan_to_num(this_z[i] - z[j], nan=0.0)
        acc[i] += np.maximum(dz * dz - 2.0, 0.0) / 2.0
        cnt[i] += 1
    return np.sqrt(acc / np.maximum(cnt, 1))


def from_replicates(this: Comparison, reps: list[Comparison]) -> Background | None:
    """Recording-to-recording variation on ``this``'s taus and bands (None without reps)."""
    if not reps:
        return None
    return Background("replicates",
                      _excess(this.z, this.tau_s, [(r.tau_s, r.z) for r in reps]),
                      _excess(this.band_z, this.band_f_hz,
                              [(r.band_f_hz, r.band_z) for r in reps]))


def from_halves(fit: Comparison, hold: Comparison) -> Background:
    """Excess difference between the two parts of one record, on the fit part's grid."""
    return Background("halves", _excess(fit.z, fit.tau_s, [(hold.tau_s, hold.z)]),
                      _excess(fit.band_z, fit.band_f_hz, [(hold.band_f_hz, hold.band_z)]))


def fired_masks(c: Comparison) -> tuple[np.ndarray, np.ndarray]:
    """(taus, bands) that fired in ``c``: region taus (all taus when the global test
    fired) and the bands of the band runs."""
    taus = np.zeros(c.tau_s.size, dtype=bool)
    if c.global_fired:
        taus[:] = True
    for r in c.regions:
        taus |= (c.tau_s >= r.tau_min_s * 0.999) & (c.tau_s <= r.tau_max_s * 1.001)
    bands = np.zeros(c.band_f_hz.size, dtype=bool)
    for b in c.bands:
        bands |= (c.band_f_hz >= float(b["f_min_hz"])) & (c.band_f_hz <= float(b["f_max_hz"]))
    return taus, bands


def within(c: Comparison, bg: Background) -> bool:
    """Whether every fired curve term of ``c`` is within ``bg`` and no statistic fired."""
    dof = c.realisations - 1
    if any(stat_fired(getattr(c, name), z_norm, one_sided, stat_dof(name, dof))
           for name, z_norm, one_sided in STAT_TESTS):
        return False
    taus, bands = fired_masks(c)
    zt = np.abs(c.z) / np.sqrt(1.0 + bg.v_tau**2)
    zb = np.abs(c.band_z) / np.sqrt(1.0 + bg.v_band**2)
    worst = np.concatenate([zt[taus & np.isfinite(zt)], zb[bands & np.isfinite(zb)]])
    return bool(worst.size == 0 or float(worst.max()) <= Z_WITHIN)


def summary(c: Comparison, bg: Background) -> dict[str, Any]:
    """JSON block: source, whether within, where (fired taus), largest background (z)."""
    taus, _ = fired_masks(c)
    sel = c.tau_s[taus]
    return {"source": bg.source, "within": within(c, bg),
            "tau_min_s": float(sel.min()) if sel.size else math.nan,
            "tau_max_s": float(sel.max()) if sel.size else math.nan,
            "v_tau_max": float(np.max(bg.v_tau)) if bg.v_tau.size else 0.0,
            "v_band_max": float(np.max(bg.v_band)) if bg.v_band.size else 0.0}
