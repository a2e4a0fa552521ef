"""A spectral line chosen on the fit part and tested on the held-out part.

The comparisons' line test (:func:`imubench.gap.curves.line_peaks`, ``line_z``) looks at
the highest peak of one part among its ~n/2 periodogram bins, and a line must stand above
the largest of that many chi-squared(2) bins of the model's realisations. A line too weak
for that on either part is still seen twice at the same frequency: here the fit part
chooses where to look (its :data:`LINE_TOP` highest peaks above the first block of
:func:`~imubench.gap.curves.line_peaks`, by the same ratio to the continuum) and the
held-out part is tested there alone. The choice is made on one sample and the test on
another (the held-out check's own principle), so the test pays only for the few bins it
examines, not for the bins the choice passed over.

The statistic: at each chosen frequency, the held-out periodogram bin nearest to it and
its two neighbours, each against the mean of the :data:`NEIGHBOURS` bins on each side
(the :data:`NEAR` bins next to it left out, where a Hann-windowed line spreads). A
periodogram bin of a stationary Gaussian continuum is the PSD times chi-squared(2) / 2
(Brockwell & Davis, Time Series: Theory and Methods, 2nd ed. 1991, sec. 10.3), so a bin
over the mean of M independent ones of the same continuum is F(2, 2M):
``P(ratio > x) = (1 + x / M)^-M``. The Hann window's neighbouring bins are correlated
(power correlation 4/9 at one bin, 1/36 at two; measured here 0.443 and 0.027), so M is
the neighbours' count over :data:`HANN_BIN_SPREAD`. The smallest p-value of the ``m``
bins, Sidak-corrected (``1 - (1 - p)^m``), is given as a normal z. A continuum that
curves upward across the neighbourhood (flicker's 1/f, a random walk's 1/f^2) raises
the mean of the neighbours and makes the test conservative.

Measured on records of white 0.004 dps/sqrt(Hz) + flicker 0.0008 dps quantised to
8.75 mdps, 1 h (fit and held-out halves), 300 each at 52 and 104 Hz: z 95 % quantile
1.5-1.7, largest 2.8-3.2, none beyond :data:`Z_ACROSS`; a 1.5 mdps sine at 2-20 Hz at
52 Hz: z 5.4-7.5 at its frequency, 40 of 40; 1.2 mdps at 104 Hz: 37 of 40. The fit
part's own line test passes neither (an outside reviewer's 1.5 mdps at 4.1 Hz, 52 Hz:
line t 2.8 against 5.9).

The test is fired when z exceeds :data:`Z_ACROSS` and the same statistic of every
realisation of the model over the held-out part at the same bins (a line the model
carries shows in them). The lines of the model's own sine and of kept sines are left
out (``explained``).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.stats import norm

from .curves import LINE_CONTINUUM_BINS, Z_LINE, line_ratios, line_segment, welch_psd

LINE_TOP = 3
"""Peaks of the fit part examined on the held-out part (one is not always the line's: a
line 18x its continuum competes with the largest of ~10^5 noise bins, 10-17x)."""
NEIGHBOURS = 32
"""Bins on each side whose mean is a tested bin's continuum."""
NEAR = 2
"""Bins on each side of a tested bin left out of its continuum (a Hann-windowed line's
spread)."""
HANN_BIN_SPREAD = 1.0 + 2.0 * (4.0 / 9.0) + 2.0 * (1.0 / 36.0)
"""Neighbouring Hann periodogram bins per independent one: 1 + 2 sum of the power
correlations at one and two bins (4/9, 1/36)."""
Z_ACROSS = Z_LINE
"""Normal z beyond which the held-out part confirms a line (one test: the per-test rate
of the comparisons' line test, :data:`imubench.gap.curves.Z_LINE`)."""


def _periodogram(y: np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """The one-segment Hann periodogram the line tests use (unit^2/Hz)."""
    return welch_psd(y, rate_hz, line_segment(len(y)))


def _log_p(p: np.ndarray, j: np.ndarray) -> np.ndarray:
    """ln P(F(2, 2M) > ratio) of the bins ``j`` of periodogram(s) ``p`` (last axis):
    each against the mean of its neighbours (module docstring)."""
    off = np.r_[-NEIGHBOURS:-NEAR, NEAR + 1:NEIGHBOURS + 1]
    cont = p[..., j[:, None] + off[None, :]].mean(axis=-1)
    m_eff = len(off) / HANN_BIN_SPREAD
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(cont > 0, p[..., j] / cont, 0.0)
    return -m_eff * np.log1p(ratio / m_eff)


def _z_of(log_p: np.ndarray) -> np.ndarray:
    """Normal z of the smallest p-value along the last axis, Sidak-corrected for their
    number."""
    m = log_p.shape[-1]
    p_min = np.exp(log_p.min(axis=-1))
    p_fam = -np.expm1(m * np.log1p(-np.minimum(p_min, 1.0 - 1e-16)))
    return np.asarray(norm.isf(np.maximum(p_fam, 1e-300)))


@dataclass
class LineAcross:
    """The held-out part's test at the fit part's peaks (module docstring)."""

    f_hz: np.ndarray
    """Frequencies of the held-out bins tested (Hz)."""
    f_fit_hz: np.ndarray
    """The fit part's peak each tested bin was chosen by (Hz)."""
    log_p: np.ndarray
    """ln p-value of each tested bin of the record."""
    sims_log_p: np.ndarray
    """The same of each realisation (K x bins; none when no bin of the record reaches
    :data:`Z_ACROSS` even alone, so that the test cannot fire)."""

    def z(self, explained: tuple[tuple[float, float], ...] = ()
          ) -> tuple[float, float, float]:
        """(z, frequency of the bin that gives it, the fit part's peak that chose it; Hz)
        of the record over the tested bins outside the ``explained`` intervals (Hz);
        NaNs when none is left."""
        keep = self._outside(explained)
        if not keep.any():
            return math.nan, math.nan, math.nan
        lp = self.log_p[keep]
        i = int(np.argmin(lp))
        return float(_z_of(lp)), float(self.f_hz[keep][i]), float(self.f_fit_hz[keep][i])

    def fired(self, explained: tuple[tuple[float, float], ...] = ()) -> bool:
        """z beyond :data:`Z_ACROSS` and beyond every realisation's at the same bins."""
        z = self.z(explained)[0]
        if not z > Z_ACROSS:
            return False
        keep = self._outside(explained)
        return bool(z > float(np.max(_z_of(self.sims_log_p[:, keep]))))

    def _outside(self, explained: tuple[tuple[float, float], ...]) -> np.ndarray:
        keep = np.ones(len(self.f_hz), dtype=bool)
        for lo, hi in explained:
            keep &= ~((self.f_hz >= lo) & (self.f_hz <= hi))
        return keep


def line_across(fit_y: np.ndarray, hold_y: np.ndarray, sims_hold: np.ndarray,
                rate_hz: float, explained: tuple[tuple[float, float], ...] = ()
                ) -> LineAcross | None:
    """The test of the fit part's :data:`LINE_TOP` highest peaks (outside the
    ``explained`` intervals, Hz) on the held-out part ``hold_y``, and on each realisation's
    held-out part (``sims_hold``, K x len(hold_y)); None when a part is too short for
    two blocks of the line continuum."""
    f1, p1 = _periodogram(fit_y, rate_hz)
    r = line_ratios(p1)
    f2, p2 = _periodogram(hold_y, rate_hz)
    if r is None or len(p2) < 2 * LINE_CONTINUUM_BINS:
        return None
    df2 = float(f2[1] - f2[0])
    r = r.copy()
    r[:LINE_CONTINUUM_BINS] = np.nan
    for lo, hi in explained:
        r[(f1[:len(r)] >= lo) & (f1[:len(r)] <= hi)] = np.nan
    chosen: dict[int, float] = {}  # held-out bin: the fit part's peak (Hz)
    for _ in range(LINE_TOP):
        if not np.isfinite(r).any():
            break
        i = int(np.nanargmax(r))
        r[max(0, i - NEAR):i + NEAR + 1] = np.nan
        j = round(float(f1[i]) / df2)
        for k in (j - 1, j, j + 1):
            if NEIGHBOURS <= k < len(p2) - NEIGHBOURS:
                chosen.setdefault(k, float(f1[i]))
    if not chosen:
        return None
    tested = np.array(sorted(chosen))
    log_p = _log_p(p2, tested)
    if float(norm.isf(math.exp(float(log_p.min())))) > Z_ACROSS and len(sims_hold):
        sims_p = np.array([_periodogram(y, rate_hz)[1] for y in sims_hold])
        sims_log_p = _log_p(sims_p, tested)
    else:
        sims_log_p = np.zeros((1, len(tested)))  # p = 1: the record alone decides
    return LineAcross(f2[tested], np.array([chosen[int(k)] for k in tested]), log_p,
                      sims_log_p)


def explained_by(effect: str, params: Mapping[str, float], n_hold: int, rate_hz: float
                 ) -> tuple[float, float] | None:
    """The frequency interval (Hz) whose line a kept ``effect`` explains: a sine's
    frequency +- NEAR + 1 bins of the held-out part's periodogram (``n_hold`` samples);
    None for other effects (a resonance narrower than a few bins is refused as a line,
    :func:`imubench.gap.candidates.fit_candidates`, and a wider one leaves its
    neighbours' mean as high as its peak)."""
    if effect != "sine":
        return None
    half = (NEAR + 1) * rate_hz / line_segment(n_hold)
    f = params["sine_freq"]
    return f - half, f + half
