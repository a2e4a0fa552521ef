"""One step of the forward selection (:mod:`imubench.gap.diagnose`): the current
realisations against the record, on the fit part, the held-out part and the whole record
(bias step, drift, temperature response, a line found again on the held-out part)."""

from __future__ import annotations

import functools
import math

import numpy as np
from lsm6ds_sim.model import ChannelModel

from imubench.gap import evidence
from imubench.gap.candidates import Candidate
from imubench.gap.curves import (
    POOLED_DOF,
    Z_SLOPE,
    line_z_cap,
    stat_fired,
    z_against,
)
from imubench.gap.line_across import explained_by, line_across
from imubench.gap.parts import PartSetup, RecordTemperature, Series

STEP_SIGMAS = 5.0
"""Largest normalised jump of block means that flags a bias step (it must also exceed
every realisation's). About 2000 differences of window means are tested
(:func:`imubench.gap.evidence.step_statistic`: widths 1-8 of 256 blocks, adjacent or one
block apart); Gaussian ones exceed 5 robust sigmas somewhere with probability ~1e-3 at
most (Bonferroni, two-sided, ``2 x 2000 Q(5)``; the wide windows' differences overlap and
are correlated, so fewer in effect)."""
Z_DRIFT = 3.5
"""Normal-equivalent threshold of the whole-record drift t (two-sided, as Student t)."""


class Step:
    """One step of the forward selection: the current realisations against the record.

    Besides the fit part's comparison, three whole-record tests: the bias step (the largest
    normalised jump of block means, :func:`imubench.gap.evidence.step_statistic`, fired
    when it exceeds STEP_SIGMAS and every realisation's; scored as its t against the
    realisations; record and realisations each less their own temperature response when
    the temperature test fired, :meth:`_for_step`), the drift
    (:func:`imubench.gap.evidence.drift_statistic` of the record minus the deterministic
    parts of the kept effects, self-normalised Student t) and the temperature response
    (:class:`imubench.gap.parts.RecordTemperature`, z against the realisations, fired
    beyond Z_SLOPE). With a held-out part, a fourth: a line at one of the fit part's
    highest peaks found again on the held-out part (:mod:`imubench.gap.line_across`;
    the lines of ``explained`` left out).
    """

    def __init__(self, fit: PartSetup, hold: PartSetup | None, sims: np.ndarray,
                 series: Series, temp: RecordTemperature, det_sum: np.ndarray | float,
                 noise: ChannelModel, explained: tuple[tuple[float, float], ...] = ()
                 ) -> None:
        n_fit = len(fit.series.y)
        rate = series.rate_hz
        self.det_sum = det_sum
        self.feats = fit.sim_features(sims[:, :n_fit])
        self.before = fit.compare(self.feats, noise)
        self.hold = (hold.compare(hold.sim_features(sims[:, n_fit:]), noise)
                     if hold is not None else None)
        self.fit_part = fit.less(det_sum if np.ndim(det_sum) == 0
                                 else np.asarray(det_sum)[:n_fit])
        """The fit part less the kept effects' deterministic parts (:meth:`PartSetup.less`),
        on which the candidates are fitted."""
        self.noise_feats = (self.feats if self.fit_part is fit
                            else self.fit_part.sim_features(sims[:, :n_fit]))
        """The realisations' features over the fit part, each less the kept effects'
        deterministic parts: the model's noise, against which the candidates are fitted.

        The comparisons of the record with the model (:attr:`before`, :attr:`hold`) keep
        those parts in both; a noise candidate fitted to the record's Allan variance less
        the model's with them in sees their Allan variance and its cross term with the
        noise, which differs from one realisation to the next, where the parts dominate.
        An outside reviewer's Markov sigma 4.6 mdps, tau_c 30 s, beside a temperature
        response of 6e-3 dps/degC on +-3 degC: once the response was kept the Markov
        term's share of the realisations' Allan variance at 3 tau_c was 0.23, most of it
        the response's (:func:`imubench.gap.candidates.markov_share`). Blind-generator
        pair Markov 4 mdps, 30 s beside 0.01 dps/degC: after the response, the Markov's
        descent beyond 3 tau_c was hidden the same way (fitted tau_c 49 s, not shown)
        and a random walk of 8.2e-4 dps/sqrt(s) was kept (3 seeds of 3); fitted on the
        record less the response, the Markov is kept beside it (sigma 3.9 mdps, tau_c
        22-33 s). The comparisons themselves keep the parts in: without them the error of
        a fitted response (5 % of 6e-3 dps/degC) showed as a held-out gap that a random
        walk's wide realisations covered, and the random walk was kept over temperature +
        Markov (:func:`imubench.gap.diagnose._better_start`)."""
        self.rate_hz = rate
        self.series_parts = (fit.series, None if hold is None else hold.series)
        """The fit and held-out parts' series (the latter None without a held-out part)."""
        self.residual = series.y - det_sum
        """The record less the kept effects' deterministic parts."""
        self.drift_t, self.drift_dof = evidence.drift_statistic(self.residual, rate)
        self.drift_fired = stat_fired(self.drift_t, Z_DRIFT, False, self.drift_dof)
        self.temp = temp.for_model(noise)
        """The whole-record temperature test under the covariance of the model's noise
        (``noise``: the base model's with the kept noise processes)."""
        self.temp_z = self.temp.z(self.residual, sims, det_sum)
        self.temp_fired = stat_fired(self.temp_z, Z_SLOPE, False, POOLED_DOF)
        self.step_y = self._for_step(self.residual[None, :])[0]
        """The record as the whole-record step test sees it (:meth:`_for_step`)."""
        self.step_real = evidence.step_statistic(self.step_y)[0]
        noise_sims = sims - det_sum  # as the record is in :attr:`residual` (one copy)
        step_sims = self._for_step(noise_sims)
        self.step_means = np.array([evidence.step_block_means(y) for y in step_sims])
        """The block means of the realisations as the step test sees them
        (:meth:`_for_step`): a step's persistence against the model's wander (K x
        :data:`imubench.gap.evidence.STEP_BLOCKS`; the realisations themselves, K x n,
        are not kept by the cached steps)."""
        sim_steps = np.array([evidence.step_statistic(y)[0] for y in step_sims])
        self.step_z = z_against(self.step_real, sim_steps)
        self.step_fired = bool(self.step_real > STEP_SIGMAS
                               and self.step_real > float(np.max(sim_steps)))
        self.explained = explained
        """Frequency intervals (Hz) of the lines the model's own sine and the kept effects
        explain (:meth:`imubench.gap.diagnose._Realiser.explained`)."""
        self.across = (None if hold is None else line_across(
            self.residual[:n_fit], self.residual[n_fit:], noise_sims[:, n_fit:], rate,
            explained))
        """The held-out part's test at the fit part's highest peaks (None without a
        held-out part or where it is too short)."""
        self.across_z, self.across_f_hz, self.across_f_fit_hz = (
            (math.nan,) * 3 if self.across is None else self.across.z(explained))
        self.across_fired = self.across is not None and self.across.fired(explained)

    @functools.cached_property
    def noise_sigma(self) -> np.ndarray:
        """The one-sigma band (ln ADEV per tau) of the fit part less the kept effects'
        deterministic parts against :attr:`noise_feats`: the weights of the candidates'
        Allan-curve fits, made in that frame. The band of :attr:`before` (parts in) is
        narrow at the long taus where a kept response dominates every realisation alike,
        and there a record's ln AVAR of few degrees of freedom lies below ln E[AVAR]
        (E ln(chi2_nu / nu) = -0.58 at nu = 2), which such weights then follow. An
        outside reviewer's random walk 3e-4 dps/sqrt(s) kept after a temperature response
        of 3e-3 dps/degC, three records: 2.03, 1.65, 2.19e-4 with those weights, 2.25,
        1.76, 2.27e-4 with these. (The rest of the shortfall is the records': their fit
        halves less the true response have ADEVs of 0.69, 0.23 and 0.74 of the truth's
        at 300 s.)"""
        if self.noise_feats is self.feats:  # nothing kept with a deterministic part
            return self.before.sigma
        return self.fit_part.compare(self.noise_feats).sigma

    def hold_drift(self) -> tuple[float, int]:
        """The held-out part's own drift test (:func:`imubench.gap.evidence.
        drift_statistic` of the record less the kept effects' deterministic parts, over
        the held-out samples): its t and degrees of freedom; NaN without a held-out
        part."""
        fit_part, hold_part = self.series_parts
        if hold_part is None:
            return math.nan, 1
        return evidence.drift_statistic(self.residual[len(fit_part.y):], self.rate_hz)

    def _for_step(self, ys: np.ndarray) -> np.ndarray:
        """``ys`` as the step test sees them: less the kept effects' deterministic parts
        (done by the caller for the record) and, when the temperature test fired, less
        each one's own temperature response (:meth:`RecordTemperature.less_response`),
        fitted beside a step at the place a first pass locates in each (the largest one
        it then sees). A temperature response widens the block means' increments and
        hid a step: a kept one hid a second effect's step (CATS gy, bias step +
        temperature at 2x their limits), an unmodelled one let a random walk take the
        step's excess first (CATS az seg 1; ax seg 2 still keeps the walk)."""
        if not self.temp_fired:
            return ys
        first = self.temp.less_response(ys)
        out = np.empty_like(first)
        for k, y in enumerate(first):
            at = round(evidence.fit_bias_step(y, self.rate_hz).step_time_s * self.rate_hz)
            out[k] = self.temp.less_response(ys[k:k + 1], step_at=at)[0]
        return out

    def explains_across(self, c: Candidate) -> bool:
        """The held-out line test fired at this step at a frequency whose line ``c``
        explains (a sine there)."""
        hold = self.series_parts[1]
        if not self.across_fired or hold is None:
            return False
        span = explained_by(c.effect, c.params, len(hold.y), self.rate_hz)
        return span is not None and span[0] <= self.across_f_hz <= span[1]

    def across_without(self, c: Candidate) -> float:
        """The held-out line test's z with the line ``c`` explains left out as well (its
        z at this step for an effect that explains none)."""
        if self.across is None:
            return math.nan
        hold = self.series_parts[1]
        assert hold is not None
        more = explained_by(c.effect, c.params, len(hold.y), self.rate_hz)
        return self.across_z if more is None else self.across.z((*self.explained, more))[0]

    def step_stats(self, sims: np.ndarray) -> np.ndarray:
        """The step statistic of each realisation, seen as the record is (:meth:`_for_step`)."""
        ys = self._for_step(sims - self.det_sum)
        return np.array([evidence.step_statistic(y)[0] for y in ys])

    @property
    def record_fired(self) -> bool:
        """A whole-record test fired (bias step, drift, temperature or the held-out
        line)."""
        return self.step_fired or self.drift_fired or self.temp_fired or self.across_fired

    @property
    def significant(self) -> bool:
        return self.before.significant or self.record_fired

    @property
    def fired(self) -> list[str]:
        """The tests that fire, by the JSON's names: the fit part's
        (:attr:`~imubench.gap.curves.Comparison.fired`) and the whole-record ones
        (``bias_step_z``, ``drift_t``, ``temperature_record_z``, ``line_across_z``, as in
        ``whole_record_after``)."""
        return self.before.fired + [name for name, hit in (
            ("bias_step_z", self.step_fired), ("drift_t", self.drift_fired),
            ("temperature_record_z", self.temp_fired), ("line_across_z", self.across_fired))
            if hit]

    def _record_excess(self, step_z: float, drift_t: float, temp_z: float,
                       across_z: float) -> float:
        e = 0.0
        if self.across_fired and math.isfinite(across_z):
            e += max(min(across_z, self.across_cap) ** 2 - 1.0, 0.0)
        if self.step_fired and math.isfinite(step_z):
            e += max(max(step_z, 0.0) ** 2 - 1.0, 0.0)
        if self.drift_fired and math.isfinite(drift_t):
            e += max(drift_t**2 - 1.0, 0.0)
        if self.temp_fired and math.isfinite(temp_z):
            e += max(temp_z**2 - 1.0, 0.0)
        return e

    def evidence_closed(self, c: Candidate) -> float:
        """Share of the significant excess (fit part and whole-record tests) removed."""
        assert c.fit is not None
        zb = self.before._fired_z(self.before)
        za = c.fit._fired_z(self.before)
        e0 = float(np.sum(np.maximum(zb * zb - 1.0, 0.0)))
        e1 = float(np.sum(np.maximum(za * za - 1.0, 0.0)))
        e0 += self._record_excess(self.step_z, self.drift_t, self.temp_z, self.across_z)
        e1 += self._record_excess(c.step_z, c.drift_t, c.temp_record_z, c.across_z)
        return 1.0 - e1 / e0 if e0 > 0 else float("nan")

    @property
    def across_cap(self) -> float:
        """The largest held-out line z the chi-squared counts: the comparisons' line cap
        (:func:`imubench.gap.curves.line_z_cap`), so that a sine gains no more from a line
        seen on both parts than from one seen on the fit part."""
        return line_z_cap(self.before.realisations)

    def record_chi2(self, step_z: float, drift_t: float, temp_z: float,
                    across_z: float) -> float:
        """The whole-record tests' chi-squared at these values (this step's, or a
        candidate's); the held-out line counts where it fired at this step, capped
        (:attr:`across_cap`)."""
        across = (min(max(across_z, 0.0), self.across_cap) ** 2
                  if self.across_fired and math.isfinite(across_z) else 0.0)
        return ((max(step_z, 0.0) ** 2 if math.isfinite(step_z) else 0.0)
                + (drift_t**2 if math.isfinite(drift_t) else 0.0)
                + (temp_z**2 if math.isfinite(temp_z) else 0.0) + across)

    def chi2(self) -> float:
        return self.before.chi2 + self.record_chi2(self.step_z, self.drift_t, self.temp_z,
                                                   self.across_z)
