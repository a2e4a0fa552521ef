"""The report's HTML: one self-contained page per sensor and an index.

A sensor page holds what an engineer copies into a datasheet comparison: per channel the
noise density, random walk (angle or velocity), bias instability, Allan deviation floor
and rate / acceleration random walk in datasheet units with 95 % intervals, the IEEE 952
reading of B on the measured minimum, the datasheet typical beside them where the chip's
shipped model file states a datasheet source for that term (its ``meta.<term>_source``;
values the file marks as placeholders are not shown as datasheet values), every other
term the model holds, the notes of the fit, and the two plots embedded as PNG data.
"""

from __future__ import annotations

import base64
import html
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from lsm6ds_sim.model import DATASHEET_PREFIX, NoiseModel, datasheet_chips, load_model

from imubench.noisefit.fit import ChannelFit
from imubench.noisefit.ieee952 import Readout, fmt, fmt_interval
from imubench.noisefit.units import WHITE_EQUIVALENT, Quantity, quantities, term_value

STYLE = """body{font-family:sans-serif;margin:1em;max-width:1100px}
td,th{border:1px solid #bbb;padding:2px 6px;font-size:12px}th{background:#eee}
table{border-collapse:collapse;margin:0.4em 0}td.num{text-align:right;white-space:nowrap}
p,li{font-size:13px}.note{color:#555;font-size:12px}img{max-width:49%}
@media print{img{max-width:49%}h1{font-size:16px}}"""

OTHER_PARAMS: dict[str, tuple[str, str]] = {
    "ramp": ("rate ramp R", "{u}/s"),
    "quantization": ("quantization Q", "{u}·s"),
    "markov_sigma": ("Gauss-Markov σ", "{u}"),
    "markov_tau": ("Gauss-Markov correlation time", "s"),
    "sine_amplitude": ("sine amplitude (peak)", "{u}"),
    "sine_freq": ("sine frequency", "Hz"),
    "bandwidth_hz": ("output low-pass bandwidth", "Hz"),
    "filter_order": ("output low-pass order", ""),
    "output_white": ("white noise after the low-pass", "{u}/√Hz"),
    "resonance_freq_hz": ("resonance centre", "Hz"),
    "resonance_width_hz": ("resonance -3 dB width", "Hz"),
    "resonance_height": ("resonance peak PSD (one-sided, before the low-pass)", "{u}²/Hz"),
}
"""Model-file keys beyond N, B, K: human label and unit (``{u}`` = dps or g)."""


@dataclass(frozen=True)
class PageInfo:
    """What every page says about where the numbers come from."""

    recording: str
    rate_hz: float
    duration_s: float
    chip: str | None
    method: str
    model_file: str | None
    notes: tuple[str, ...] = ()


def datasheet_typicals(chip: str | None) -> tuple[NoiseModel | None, dict[str, str]]:
    """The chip's shipped datasheet-typical model and, per term, the source note of the
    terms it states as datasheet values (``meta.<term>_source``); (None, {}) if none."""
    if not chip or chip.lower() not in datasheet_chips():
        return None, {}
    model = load_model(DATASHEET_PREFIX + chip.lower())
    sources = {k[: -len("_source")]: str(v) for k, v in model.meta.items()
               if k.endswith("_source")}
    return model, sources


def _cell(fit: ChannelFit, q: Quantity) -> str:
    """Value [95 % interval] of a fitted quantity, or what stands in for it."""
    value, ci = fit.coefficient(q.term)
    v = value * q.factor
    if v <= 0:
        if ci is not None and ci[1] > 0:
            return f"not detected (&lt; {fmt(ci[1] * q.factor)})"
        return "not in the model" if not fit.ci else "not detected"
    if ci is None:
        return f"{fmt(v)} <span class=note>(no interval)</span>"
    return fmt_interval(v, ci[0] * q.factor, ci[1] * q.factor)


def _datasheet_cell(q: Quantity, chans: Sequence[str], typical: NoiseModel | None,
                    sources: Mapping[str, str]) -> str:
    source_key = "white" if q.term == WHITE_EQUIVALENT else q.term
    if typical is None or source_key not in sources:
        return "-"
    values = sorted({fmt(term_value(typical[ch].to_dict(), q.term) * q.factor)
                     for ch in chans})
    return " / ".join(values) + " *"


def _readout_row(readouts: Mapping[str, Mapping[str, Readout]], chans: Sequence[str],
                 q: Quantity) -> str:
    cells = []
    for ch in chans:
        r = readouts[ch]["B"]
        tau = "" if r.tau_s is None else f" at τ = {r.tau_s:.3g} s"
        cells.append(f"<td class=num>{html.escape(r.text(q, unit=False))}{tau}</td>")
    return (f"<tr><td>bias instability, IEEE 952 reading σ<sub>min</sub>/0.664 of the "
            f"measured OADEV</td><td>{q.unit}</td>{''.join(cells)}<td>-</td></tr>")


def sensor_table(fits: Mapping[str, ChannelFit], readouts: Mapping[str, Mapping[str, Readout]],
                 chip: str | None) -> str:
    """The datasheet-comparison table of one sensor's channels (module docstring)."""
    chans = list(fits)
    typical, sources = datasheet_typicals(chip)
    head = "".join(f"<th>{ch}</th>" for ch in chans)
    rows = []
    for q in quantities(chans[0]):
        cells = "".join(f"<td class=num>{_cell(fits[ch], q)}</td>" for ch in chans)
        rows.append(f"<tr><td>{html.escape(q.label)}</td><td>{html.escape(q.unit)}</td>"
                    f"{cells}<td class=num>{_datasheet_cell(q, chans, typical, sources)}"
                    "</td></tr>")
        if q.key.startswith("bias_instability"):
            rows.append(_readout_row(readouts, chans, q))
    ds_head = (f"{html.escape(chip)} datasheet typical" if chip and typical is not None
               else "datasheet")
    foot = "".join(f"<li>* {html.escape(term)}: {html.escape(src)}</li>"
                   for term, src in sources.items())
    if typical is not None:
        foot += ("<li>Terms without a datasheet source in the shipped model file are "
                 "placeholders there and are not shown as datasheet values.</li>")
    return (f"<table><tr><th>quantity</th><th>unit</th>{head}<th>{ds_head}</th></tr>"
            f"{''.join(rows)}</table><ul class=note>{foot}</ul>")


def other_terms(fits: Mapping[str, ChannelFit], unit: str) -> str:
    """A list of the model's terms beyond N, B, K per channel (empty string if none)."""
    items = []
    for ch, fit in fits.items():
        parts = []
        for key, (label, u) in OTHER_PARAMS.items():
            if key not in fit.present:
                continue
            v = float(fit.params[key])
            ci = fit.ci.get(key)
            text = fmt(v) if ci is None else fmt_interval(v, *ci)
            parts.append(f"{label} {text} {u.format(u=unit)}".rstrip())
        if parts:
            items.append(f"<li>{ch}: {html.escape('; '.join(parts))}</li>")
    return f"<h3>Other terms in the model</h3><ul>{''.join(items)}</ul>" if items else ""


def _source_paragraph(info: PageInfo) -> str:
    where = (f"values from the model file <code>{html.escape(info.model_file)}</code> "
             "(not refitted); the model file holds no confidence intervals, so none are "
             "shown for them (refit without <code>--model</code> to get them)"
             if info.model_file else f"fitted by method <code>{html.escape(info.method)}"
             "</code>; intervals are 95 %")
    return (f"<p>Recording <code>{html.escape(info.recording)}</code>: "
            f"{info.rate_hz:g} Hz, {info.duration_s / 3600:.3g} h, chip "
            f"{html.escape(str(info.chip or 'unknown'))}. Noise {where}. The "
            "IEEE 952 minimum reading is read on the measured curve, with the chi-squared "
            "interval of that point when the curve shows a floor, else as an upper bound "
            "(&lt; value: the curve shows no established floor).</p>")


def _png(path: Path) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return f'<img alt="{html.escape(path.stem)}" src="data:image/png;base64,{data}">'


def sensor_page(info: PageInfo, sensor: str, fits: Mapping[str, ChannelFit],
                readouts: Mapping[str, Mapping[str, Readout]], images: Sequence[Path],
                unit: str) -> str:
    """One self-contained page for ``sensor`` ("gyro" or "accel")."""
    by_note: dict[str, list[str]] = {}
    for ch, f in fits.items():
        for n in f.notes:
            by_note.setdefault(n, []).append(ch)
    notes = [f"{', '.join(chs)}: {n}" for n, chs in by_note.items()] + list(info.notes)
    note_html = "".join(f"<li>{html.escape(n)}</li>" for n in notes)
    name = Path(info.recording).name
    return f"""<!doctype html><html><head><meta charset="utf-8">
<title>{sensor} noise: {html.escape(name)}</title><style>{STYLE}</style></head><body>
<h1>{'Gyroscope' if sensor == 'gyro' else 'Accelerometer'} noise: {html.escape(name)}</h1>
{_source_paragraph(info)}
{sensor_table(fits, readouts, info.chip)}
{other_terms(fits, unit)}
<div>{''.join(_png(p) for p in images if p.suffix == '.png')}</div>
<h3>Notes</h3><ul class=note>{note_html or '<li>none</li>'}</ul>
</body></html>
"""


def index_page(info: PageInfo, pages: Sequence[Path], files: Sequence[Path],
               kalibr_text: str | None, kalibr_note: str | None) -> str:
    """The report's index: links to the sensor pages and files, the Kalibr values."""
    links = "".join(f'<li><a href="{p.name}">{html.escape(p.stem)}</a></li>' for p in pages)
    file_links = "".join(f'<li><a href="{p.name}">{p.name}</a></li>' for p in files)
    kal = (f"<pre>{html.escape(kalibr_text)}</pre>" if kalibr_text is not None
           else f"<p>{html.escape(kalibr_note or 'not written')}</p>")
    return f"""<!doctype html><html><head><meta charset="utf-8">
<title>imubench report: {html.escape(Path(info.recording).name)}</title>
<style>{STYLE}</style></head><body>
<h1>Noise report: {html.escape(info.recording)}</h1>
{_source_paragraph(info)}
<h2>Sensor summaries</h2><ul>{links}</ul>
<h2>Kalibr imu.yaml</h2>{kal}
<h2>Files</h2><ul>{file_links}</ul>
</body></html>
"""


__all__ = ["OTHER_PARAMS", "PageInfo", "datasheet_typicals", "index_page", "other_terms",
           "sensor_page", "sensor_table"]
