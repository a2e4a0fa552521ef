"""Fit every channel of a recording and turn the result into a model file and JSON."""

from __future__ import annotations

import datetime as _dt
import logging
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from lsm6ds_sim.model import ChannelModel, NoiseModel

from imubench.batch import CHANNELS, UNITS
from imubench.noisefit.errors import FitError
from imubench.noisefit.fit import (
    PARAM_KEYS,
    ChannelFit,
    avar_points,
    check_series,
    fit_channel,
)
from imubench.noisefit.kernels import AMPLITUDE_KEY
from imubench.noisefit.outliers import outlier_warning
from imubench.noisefit.temperature import (
    SCREEN_T,
    T_LIMIT,
    TemperatureResponse,
    TemperatureTerms,
    filled_temperature,
    fit_temperature_response,
    increment_nll,
    no_response_note,
    removal_note,
    sensed,
    temperature_warning,
    with_halves,
)
from imubench.noisefit.units import (
    KALIBR_UNITS,
    WHITE_EQUIVALENT,
    datasheet_comparison,
    kalibr_imu,
    param_units,
    quantities,
)

log = logging.getLogger(__name__)

if TYPE_CHECKING:
    from imubench.recording import InputOptions, Recording


@dataclass(frozen=True)
class RecordingFit:
    """The fits of a recording's channels."""

    source: str
    rate_hz: float
    chip: str | None
    method: str
    fits: dict[str, ChannelFit]
    units_assumed: tuple[str, ...] = ()
    """Channels whose unit nothing in the recording stated (read as dps / g)."""
    samples: int = 0
    """Samples the recording holds (0: not known, a fit made without the recording)."""
    lost_samples: int = 0
    """Samples missing in its holes (the Allan curves are computed across them)."""
    holes: int = 0
    """Holes between recorded samples."""
    skipped: dict[str, str] = field(default_factory=dict)
    """Channels left out, with why (a constant, dead axis when no ``--channels`` named
    it): they stay quiet in the model file."""
    temperature_out: dict[str, TemperatureTerms] = field(default_factory=dict)
    """Channel -> the response to the recording's temperature taken out of its data
    before the noise terms were fitted (``--fit-temperature``) or compared with a model
    file's (the file's ``temp_coeff``): :meth:`noise_data` is what the fit describes."""

    def noise_data(self, rec: Recording, channel: str) -> np.ndarray:
        """The recording's ``channel`` (unit, NaN where lost) as the noise terms describe
        it: less the temperature response in :attr:`temperature_out`, if any (NaN
        outside the temperature readings, where no response can be taken out)."""
        y = rec.channel(channel)
        terms = self.temperature_out.get(channel)
        return y if terms is None else y - terms.response(rec.channel("temp"))

    def coverage(self) -> str:
        """``54950 samples, 2 holes (6050 samples, 9.9 % missing)``, or ``""``."""
        from imubench.recording import coverage_text

        return coverage_text(self.samples, self.lost_samples, self.holes) if self.samples \
            else ""

    def noise_model(self) -> NoiseModel:
        """A model file's content: fitted channels, others quiet; provenance in [meta]."""
        chans = {ch: (self.fits[ch].channel_model() if ch in self.fits else ChannelModel())
                 for ch in CHANNELS}
        meta: dict[str, Any] = {
            "name": f"imubench fit of {Path(self.source).name}",
            "source": str(self.source),
            "method": self.method,
            "rate_hz": float(self.rate_hz),
            "fitted_channels": ",".join(self.fits),
            "created": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        }
        if self.chip:
            meta["chip"] = self.chip
        return NoiseModel(channels=chans, meta=meta, source=str(self.source))

    def kalibr(self, inflate: float = 1.0) -> dict[str, Any]:
        """Kalibr ``imu.yaml`` values (:func:`~imubench.noisefit.units.kalibr_imu`): the
        terms found present, and the upper 95 % confidence limit of those that were not
        (marked in ``upper_limits``)."""
        present = {ch: {k: v for k, v in f.params.items() if k in f.present}
                   for ch, f in self.fits.items()}
        limits = {ch: {k: hi for k, (_, hi) in f.ci.items() if k not in f.present}
                  for ch, f in self.fits.items()}
        for ch, f in self.fits.items():  # N's limit by ChannelFit.coefficient's rule
            _, ci = f.coefficient(WHITE_EQUIVALENT)
            if ci is not None:
                limits[ch].setdefault(WHITE_EQUIVALENT, ci[1])
        return kalibr_imu(present, self.rate_hz, upper_limits=limits, inflate=inflate)

    def _kalibr_or_reason(self) -> dict[str, Any]:
        """:meth:`kalibr`, or ``{"not_written": why}`` when a value would have to be made
        up (a model file without a random walk and without intervals)."""
        try:
            return self.kalibr()
        except FitError as exc:
            return {"not_written": str(exc)}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: per channel the fit, its datasheet units and the ``units`` of its
        numbers (``params``, ``ci95``, ``bias``, ``points``); Kalibr with its units;
        datasheet ratio."""
        params = {ch: f.params for ch, f in self.fits.items()}
        return {
            "recording": str(self.source),
            "rate_hz": self.rate_hz,
            "samples": self.samples,
            "lost_samples": self.lost_samples,
            "holes": self.holes,
            "chip": self.chip,
            "method": self.method,
            "units_assumed": list(self.units_assumed),
            "channels": {
                ch: {**f.to_dict(), "datasheet_units": fit_datasheet_units(ch, f),
                     "units": {**param_units(ch), "tau_s": "s",
                               "avar": f"{UNITS[ch]}^2", "edf": "1"}}
                for ch, f in self.fits.items()
            },
            "skipped_channels": dict(self.skipped),
            "kalibr": self._kalibr_or_reason(),
            "kalibr_units": dict(KALIBR_UNITS),
            "datasheet_comparison": datasheet_comparison(self.chip, params, self.rate_hz),
        }


def fit_datasheet_units(channel: str, fit: ChannelFit) -> dict[str, float | None]:
    """The fit's N, B, K in datasheet units (:func:`~imubench.noisefit.units.quantities`):
    a term the fit judged absent is ``None`` with its upper 95 % limit under
    ``KEY_upper_95`` (a 0.0 read as measured: ADIS16405 gx, 1 h, bias instability "0.0
    deg/h" beside a clear Allan floor at 40 deg/h, the flicker term's limit 27 deg/h)."""
    out: dict[str, float | None] = {}
    for q in quantities(channel):
        value, ci = fit.coefficient(q.term)
        out[q.key] = value * q.factor if value > 0 else None
        if value <= 0 and ci is not None and ci[1] > 0:
            out[f"{q.key}_upper_95"] = ci[1] * q.factor
    return out


def parse_channels(text: str | Sequence[str] | None, available: Iterable[str]) -> list[str]:
    """Channels to fit: the given ones (comma/space separated), else every one present."""
    avail = [c for c in available if c in CHANNELS]
    if text is None or (isinstance(text, str) and not text.strip()):
        return avail
    items = text.replace(",", " ").split() if isinstance(text, str) else list(text)
    bad = [c for c in items if c not in CHANNELS]
    if bad:
        raise FitError(f"--channels: unknown channel(s) {bad}; channels are "
                       + ", ".join(CHANNELS))
    missing = [c for c in items if c not in avail]
    if missing:
        raise FitError(f"--channels: {missing} not in the recording (it has {avail})")
    return items


def fit_recording(path: str | Path, *, channels: str | Sequence[str] | None = None,
                  terms: str = "auto", method: str = "wls",
                  options: InputOptions | None = None, fit_temperature: bool = False,
                  on_channel: Callable[[int, int], None] | None = None) -> RecordingFit:
    """Load a recording (any the reader takes, with ``options``) and fit the chosen
    channels (``on_channel(done, total)`` after each one: a progress bar).

    ``fit_temperature``: where a channel follows the recording's temperature column
    (:func:`~imubench.noisefit.temperature.fit_temperature_response`, |t| above its
    limit), that response is taken out before the noise terms are fitted and written to
    the model (``temp_coeff``, ``temp_ref``); otherwise it is only named
    in a warning, and the long-tau terms carry it."""
    from imubench.recording import load_recording

    return fit_loaded(load_recording(path, options), str(path), channels=channels,
                      terms=terms, method=method, fit_temperature=fit_temperature,
                      on_channel=on_channel)


def fit_loaded(rec: Recording, source: str, *, channels: str | Sequence[str] | None = None,
               terms: str = "auto", method: str = "wls", fit_temperature: bool = False,
               on_channel: Callable[[int, int], None] | None = None) -> RecordingFit:
    """:func:`fit_recording` on a recording already in memory (``source`` names it)."""
    try:  # errors name the recording (a batch fits many)
        chans = parse_channels(channels, rec.channels)
    except FitError as exc:
        raise FitError(f"{source}: {exc}") from None
    if not chans:
        raise FitError(f"{source}: no gyro or accel channel with data to fit")
    fits = {}
    skipped: dict[str, str] = {}
    temp_c = rec.channel("temp")  # dense like the channels: NaN where samples are lost
    for k, ch in enumerate(chans):
        y = rec.channel(ch)
        finite = y[np.isfinite(y)]
        if channels is None and len(chans) > 1 and finite.size and np.ptp(finite) == 0:
            # a dead or unconnected axis: the others are still fitted (one constant
            # channel stopped the whole fit, and report has no --channels)
            skipped[ch] = (f"constant ({finite[0]:g} {UNITS[ch]} in every sample): a stuck "
                           "or unconnected axis has no noise to fit")
            log.warning("%s: %s left out: %s", source, ch, skipped[ch])
            continue

        def fit(v: np.ndarray, c: str = ch) -> ChannelFit:
            return fit_channel(v, rec.rate_hz, terms=terms, method=method, channel=c)

        try:
            fits[ch], response = _fit_with_temperature(y, temp_c, rec.rate_hz,
                                                       fit_temperature, fit)
        except FitError as exc:
            raise FitError(f"{source}: {exc}") from None
        fits[ch] = replace(fits[ch], temperature_check=response)
        taken_out = fits[ch].temperature
        if taken_out is not None:
            note = removal_note(ch, UNITS[ch], taken_out) + _left_out(
                y, filled_temperature(temp_c), "the noise fit")
            log.info("%s: %s", source, note)
            fits[ch] = replace(fits[ch], notes=(*fits[ch].notes, note))
        missing = no_response_note(ch) if fit_temperature and response is None else None
        from imubench.recording import empty_cells_text  # the reader imports the fit

        for warning in (missing, empty_cells_text(rec, ch),
                        None if taken_out else temperature_warning(
                            ch, UNITS[ch], response, fit_temperature),
                        outlier_warning(ch, y)):
            if warning is not None:
                log.warning("%s: %s", source, warning)
                fits[ch] = replace(fits[ch], notes=(*fits[ch].notes, warning))
        if on_channel is not None:
            on_channel(k + 1, len(chans))
    if not fits:
        raise FitError(f"{source}: every channel is constant; there is no noise to fit")
    chip = rec.metadata.get("chip")
    return RecordingFit(source, rec.rate_hz, str(chip) if chip else None, method, fits,
                        tuple(rec.metadata.get("units_assumed", ())), *_coverage(rec),
                        skipped=skipped, temperature_out={
                            ch: f.temperature.terms for ch, f in fits.items()
                            if f.temperature is not None})


TEMPERATURE_PASSES = 2
"""Refits of the noise terms to the record less the temperature response."""
UNSEEN_TERMS = ("flicker", "random_walk")
"""Long-tau terms that the response's covariance holds at their upper 95 % limit when the
fit judged them absent."""


def _test_noise(f: ChannelFit) -> ChannelModel:
    """The noise whose covariance the temperature response is estimated under: the fit's
    terms, and each long-tau term it judged absent at its upper 95 % limit. A random walk
    too weak for the selection (3e-5 dps/sqrt(s) under white 0.004 dps/sqrt(Hz), 1 h) still
    wanders with a 20 -> 30 degC warm-up: under the white noise alone it read as a
    response at t -8.3 on one of six such records."""
    cm = f.channel_model()
    upper = {key: f.ci[key][1] for key in UNSEEN_TERMS
             if key not in f.present and key in f.ci and math.isfinite(f.ci[key][1])}
    return cm.replace(**upper) if upper else cm


def _fit_with_temperature(y: np.ndarray, temp_c: np.ndarray, rate_hz: float, take_out: bool,
                          fit: Callable[[np.ndarray], ChannelFit]
                          ) -> tuple[ChannelFit, TemperatureResponse | None]:
    """The channel's noise fit and its response to the temperature.

    The response is estimated under the covariance of the noise fitted to the record as
    it is (:func:`~imubench.noisefit.temperature.fit_temperature_response`,
    :func:`_test_noise`); without ``take_out`` and at |t| above :data:`SCREEN_T` that is
    all (one fit: the default ``imubench fit`` warns on it). That noise carries the
    response itself (as a random walk, flicker or ramp), which widens its error; where it
    reads |t| <= :data:`SCREEN_T`, a second screen under the record's white scatter
    (:func:`_white_noise`) at |t| above :data:`~imubench.noisefit.temperature.T_LIMIT`
    still goes on (a response that dominates the record). With ``take_out``, or from the
    second screen, feasible generalised least squares: the noise is refitted to the record less the
    response and the response re-estimated under the refitted noise's covariance,
    :data:`TEMPERATURE_PASSES` times. The last response decides (``accepted``): significant,
    the same in the record's halves (:func:`~imubench.noisefit.temperature.with_halves`),
    and the record's block means more likely with it taken out and the noise refitted
    than as they are under the first fit's noise
    (:func:`~imubench.noisefit.temperature.increment_nll`). An accepted response is taken
    out and the noise refitted without it (``ChannelFit.temperature``; without
    ``take_out`` it is returned for the warning only); otherwise the first fit is
    returned, with the first screen's response unless the refitted one was screened."""
    first = fit(y)
    screened = fit_temperature_response(y, temp_c, rate_hz, _test_noise(first))
    if screened is None:
        return first, None
    response = screened
    if abs(screened.t) <= SCREEN_T:
        white = fit_temperature_response(y, temp_c, rate_hz, _white_noise(y, rate_hz))
        if white is None or abs(white.t) <= T_LIMIT:
            return first, screened
        response = white  # refitted below; kept only if it is then accepted
    elif not take_out:
        return first, screened
    for _ in range(TEMPERATURE_PASSES):
        less = fit(y - response.response(temp_c))
        found = fit_temperature_response(y, temp_c, rate_hz, _test_noise(less))
        if found is None:
            return first, response
        response = found
    response = with_halves(response, y, temp_c, rate_hz, _test_noise(less))
    final = fit(y - response.response(temp_c))
    gain = (increment_nll(y, temp_c, rate_hz, _test_noise(first))
            - increment_nll(y - response.response(temp_c), temp_c, rate_hz,
                            _test_noise(final)))
    response = replace(response, likelihood_gain=gain if math.isfinite(gain) else None)
    if not response.accepted:
        return first, (response if abs(screened.t) > SCREEN_T else screened)
    if not take_out:
        return first, response
    return replace(final, temperature=response), response


def _white_noise(y: np.ndarray, rate_hz: float) -> ChannelModel:
    """White noise of the record's sample-to-sample scatter (``std(diff y) / sqrt(2
    rate)``, unit/sqrt(Hz)): the covariance of a second screen for a response that
    dominates the record. The first fit then takes the response for its noise (a 0.01
    dps/degC response to a +-4 degC cycle of 900 s beside white 0.004 dps/sqrt(Hz) at
    10 Hz: a random walk of 0.0148 dps/sqrt(s) and no white term), under whose covariance
    the response reads t 0.8; under this one every slow wander that moves with the
    temperature reads large, so the refits and the acceptance rules decide."""
    return ChannelModel(white=float(np.nanstd(np.diff(y))) / math.sqrt(2.0 * rate_hz))


def _left_out(y: np.ndarray, filled_temp_c: np.ndarray, where: str) -> str:
    """``; N samples before the first or after the last temperature reading ... are left
    out of <where>`` when a response taken out leaves samples of ``y`` without one (NaN
    in the filled temperature, :func:`~imubench.noisefit.temperature.filled_temperature`),
    else ``""``: every sample is accounted for."""
    unused = int((np.isfinite(y) & ~np.isfinite(filled_temp_c)).sum())
    return (f"; {unused} samples before the first or after the last temperature reading "
            f"have no response to take out and are left out of {where}" if unused else "")


def _unmodelled_response(channel: str, y: np.ndarray, temp_c: np.ndarray, rate_hz: float,
                         cm: ChannelModel) -> str | None:
    """A note when a model file without a temperature response is compared with a
    recording whose ``channel`` follows its temperature (|t| above
    :data:`~imubench.noisefit.temperature.T_LIMIT` under the model's noise covariance,
    :func:`~imubench.noisefit.temperature.fit_temperature_response`): the comparison
    then holds that drift, which the model's noise terms do not describe."""
    found = fit_temperature_response(y, temp_c, rate_hz, cm)
    if found is None or not found.significant:
        return None
    return (f"{channel}: the recording's {sensed(channel)} follows the die temperature "
            f"({found.temp_coeff:.3g} +- {found.temp_coeff_se:.2g} {UNITS[channel]}/degC, t "
            f"{found.t:.1f} under the model's noise) and the model has no temperature "
            "response (temp_coeff): that drift is in the compared curves; fit one with "
            "`imubench fit --fit-temperature`")


def _coverage(rec: Recording) -> tuple[int, int, int]:
    """(samples held, samples lost in holes, holes) of ``rec``."""
    return len(rec), rec.lost_samples, rec.holes


MODEL_FILE_METHOD: str = "model file"
"""``method`` of a :class:`ChannelFit` read from a model file instead of fitted."""
_COMPANION = {"markov_sigma": ("markov_tau",), "sine_amplitude": ("sine_freq",),
              "resonance_height": ("resonance_freq_hz", "resonance_width_hz")}


def channel_from_model(cm: ChannelModel, y: np.ndarray, rate_hz: float, channel: str
                       ) -> ChannelFit:
    """A :class:`ChannelFit` holding a model file's values for ``channel`` (no fit).

    ``params`` are the file's noise keys, ``present`` those that are non-zero, ``ci`` is
    empty (a model file carries no intervals), and ``tau_s/avar/edf`` are the recording's
    octave OAVAR points (``y`` at ``rate_hz``) that the model is shown against.
    """
    arr = check_series(y, rate_hz, channel)
    pts = avar_points(arr, rate_hz, None, channel)
    params: dict[str, float] = {k: float(getattr(cm, k)) for k in PARAM_KEYS}
    present: list[str] = []
    for key in AMPLITUDE_KEY.values():
        if params.get(key, 0.0) != 0.0:
            present += [key, *_COMPANION.get(key, ())]
    if params["bandwidth_hz"] > 0:
        present += ["bandwidth_hz", "filter_order"]
    return ChannelFit(channel, float(rate_hz), MODEL_FILE_METHOD, params, {}, tuple(present),
                      pts.tau_s, pts.avar, pts.edf, float(np.nanmean(arr)),
                      notes=("values from the model file: no fit, no intervals",))


def model_file_fit(model: NoiseModel, rec: Recording, source: str, *,
                   channels: str | Sequence[str] | None = None) -> RecordingFit:
    """A :class:`RecordingFit` built from a model file (``imubench fit -o`` output, read by
    :func:`lsm6ds_sim.model.load_model`) for the recording ``rec``: every requested channel
    of the recording that the model gives noise to (default: the model's
    ``meta.fitted_channels`` when present, else every channel with a noise term)."""
    chans = parse_channels(channels, rec.channels)
    fitted = model.meta.get("fitted_channels")
    if channels is None and isinstance(fitted, str):
        chans = [ch for ch in chans if ch in fitted.replace(",", " ").split()]
    keys = set(AMPLITUDE_KEY.values())
    chans = [ch for ch in chans if any(float(getattr(model[ch], k)) != 0.0 for k in keys)]
    if not chans:
        raise FitError(f"{model.source}: gives no noise term to any channel of {source} "
                       f"(recording channels {list(rec.channels)})")
    temp_c = rec.channel("temp")
    has_temp = int(np.isfinite(temp_c).sum()) >= 2
    out: dict[str, TemperatureTerms] = {}
    fits = {}
    for ch in chans:
        cm = model[ch]
        terms = TemperatureTerms(float(cm.temp_coeff), float(cm.temp_coeff2),
                                 float(cm.temp_ref))
        y = rec.channel(ch)
        note = None
        if terms.temp_coeff or terms.temp_coeff2:
            what = (f"the model's response to the die temperature (temp_coeff "
                    f"{terms.temp_coeff:.4g} {UNITS[ch]}/degC, temp_coeff2 "
                    f"{terms.temp_coeff2:.3g} {UNITS[ch]}/degC^2 about {terms.temp_ref:g} degC)")
            if has_temp:
                out[ch] = terms
                note = (f"{ch}: {what} was taken out of the recording before its Allan "
                        "curve was compared with the model's noise terms"
                        + _left_out(y, filled_temperature(temp_c), "the comparison"))
                y = y - terms.response(temp_c)
            else:
                note = (f"{ch}: {what} is not in this comparison: the recording has no "
                        "temperature readings, so its drift, if any, is compared with the "
                        "noise terms alone")
        elif has_temp:
            note = _unmodelled_response(ch, y, temp_c, rec.rate_hz, cm)
        f = channel_from_model(cm, y, rec.rate_hz, ch)
        fits[ch] = f if note is None else replace(f, notes=(*f.notes, note))
    chip = rec.metadata.get("chip")  # the recording's: a model's chip is not its sensor
    return RecordingFit(source, rec.rate_hz, str(chip) if chip else None, MODEL_FILE_METHOD,
                        fits, (), *_coverage(rec), temperature_out=out)


__all__ = ["MODEL_FILE_METHOD", "RecordingFit", "channel_from_model", "fit_loaded",
           "fit_recording", "model_file_fit", "parse_channels"]
