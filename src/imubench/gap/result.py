"""The diagnosis of one channel as it is reported: the CLI's options
(:class:`GapOptions`) and the result (:class:`ChannelDiagnosis`) with its JSON form
(docs/gap.md, "JSON"). :mod:`imubench.gap.diagnose` makes it."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from lsm6ds_sim.model import ChannelModel

from imubench.gap.candidates import EFFECTS, Candidate, temperature_slope
from imubench.gap.curves import STAT_TESTS, Comparison, Region
from imubench.gap.errors import GapError
from imubench.gap.line_across import Z_ACROSS


@dataclass(frozen=True)
class GapOptions:
    """Knobs of the diagnosis (CLI flags)."""

    realisations: int = 10
    seed: int = 0
    holdout_fraction: float = 0.5
    effects: tuple[str, ...] = EFFECTS
    standard_errors: bool = True
    """Refit the kept effects on the realisations for their ``params_se``
    (:func:`imubench.gap.uncertainty.standard_errors`); off where only the verdict is
    used (the detection limits' injections)."""

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
class ChannelDiagnosis:
    channel: str
    before: Comparison
    holdout_before: Comparison | None
    candidates: list[Candidate]
    """The first step's candidates, ranked by score (one per effect)."""
    verdict: str
    evidence: dict[str, Any]
    kept: list[Candidate] = field(default_factory=list)
    """Effects kept by the forward selection, in order."""
    reason: str = ""
    step_z: float = float("nan")
    """Whole-record bias-step statistic against the base realisations."""
    drift_t: float = float("nan")
    """Whole-record drift t (:func:`imubench.gap.evidence.drift_statistic`)."""
    step_fired: bool = False
    """The whole-record bias-step test fired at the first step."""
    drift_fired: bool = False
    """The whole-record drift test fired at the first step."""
    temp_record_z: float = float("nan")
    """Whole-record temperature z (:class:`imubench.gap.parts.RecordTemperature`)."""
    temp_fired: bool = False
    """The whole-record temperature test fired at the first step."""
    across_z: float = float("nan")
    """The held-out line test's z at the first step (:mod:`imubench.gap.line_across`)."""
    across_f_hz: float = float("nan")
    """Its held-out bin's frequency (Hz)."""
    across_f_fit_hz: float = float("nan")
    """The fit part's peak that chose that bin (Hz)."""
    across_fired: bool = False
    """The held-out line test fired at the first step."""
    temp_note: str = ""
    """Why the temperature test could not be made (:attr:`RecordTemperature.note`)."""
    held_samples: tuple[float, float] | None = None
    """(share of the record's samples that repeat the previous one, median number of
    samples a value is held for) when the record holds its output
    (:func:`imubench.noisefit.outliers.held_runs`), else None: the realisations do not
    hold theirs."""
    residual_significant: bool = False
    """A significant departure remains after the kept effects."""
    background: dict[str, Any] | None = None
    pruned: list[Candidate] = field(default_factory=list)
    """Effects the forward selection kept and the sequential replacement
    (:func:`imubench.gap.diagnose._exchange`) or the backward step
    (:func:`imubench.gap.diagnose._prune`) dropped, each with its ``note``."""
    replicates: list[tuple[str, Comparison, Comparison | None]] = field(default_factory=list)
    alternative: dict[str, Any] | None = None
    """Another set of effects that explains the record nearly as well and was not kept
    (:attr:`imubench.gap.diagnose._Path.alternative`; JSON ``alternative``, None when
    there is none)."""
    fired_refused: list[Candidate] = field(default_factory=list)
    """The effects whose own whole-record tests fired (temperature, ramp, bias step) and
    that the selection examining them first
    (:func:`imubench.gap.diagnose._better_start`) refused, each with its ``note``, when
    that selection then kept what the other did (JSON ``fired_first_refused``): why a test
    that fired names no effect."""
    look_alike: dict[str, Any] | None = None
    """Another effect the fit part does not tell apart from the verdict's (JSON
    ``look_alike``, :func:`imubench.gap.diagnose._look_alike_dict`; None when there is none)."""
    fired_after: list[str] = field(default_factory=list)
    """The tests that still fire against the model with the kept effects
    (:attr:`imubench.gap.step.Step.fired`; JSON ``fired_after``), empty when
    nothing significant is left."""
    regions_after: list[Region] = field(default_factory=list)
    """The fit part's Allan regions against the model with the kept effects, when a
    significant departure is left (JSON ``regions_after``)."""
    temp_mean_c: float = float("nan")
    """The record's mean temperature (degC; NaN without one)."""
    temp_ref_c: float = float("nan")
    """The model's ``temp_ref`` (degC), where the temperature coefficients are stated."""
    model_params: dict[str, dict[str, float]] = field(default_factory=dict)
    """By effect, the model's own values of the parameters it sets: of each noise term a
    kept effect of the same name raises (:data:`RAISED_TERMS`) and of the white level and
    filter the base model's refit sets (JSON ``model_params`` of those kept, dropped or
    not kept)."""
    temp_spans_c: tuple[float, float, float] | None = None
    """The fit part's, the held-out part's and the record's temperature spans (degC) when
    the split cannot both fit and test a temperature response
    (:func:`imubench.gap.diagnose.temperature_spans`)."""
    ramp_temperature: dict[str, float] | None = None
    """A kept ramp's drift read as a temperature response, when the record's temperature
    drifted in step with time (:func:`imubench.gap.diagnose.ramp_as_temperature`; JSON
    ``ramp_temperature_alias``)."""
    not_kept: list[Candidate] = field(default_factory=list)
    """The candidates examined at the step where the forward selection stopped with a
    significant departure left (after at least one kept effect), each with the ``note``
    that refused it: what a second or third effect would have been and why it was not
    kept."""

    @property
    def winner(self) -> Candidate | None:
        """The verdict's effect (a kept unmodelled effect, or the base model)."""
        for c in self.kept:
            if c.effect == self.verdict:
                return c
        return None

    @property
    def final_fit(self) -> Comparison | None:
        return self.kept[-1].fit if self.kept else None

    @property
    def final_holdout(self) -> Comparison | None:
        return self.kept[-1].holdout if self.kept else None

    def _refused_dict(self, c: Candidate) -> dict[str, Any]:
        """A dropped or not-kept candidate's JSON entry, with the model's own value of
        the term it raises (``model_params``; a flicker fitted at the model's own value
        raises nothing)."""
        d: dict[str, Any] = {"effect": c.effect, "params": c.params, **c.at_output(),
                             "reason": c.note}
        if c.effect in self.model_params:
            d["model_params"] = self.model_params[c.effect]
        return d

    def to_dict(self) -> dict[str, Any]:
        ff = self.final_fit or self.before
        kept_effects = {c.effect for c in self.kept}
        out: dict[str, Any] = {
            "gap_before": self.before.gap,
            "significant": (self.before.significant or self.step_fired or self.drift_fired
                            or self.temp_fired or self.across_fired),
            "whole_record": {"step_fired": self.step_fired, "drift_fired": self.drift_fired,
                             "temperature_fired": self.temp_fired,
                             "line_across_fired": self.across_fired},
            "regions": [r.to_dict() for r in self.before.regions],
            "effects": [c.to_dict(self.before) for c in self.candidates],
            "verdict": self.verdict,
            "reason": self.reason,
            "kept": [kept_dict(c, self.model_params) for c in self.kept],
            "dropped": [self._refused_dict(c) for c in self.pruned],
            "not_kept": [self._refused_dict(c) for c in self.not_kept],
            "residual_significant": self.residual_significant,
            "fired_after": self.fired_after,
            "regions_after": [r.to_dict() for r in self.regions_after],
            "gap_after": ff.gap,
            "gap_null": self.before.gap_null,
            "gap_null_after": ff.gap_null,
            "gap_excess_before": self.before.gap_excess,
            "gap_excess_after": ff.gap_excess,
            "gap_excess_floor": self.before.gap_excess_floor,
            "gap_excess_floor_after": ff.gap_excess_floor,
            "holdout": None,
            "bands": [dict(b) for b in self.before.bands],
            "line": {"f_hz": self.before.line_f_hz, "z": self.before.line_z},
            "impulses_z": self.before.tail_z,
            "temperature_slope_z": self.before.temp_z,
            "temperature_level_z": self.before.temp_level_z,
            "trend_z": self.before.trend_z,
            "bias_step_z": self.step_z,
            "drift_t": self.drift_t,
            "temperature_record_z": self.temp_record_z,
            "line_across": {"z": self.across_z, "f_hz": self.across_f_hz,
                            "f_fit_hz": self.across_f_fit_hz, "threshold": Z_ACROSS},
            "statistics_after": {key: getattr(ff, key) for key, _, _ in STAT_TESTS},
            "whole_record_after": self._whole_record_after(),
            "global_after": ff.global_dict(),
            "temperature_note": self.temp_note or None,
            "held_samples": (None if self.held_samples is None else
                             {"share": self.held_samples[0],
                              "median_hold_samples": self.held_samples[1]}),
            "temperature_spans_c": (None if self.temp_spans_c is None else
                                    {"fit_part": self.temp_spans_c[0],
                                     "held_out": self.temp_spans_c[1],
                                     "record": self.temp_spans_c[2]}),
            "not_fitted": {e: why for e, why in self.evidence.get("not_fitted", {}).items()
                           if e not in kept_effects},
            "global": self.before.global_dict(),
            "background": self.background,
            "alternative": self.alternative,
            "fired_first_refused": [self._refused_dict(c) for c in self.fired_refused],
            "look_alike": self.look_alike,
            "ramp_temperature_alias": self.ramp_temperature,
        }
        for entry in out["effects"]:
            entry["kept"] = entry["effect"] in kept_effects
        for entry in (out["effects"] + out["kept"] + out["dropped"] + out["not_kept"]):
            self._slope_at_mean(entry)
        for rd, r in zip(out["regions"], self.before.regions, strict=True):
            rd["gap_after"] = ff.gap_over(r.tau_min_s, r.tau_max_s)
        for bd in out["bands"]:
            bd["z_max_after"] = ff.band_z_over(float(bd["f_min_hz"]), float(bd["f_max_hz"]))
        for kd, c in zip(out["kept"], self.kept, strict=True):
            if c.holdout is not None:
                kd["holdout_region_gap_after"] = c.holdout.region_gap(self.before.regions)
        if self.holdout_before is not None:
            hb = self.holdout_before
            ha = self.final_holdout or hb
            regions = self.before.regions
            out["holdout"] = {
                "gap_before": hb.gap, "gap_after": ha.gap,
                "region_gap_before": hb.region_gap(regions),
                "region_gap_after": ha.region_gap(regions),
                "chi2_closed": ha.excess_closed(hb) if self.kept else 0.0,
                "gap_null": hb.gap_null,
                "gap_null_after": ha.gap_null,
                "gap_excess_before": hb.gap_excess,
                "gap_excess_after": ha.gap_excess,
                "gap_excess_floor": hb.gap_excess_floor,
                "gap_excess_floor_after": ha.gap_excess_floor,
                "chi2_check_before": hb.chi2_check,
                "chi2_check_after": ha.chi2_check,
                "significant": hb.significant,
                "fired": hb.fired,
                "regions": [r.to_dict() for r in hb.regions],
                "significant_after": ha.significant,
                "fired_after": ha.fired,
                "regions_after": [r.to_dict() for r in ha.regions],
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

    def _whole_record_after(self) -> dict[str, float]:
        """The whole-record statistics against the model with all kept effects
        (``bias_step_z``, ``drift_t``, ``temperature_record_z``, ``line_across_z``; the
        first step's without a kept effect)."""
        last = self.kept[-1] if self.kept else None
        return {"bias_step_z": self.step_z if last is None else last.step_z,
                "drift_t": self.drift_t if last is None else last.drift_t,
                "temperature_record_z": (self.temp_record_z if last is None
                                         else last.temp_record_z),
                "line_across_z": self.across_z if last is None else last.across_z}

    def _slope_at_mean(self, entry: dict[str, Any]) -> None:
        """Adds to a temperature effect's ``entry`` its response's slope at the record's
        mean temperature, ``temp_slope_at_mean`` (unit/degC, :func:`imubench.gap.
        candidates.temperature_slope`) at ``temp_mean_c`` (degC)."""
        if entry.get("effect") != "temperature" or not math.isfinite(self.temp_mean_c):
            return
        entry["temp_mean_c"] = self.temp_mean_c
        entry["temp_slope_at_mean"] = temperature_slope(entry["params"], self.temp_mean_c,
                                                        self.temp_ref_c)


RAISED_TERMS = ("flicker", "random_walk", "quantization")
"""Kept effects that raise a noise term of the model's (a zero: the model lacks it)."""
BASE_PARAMS = ("white", "bandwidth_hz", "filter_order")
"""What the base model's refit sets."""


def model_params_of(cm: ChannelModel) -> dict[str, dict[str, float]]:
    """:attr:`ChannelDiagnosis.model_params` of the model's channel ``cm``."""
    out = {k: {k: float(getattr(cm, k))} for k in RAISED_TERMS}
    out["base_model"] = {k: float(getattr(cm, k)) for k in BASE_PARAMS}
    return out


def kept_dict(c: Candidate, model_params: Mapping[str, dict[str, float]]
               ) -> dict[str, Any]:
    """A kept effect's JSON entry; ``model_params``: the model's own values of what it
    sets (:attr:`ChannelDiagnosis.model_params`)."""
    assert c.fit is not None
    d: dict[str, Any] = {"effect": c.effect, "params": c.params, "n_params": c.n_params,
                         "params_se": dict(c.params_se),  # NaN: null in the JSON
                         "params_bias": dict(c.params_bias), "params_n": dict(c.params_n),
                         "gap_after": c.fit.gap,
                         "gap_excess_after": c.fit.gap_excess,
                         "evidence_closed": c.evidence_closed, **c.at_output(),
                         **c.fitted_on(), **c.holdout_dict()}
    if c.effect in model_params:
        d["model_params"] = model_params[c.effect]
    if c.estimator:
        d["estimator"] = c.estimator
    if c.slow_scale < 1.0:
        d["slow_terms_scale"] = c.slow_scale
    if math.isfinite(c.unique_chi2):
        d["chi2_rise_without"] = c.unique_chi2
    return d
