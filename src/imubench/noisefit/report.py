"""The ``imubench report`` output: plots, fit files and one HTML page per sensor.

Per sensor (gyro gx gy gz, accel ax ay az) with fitted channels:

- ``sigma_tau_<sensor>.png/.svg``: OADEV with 95 % error bars, model and per-term lines,
  IEEE 952 readouts with a table in datasheet units (:func:`plots.sigma_tau_figure`);
- ``psd_<sensor>.png/.svg``: amplitude spectral density with the model
  (:func:`plots.psd_figure`);
- ``<sensor>.html``: the one-page summary (:mod:`.report_html`).

Plus ``model.toml`` (loads in the simulator), ``fit.json``, ``imu.yaml`` (Kalibr) and
``index.html``. The noise values come from a fit of the recording, or, with
``model_file``, from a model file (``imubench fit -o`` output) without refitting; such a
file has no intervals and the pages say so.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from lsm6ds_sim.model import NoiseModel, load_model

from imubench.noisefit.errors import FitError
from imubench.noisefit.fit import ChannelFit
from imubench.noisefit.ieee952 import Readout, ieee952_readouts
from imubench.noisefit.misfit import MODEL_FILE_FLOOR, curve_misfit
from imubench.noisefit.model_avar import model_oavar_edf
from imubench.noisefit.plots import psd_figure, save_figure, sigma_tau_figure
from imubench.noisefit.recording_fit import RecordingFit, fit_loaded, model_file_fit
from imubench.noisefit.report_html import PageInfo, index_page, sensor_page
from imubench.noisefit.spectrum import band_psd
from imubench.noisefit.units import kalibr_yaml
from imubench.progress import progress
from imubench.recording.options import InputOptions

SENSORS: dict[str, tuple[tuple[str, ...], str]] = {
    "gyro": (("gx", "gy", "gz"), "dps"), "accel": (("ax", "ay", "az"), "g")}
"""Sensor -> (channels, model unit)."""
FIT_SHARE: float = 0.7
"""Fraction of the progress bar given to the fit (the rest: curves, spectra, plots)."""


def oadev_curve(y: np.ndarray, rate_hz: float) -> Any:
    """The measured OADEV at octave taus with 95 % chi-squared limits (StatResult)."""
    from imubench.stats import oadev

    return oadev(y, rate_hz, "freq", "octave", confidence=0.95)


def _title(kind: str, result: RecordingFit, sensor: str, duration_s: float) -> str:
    source = "model file" if result.method == "model file" else f"fit ({result.method})"
    return (f"{sensor} {kind}: {Path(result.source).name} ({result.rate_hz:g} Hz, "
            f"{duration_s / 3600:.3g} h; {source})")


def _info(result: RecordingFit, n_samples: int, model: NoiseModel | None,
          notes: list[str]) -> PageInfo:
    notes = list(notes) + [f"{ch} left out: {why}" for ch, why in result.skipped.items()]
    if model is not None:
        model_rate = model.meta.get("rate_hz")
        if isinstance(model_rate, (int, float)) and not np.isclose(model_rate,
                                                                     result.rate_hz):
            notes.append(f"{model.source} was fitted at {model_rate:g} Hz; the recording is "
                         f"at {result.rate_hz:g} Hz (densities carry over, a fitted output "
                         "filter does not)")
    return PageInfo(str(result.source), result.rate_hz, n_samples / result.rate_hz,
                    result.chip, result.method, None if model is None else model.source,
                    tuple(notes))


def misfit_notes(fits: dict[str, ChannelFit], curves: dict[str, Any]) -> list[str]:
    """Per channel, where a model that was not fitted to this recording lies beyond the
    measured OADEV's scatter (:func:`imubench.noisefit.misfit.curve_misfit`, with
    :data:`~imubench.noisefit.misfit.MODEL_FILE_FLOOR` of model error): the pages then say
    so instead of showing another sensor's numbers as this one's. The EDF is the smaller
    of the curve's (Greenhall-Riley, of the power law identified at each tau) and the
    model's (:func:`~imubench.noisefit.model_avar.model_oavar_edf`), as in the fit: the
    identified law of a long tau's few terms can be white PM and its EDF ten times too
    large (a simulated LSM6DSL hour: 75 at 630 s, where the model's is ~6)."""
    notes: list[str] = []
    for ch, fit in fits.items():
        c = curves[ch]
        cm = fit.channel_model()
        edf = np.minimum(c.edf, model_oavar_edf(cm, c.m, c.n, fit.rate_hz))
        notes.extend(f"{ch}: {text}" for text in
                     curve_misfit(c.tau_s, c.dev**2, fit.model_avar(c.tau_s), edf,
                                  MODEL_FILE_FLOOR, fitted=False))
    return notes


def write_report(recording: str | Path, out_dir: str | Path, *, terms: str = "auto",
                 method: str = "wls", options: InputOptions | None = None,
                 model_file: str | Path | None = None,
                 fit_temperature: bool = False) -> list[Path]:
    """Fit the recording (read with ``options``; ``fit_temperature`` as for
    :func:`~imubench.noisefit.recording_fit.fit_loaded`), or take the noise values from
    ``model_file`` (a file or ``datasheet:CHIP``) without fitting, and write every report
    file into ``out_dir``; return the paths. The curves are of the data the noise terms
    describe (:meth:`~imubench.noisefit.recording_fit.RecordingFit.noise_data`: less a
    temperature response taken out or given by the model file). The model and the
    recording are read before anything is written, so a bad one leaves no folder behind."""
    from imubench.recording import load_recording

    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"--out {out} is a file; give a folder for the report")
    model = None if model_file is None else load_model(model_file)
    rec = load_recording(recording, options)
    with progress(100, "report", unit="%") as bar:
        if model is None:
            result = fit_loaded(rec, str(recording), terms=terms, method=method,
                                fit_temperature=fit_temperature,
                                on_channel=lambda done, total:
                                bar.fraction(FIT_SHARE * done / total))
        else:
            result = model_file_fit(model, rec, str(recording))
            bar.fraction(FIT_SHARE)
        out.mkdir(parents=True, exist_ok=True)
        data = {ch: result.noise_data(rec, ch) for ch in result.fits}
        n_samples = max(int(np.size(v)) for v in data.values())
        curves = {ch: oadev_curve(data[ch], result.rate_hz) for ch in result.fits}
        info = _info(result, n_samples, model,
                     ([result.coverage()] if result.lost_samples else [])
                     + ([] if model is None else misfit_notes(result.fits, curves)))
        files: list[Path] = []
        pages: list[Path] = []
        readouts: dict[str, dict[str, Readout]] = {}
        for k, (sensor, (chans, unit)) in enumerate(SENSORS.items()):
            fits = {ch: result.fits[ch] for ch in chans if ch in result.fits}
            if not fits:
                continue
            for ch in fits:
                readouts[ch] = ieee952_readouts(fits[ch], curves[ch])
            images = save_figure(sigma_tau_figure(
                _title("Allan deviation", result, sensor, info.duration_s), fits,
                {ch: curves[ch] for ch in fits}, {ch: readouts[ch] for ch in fits}, sensor),
                out / f"sigma_tau_{sensor}")
            bands = {ch: band_psd(data[ch], result.rate_hz) for ch in fits}
            images += save_figure(psd_figure(
                _title("amplitude spectral density", result, sensor, info.duration_s),
                fits, bands, sensor), out / f"psd_{sensor}")
            page = out / f"{sensor}.html"
            page.write_text(sensor_page(info, sensor, fits, readouts, images, unit),
                            encoding="utf-8")
            files += images
            pages.append(page)
            bar.fraction(FIT_SHARE + (1 - FIT_SHARE) * (k + 1) / len(SENSORS))
    files += pages + _write_fit_files(result, out, model, info, pages, files)
    return files


def _write_fit_files(result: RecordingFit, out: Path, model: NoiseModel | None,
                     info: PageInfo, pages: list[Path], plots: list[Path]) -> list[Path]:
    """model.toml (the model given, or the fit's), fit.json (with the model's source and
    its misfit notes), imu.yaml (when it can be written honestly) and index.html."""
    doc = result.to_dict()
    if model is not None:
        doc["model_file"] = model.source
        doc["model_notes"] = list(info.notes)
    (out / "model.toml").write_text((result.noise_model() if model is None else model)
                                    .to_toml(), encoding="utf-8")
    (out / "fit.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    written = [out / "model.toml", out / "fit.json"]
    kalibr_text: str | None = None
    kalibr_note: str | None = None
    try:
        kalibr_text = kalibr_yaml(result.kalibr())
    except FitError as exc:
        kalibr_note = f"imu.yaml not written: {exc}"
    if kalibr_text is not None:
        (out / "imu.yaml").write_text(kalibr_text, encoding="utf-8")
        written.append(out / "imu.yaml")
    index = out / "index.html"
    index.write_text(index_page(info, pages, plots + written, kalibr_text, kalibr_note),
                     encoding="utf-8")
    return [*written, index]


__all__ = ["SENSORS", "oadev_curve", "write_report"]
