"""Which unmodelled effect makes the simulated sensor depart from the real one.

For one channel: simulate K realisations of the model over the record's length, rate and
temperature history (:mod:`imubench.gap.curves` compares them with the real record on the
fit part); fit each candidate effect to the REAL fit part with the evidence that suits it
(:mod:`imubench.gap.evidence`, :mod:`imubench.gap.avarfit`); re-simulate with the effect
added (same seeds: common random numbers, so candidates differ only by their effect);
rank by the score ``chi2_after + ln(n_terms) * n_params`` (Schwarz's BIC penalty per
added parameter, Schwarz 1978, Ann. Statist. 6(2)); report the winner's and the
runners-up's gap before/after on the fit part and on the held-out part.

Verdict: ``none`` when nothing on the fit part is significant, ``unexplained`` when the
best candidate removes less than :data:`MIN_CLOSURE` of the significant excess chi-squared
(:meth:`~imubench.gap.curves.Comparison.evidence_closed`: over the terms that fired) or
raises the total chi-squared, else the winning effect's name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from lsm6ds_sim.model import ChannelModel, NoiseModel
from lsm6ds_sim.physics import simulate
from lsm6ds_sim.temperature import ReplayTemperature

from imubench.gap import avarfit, evidence
from imubench.gap.curves import (
    Comparison,
    Features,
    SimFeatures,
    analysis_afs,
    band_edges,
    compare,
    features,
    line_segment,
    psd_segment,
    stack,
    t_threshold,
    welch_psd,
)
from imubench.gap.errors import GapError
from imubench.noisefit.covariance import oavar_correlation
from imubench.stats import oadev

EFFECTS: tuple[str, ...] = (
    "flicker", "random_walk", "ramp", "quantization", "markov", "sine", "temperature",
    "outliers", "filter",
)
"""Candidate effects, by the names the JSON uses."""
MAIN_PARAM: dict[str, str] = {
    "flicker": "flicker", "random_walk": "random_walk", "ramp": "ramp",
    "quantization": "quantization", "markov": "markov_sigma", "sine": "sine_amplitude",
    "temperature": "temp_coeff", "outliers": "outlier_rate", "filter": "bandwidth_hz",
}
"""The model-file key that measures each effect's size (used for parameter errors)."""
MIN_CLOSURE = 0.5
"""Fraction of the significant excess chi-squared (over the taus, bands and statistics that
fired on the fit part) the best candidate must remove, else unexplained. Measured over the
fired terms only since 2026-11-21: over all terms, the sub-threshold scatter a loose base
model leaves (a noise fit of a real recording) counted as gap no single effect could
remove, and a clear added sine (line t 7.3) or temperature (t 7.5) on the real ADIS hour
came out `unexplained`."""
MARKOV_SPAN = 15.0
"""A Markov candidate needs its tau_c at most the longest analysed tau / MARKOV_SPAN.

Gauss-Markov ADEV peaks near 1.9 tau_c and falls as tau^-1/2 beyond ~3 tau_c (IEEE 952
C.6); only that descent, seen over a factor 5 in tau (3 to 15 tau_c, a factor 2.2 in
ADEV), tells it from flicker (flat) or random walk (rising), which have one parameter
fewer. A longer tau_c is reported as those."""
Z_TEMP_CANDIDATE = 2.5
"""The temperature candidate needs |temp_z| (the correlation of the block means'
INCREMENTS with the temperature's, against the realisations') above this normal-
equivalent z (as Student t with K - 1 dof). A random walk or flicker level correlates
with any slow temperature history in levels, and then a temperature coefficient closes
a rising Allan curve as well as the random walk does; only a correlation of the
prewhitened (differenced) series beyond the realisations' chance level is evidence."""
HOLDOUT_TOP = 3
"""Effects (winner and runners-up) re-checked on the held-out part and replicates."""


@dataclass(frozen=True)
class GapOptions:
    """Knobs of the diagnosis (CLI flags)."""

    realisations: int = 10
    seed: int = 0
    holdout_fraction: float = 0.5
    effects: tuple[str, ...] = EFFECTS

    def __post_init__(self) -> None:
        if not 0.0 <= self.holdout_fraction < 1.0:
            raise GapError(
                f"--holdout-fraction must be in [0, 1), got {self.holdout_fraction!r}"
            )
        if self.realisations < 3:
            raise GapError(f"--realisations must be >= 3, got {self.realisations!r}")
        bad = [e for e in self.effects if e not in EFFECTS]
        if bad:
            raise GapError(f"unknown effect(s) {bad}; candidates are {', '.join(EFFECTS)}")


@dataclass
class Series:
    """One channel of one record: rate samples, temperature (or None), rate."""

    y: np.ndarray
    temp_c: np.ndarray | None
    rate_hz: float
    name: str = "<record>"

    def part(self, start: int, stop: int) -> Series:
        t = None if self.temp_c is None else self.temp_c[start:stop]
        return Series(self.y[start:stop], t, self.rate_hz, self.name)

    @property
    def has_temperature(self) -> bool:
        return self.temp_c is not None and bool(np.isfinite(self.temp_c).sum() > 1)


@dataclass
class Candidate:
    effect: str
    params: dict[str, float]
    """Model-file keys with their values AFTER adding the effect."""
    n_params: int
    fit: Comparison | None = None
    holdout: Comparison | None = None
    replicates: list[Comparison] = field(default_factory=list)
    score: float = math.inf
    closure: float = 0.0
    """Share of the total excess chi-squared removed (all taus, bands, statistics)."""
    evidence_closed: float = float("nan")
    """Share of the significant excess chi-squared removed (the verdict's criterion)."""

    def to_dict(self, before: Comparison, holdout_before: Comparison | None) -> dict[str, Any]:
        assert self.fit is not None
        d: dict[str, Any] = {
            "effect": self.effect,
            "params": self.params,
            "gap_after": self.fit.gap,
            "n_params": self.n_params,
            "score": self.score,
            "chi2_closed": self.closure,
            "evidence_closed": self.evidence_closed,
            "gap_closed": 1.0 - self.fit.gap / before.gap if before.gap > 0 else 0.0,
            "gap_excess_after": self.fit.gap_excess,
        }
        if self.holdout is not None and holdout_before is not None:
            d["holdout_gap_after"] = self.holdout.gap
            d["holdout_gap_excess_after"] = self.holdout.gap_excess
        return d


@dataclass
class ChannelDiagnosis:
    channel: str
    before: Comparison
    holdout_before: Comparison | None
    candidates: list[Candidate]
    verdict: str
    evidence: dict[str, Any]
    replicates: list[tuple[str, Comparison, Comparison | None]] = field(default_factory=list)

    @property
    def winner(self) -> Candidate | None:
        if self.verdict in ("none", "unexplained"):
            return None
        return self.candidates[0]

    def to_dict(self) -> dict[str, Any]:
        w = self.winner
        after = w.fit.gap if w is not None and w.fit is not None else self.before.gap
        out: dict[str, Any] = {
            "gap_before": self.before.gap,
            "significant": self.before.significant,
            "regions": [r.to_dict() for r in self.before.regions],
            "effects": [c.to_dict(self.before, self.holdout_before) for c in self.candidates],
            "verdict": self.verdict,
            "gap_after": after,
            "gap_null": self.before.gap_null,
            "gap_excess_before": self.before.gap_excess,
            "gap_excess_after": (w.fit.gap_excess if w is not None and w.fit is not None
                                 else self.before.gap_excess),
            "holdout": None,
            "bands": self.before.bands,
            "line": {"f_hz": self.before.line_f_hz, "z": self.before.line_z},
            "impulses_z": self.before.tail_z,
            "temperature_slope_z": self.before.temp_z,
            "trend_z": self.before.trend_z,
            "global": self.before.global_dict(),
        }
        regions = self.before.regions
        for rd, r in zip(out["regions"], regions, strict=True):
            rd["gap_after"] = (w.fit.gap_over(r.tau_min_s, r.tau_max_s)
                               if w is not None and w.fit is not None else rd["gap"])
        if self.holdout_before is not None:
            hb = self.holdout_before
            ha = w.holdout if w is not None and w.holdout is not None else hb
            out["holdout"] = {
                "gap_before": hb.gap, "gap_after": ha.gap,
                "region_gap_before": hb.region_gap(regions),
                "region_gap_after": ha.region_gap(regions),
                "chi2_closed": ha.excess_closed(hb) if w is not None else 0.0,
                "gap_null": hb.gap_null,
                "gap_excess_before": hb.gap_excess,
                "gap_excess_after": ha.gap_excess,
            }
        if self.replicates:
            reps = [{"recording": name, "gap_before": b.gap,
                     "gap_after": (a.gap if a is not None else b.gap),
                     "gap_null": b.gap_null, "gap_excess_before": b.gap_excess,
                     "significant": b.significant}
                    for name, b, a in self.replicates]
            out["holdout"] = dict(out["holdout"] or {})
            out["holdout"]["recordings"] = reps
        return out


def _seeds(seed: int, k: int) -> list[int]:
    return [int(s) for s in np.random.SeedSequence(int(seed)).generate_state(k)]


def _profile(series: Series) -> ReplayTemperature | None:
    if not series.has_temperature:
        return None
    assert series.temp_c is not None
    t = np.arange(len(series.temp_c)) / series.rate_hz
    return ReplayTemperature(t, series.temp_c, name=series.name)


def simulate_channel(model: NoiseModel, channel: str, series: Series, seeds: list[int]
                     ) -> np.ndarray:
    """(K, n) realisations of ``channel`` over the series' length and temperature."""
    prof = _profile(series)
    n = len(series.y)
    out = np.empty((len(seeds), n))
    for i, s in enumerate(seeds):
        out[i] = simulate(model, n, series.rate_hz, s, temperature=prof,
                          channels=[channel])[channel]
    nan = ~np.isfinite(series.y)
    if nan.any():
        out[:, nan] = np.nan
    return out


def tau_correlation(cm: ChannelModel, afs: np.ndarray, n: int, rate_hz: float) -> np.ndarray:
    """Model correlation of the OAVAR estimates at averaging factors ``afs`` of n samples.

    From the channel's stochastic terms (:func:`imubench.noisefit.covariance.
    oavar_correlation`); the global test (:func:`imubench.gap.curves.global_chi2`) needs it.
    """
    amp2 = {"white": cm.white**2, "flicker": cm.flicker**2,
            "random_walk": cm.random_walk**2, "quantization": cm.quantization**2,
            "output_white": cm.output_white**2}
    tau_c = 0.0
    if cm.markov_sigma > 0 and cm.markov_tau > 0:
        amp2["markov"] = cm.markov_sigma**2
        tau_c = float(cm.markov_tau)
    m = np.asarray(afs, dtype=np.int64)
    return oavar_correlation(m, n - 2 * m, amp2, rate_hz, tau_c_s=tau_c,
                             bandwidth_hz=float(cm.bandwidth_hz),
                             filter_order=int(cm.filter_order))


class _PartSetup:
    """Taus, bands and the real features of one part (fit, holdout or a replicate)."""

    def __init__(self, series: Series, cm: ChannelModel | None = None) -> None:
        n = len(series.y)
        if np.isfinite(series.y).sum() < 64:
            raise GapError(f"{series.name}: fewer than 64 valid samples to analyse")
        self.series = series
        self.afs = analysis_afs(n, series.rate_hz)
        self.nperseg = psd_segment(n)
        f, _ = welch_psd(series.y[:self.nperseg], series.rate_hz, self.nperseg)
        self.f_hz = f
        self.edges = band_edges(f)
        full = oadev(series.y, series.rate_hz, "freq", afs=self.afs)
        self.tau_s = np.asarray(full.tau_s)
        with np.errstate(divide="ignore", invalid="ignore"):
            self.ci_s = 0.5 * np.log(np.asarray(full.ci_high) / np.asarray(full.ci_low))
        self.real = features(series.y, series.rate_hz, self.afs, self.edges, self.nperseg,
                             series.temp_c)
        self.corr = (None if cm is None
                     else tau_correlation(cm, self.afs, n, series.rate_hz)[:len(self.tau_s),
                                                                           :len(self.tau_s)])

    def sim_features(self, sims: np.ndarray) -> SimFeatures:
        return stack([features(s, self.series.rate_hz, self.afs, self.edges, self.nperseg,
                               self.series.temp_c) for s in sims])

    def compare(self, sims: SimFeatures) -> Comparison:
        return compare(self.real, self.ci_s, sims, self.tau_s, self.edges, self.corr)


def _additive(cm: ChannelModel, effect: str) -> bool:
    """True when the effect's increment simulates alone and adds (linear output chain)."""
    if effect == "markov":
        return cm.markov_sigma == 0.0
    if effect == "sine":
        return cm.sine_amplitude == 0.0
    if effect == "outliers":
        return cm.outlier_rate == 0.0
    return effect != "filter"


def _increment(cm: ChannelModel, params: dict[str, float]) -> dict[str, float]:
    """Model keys to simulate alone so that base + increment has the totals ``params``.

    Common random numbers: a term of a single-term model draws the same stream as that
    term of the full model, so the sum equals the model with the total coefficient.
    """
    inc: dict[str, float] = {}
    for k, v in params.items():
        v0 = getattr(cm, k)
        # the increment draws the SAME random stream as the model's term (same seed,
        # channel and term), so base + increment is that term with coefficient v0 + inc
        inc[k] = v - v0
    return inc


def _effect_realisations(model: NoiseModel, channel: str, effect: str,
                         params: dict[str, float], series: Series, seeds: list[int],
                         base: np.ndarray) -> np.ndarray:
    cm = model[channel]
    if _additive(cm, effect):
        keep = {"bandwidth_hz": cm.bandwidth_hz, "filter_order": cm.filter_order,
                "temp_ref": cm.temp_ref}
        inc_model = NoiseModel.single_term(channel, **keep, **_increment(cm, params))
        return base + simulate_channel(inc_model, channel, series, seeds)
    return simulate_channel(model.with_channel(channel, **params), channel, series, seeds)


def fit_candidates(cm: ChannelModel, fit: _PartSetup, before: Comparison,
                   base_feats: SimFeatures, effects: tuple[str, ...]
                   ) -> tuple[list[Candidate], dict[str, Any]]:
    """Each applicable effect with parameters fitted to the real fit part, and evidence."""
    s = fit.series
    cands: list[Candidate] = []
    ev: dict[str, Any] = {}
    model_avar = base_feats.avar.mean(axis=0)
    sig = before.sigma
    for eff in effects:
        if eff in avarfit.BASES:
            p = avarfit.fit_single(eff, fit.tau_s, fit.real.avar, model_avar, sig)
            p0 = getattr(cm, eff)
            cands.append(Candidate(eff, {eff: math.sqrt(p0 * p0 + p * p)}, 1))
        elif eff == "ramp":
            cands.append(Candidate(eff, {"ramp": fit.real.trend_slope}, 1))
        elif eff == "filter":
            bw, order, white = avarfit.fit_filter(cm, fit.tau_s, s.rate_hz, fit.real.avar,
                                                  model_avar, sig)
            cands.append(Candidate(eff, {"bandwidth_hz": bw, "filter_order": order,
                                         "white": white}, 3))
        elif eff == "markov":
            sg, tc = avarfit.fit_markov(fit.tau_s, fit.real.avar, model_avar, sig)
            if tc * MARKOV_SPAN <= fit.tau_s[-1]:
                cands.append(Candidate(eff, {"markov_sigma": sg, "markov_tau": tc}, 2))
        elif eff == "sine":
            if before.line_z > 3.0:
                bin_hz = s.rate_hz / line_segment(len(s.y))
                sf = evidence.fit_sine(s.y, s.rate_hz, before.line_f_hz, bin_hz)
                cands.append(Candidate(eff, {"sine_amplitude": sf.sine_amplitude,
                                             "sine_freq": sf.sine_freq}, 2))
                ev["sine"] = sf
        elif eff == "temperature":
            dof = base_feats.k - 1
            if s.has_temperature and abs(before.temp_z) > t_threshold(Z_TEMP_CANDIDATE, dof):
                assert s.temp_c is not None
                tf = evidence.fit_temperature(s.y, s.temp_c, s.rate_hz, cm.temp_ref)
                if tf is not None:
                    ev["temperature"] = tf
                    cands.append(Candidate(eff, {"temp_coeff": tf.temp_coeff_linear,
                                                 "temp_coeff2": cm.temp_coeff2}, 1))
                    cands.append(Candidate(eff, {"temp_coeff": tf.temp_coeff,
                                                 "temp_coeff2": tf.temp_coeff2}, 2))
        elif eff == "outliers":
            of = evidence.fit_outliers(s.y, s.rate_hz, float(base_feats.impulses.mean()))
            if of is not None:
                ev["outliers"] = of
                cands.append(Candidate(eff, {"outlier_rate": of.outlier_rate,
                                             "outlier_amplitude": of.outlier_amplitude}, 2))
    return cands, ev


def diagnose_channel(model: NoiseModel, channel: str, series: Series,
                     options: GapOptions | None = None,
                     replicates: list[Series] | None = None) -> ChannelDiagnosis:
    """Diagnose one channel of one record (and check the result on replicate records)."""
    opt = options or GapOptions()
    cm = model[channel]
    n = len(series.y)
    n_fit = n if opt.holdout_fraction == 0 else round(n * (1.0 - opt.holdout_fraction))
    if n_fit < 256 or (opt.holdout_fraction > 0 and n - n_fit < 256):
        raise GapError(
            f"{series.name}: {n} samples are too few to split with --holdout-fraction "
            f"{opt.holdout_fraction} (each part needs >= 256 samples)"
        )
    seeds = _seeds(opt.seed, opt.realisations)
    base = simulate_channel(model, channel, series, seeds)
    fit = _PartSetup(series.part(0, n_fit), cm)
    base_fit = fit.sim_features(base[:, :n_fit])
    before = fit.compare(base_fit)
    hold: _PartSetup | None = None
    hold_before: Comparison | None = None
    base_hold: np.ndarray | None = None
    if n_fit < n:
        hold = _PartSetup(series.part(n_fit, n), cm)
        base_hold = base[:, n_fit:]
        hold_before = hold.compare(hold.sim_features(base_hold))

    cands, ev = fit_candidates(cm, fit, before, base_fit, opt.effects)
    ev["psd"] = (fit.f_hz, fit.real.psd, base_fit.psd.mean(axis=0))
    penalty = math.log(before.n_terms)
    excess0 = before.chi2 - before.n_terms
    held_sims: dict[int, np.ndarray] = {}  # the held-out part of each candidate's realisations
    for i, c in enumerate(cands):
        sims = _effect_realisations(model, channel, c.effect, c.params, series, seeds, base)
        if hold is not None:
            held_sims[i] = sims[:, n_fit:].copy()  # the fit part is not kept
        c.fit = fit.compare(fit.sim_features(sims[:, :n_fit]))
        c.score = c.fit.chi2 + penalty * c.n_params
        c.closure = c.fit.excess_closed(before) if excess0 > 1e-9 else 0.0
        c.evidence_closed = c.fit.evidence_closed(before)
    order = sorted(range(len(cands)), key=lambda i: cands[i].score)
    ranked: list[Candidate] = []
    seen: set[str] = set()
    for i in order:  # one entry per effect (temperature: linear or quadratic, the better)
        if cands[i].effect not in seen:
            seen.add(cands[i].effect)
            ranked.append(cands[i])
    if not before.significant:
        verdict = "none"
    elif (not ranked or not ranked[0].evidence_closed >= MIN_CLOSURE
          or ranked[0].fit is None or ranked[0].fit.chi2 > before.chi2):
        verdict = "unexplained"
    else:
        verdict = ranked[0].effect
    top = ranked[:HOLDOUT_TOP]
    if hold is not None and base_hold is not None:
        for c in top:
            c.holdout = hold.compare(hold.sim_features(held_sims[cands.index(c)]))
    diag = ChannelDiagnosis(channel, before, hold_before, ranked, verdict, ev)
    for rep in replicates or []:
        rs = _PartSetup(rep, cm)
        rbase = simulate_channel(model, channel, rep, seeds)
        b = rs.compare(rs.sim_features(rbase))
        a = None
        w = diag.winner
        if w is not None:
            rsims = _effect_realisations(model, channel, w.effect, w.params, rep, seeds, rbase)
            a = rs.compare(rs.sim_features(rsims))
        diag.replicates.append((rep.name, b, a))
    return diag


def main_param_error(effect: str, fitted: dict[str, float], truth: float) -> float:
    """|fitted - truth| / |truth| of the effect's main parameter."""
    key = MAIN_PARAM[effect]
    return abs(abs(fitted[key]) - abs(truth)) / abs(truth)


__all__ = [
    "EFFECTS", "MAIN_PARAM", "MIN_CLOSURE", "Candidate", "ChannelDiagnosis", "Features",
    "GapOptions", "Series", "diagnose_channel", "main_param_error", "simulate_channel",
]
