"""The ``imubench report`` output: sigma-tau and PSD plots, fit files, one-page HTML.

Per sensor (gyro gx gy gz, accel ax ay az) a sigma-tau plot: OADEV with its 95 % chi-squared
error bars (EDF per point), MDEV, the fitted model (solid) and each present term's own line
(dashed), with the local ADEV slope written at each decade; and a PSD plot (Welch, one
sided, unit^2/Hz) with the model's white level 2 N^2. PNG and SVG through matplotlib's Agg
backend. The fit goes to ``model.toml`` (loads in the simulator) and ``fit.json``.
"""

from __future__ import annotations

import html
import json
from pathlib import Path
from typing import Any

import numpy as np

from imubench.noisefit.recording_fit import RecordingFit, fit_loaded
from imubench.noisefit.units import kalibr_yaml
from imubench.progress import progress
from imubench.recording.options import InputOptions

SENSORS = {"gyro": (("gx", "gy", "gz"), "dps"), "accel": (("ax", "ay", "az"), "g")}
COLORS = {"x": "tab:blue", "y": "tab:orange", "z": "tab:green"}


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _finish(plt, fig, ax, stem: Path) -> list[Path]:  # type: ignore[no-untyped-def]
    """Grid, legend and layout of one plot; save it as ``stem.png`` and ``stem.svg``."""
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=3)
    fig.tight_layout()
    paths = [stem.with_suffix(".png"), stem.with_suffix(".svg")]
    for p in paths:
        fig.savefig(p, dpi=110)
    plt.close(fig)
    return paths


def _fitted_channels(result: RecordingFit, sensor: str) -> tuple[tuple[str, ...], str]:
    """The channels of ``sensor`` ("gyro" or "accel") that were fitted, and their unit."""
    chans, unit = SENSORS[sensor]
    return tuple(c for c in chans if c in result.fits), unit


def sigma_tau_plot(result: RecordingFit, data: dict[str, np.ndarray], sensor: str,
                   out: Path) -> list[Path]:
    """Write ``sigma_tau_<sensor>.png/.svg``; return the paths (none if no channel)."""
    from imubench.stats import mdev, oadev

    chans, unit = _fitted_channels(result, sensor)
    if not chans:
        return []
    plt = _plt()
    fig, ax = plt.subplots(figsize=(9, 6.5))
    for ch in chans:
        f = result.fits[ch]
        color = COLORS[ch[1]]
        r = oadev(data[ch], result.rate_hz, "freq", "octave", confidence=0.95)
        ax.errorbar(r.tau_s, r.dev, yerr=[r.dev - r.ci_low, r.ci_high - r.dev], fmt="o",
                    ms=4, color=color, capsize=2, label=f"{ch} OADEV (95 % CI)")
        md = mdev(data[ch], result.rate_hz, "freq", "octave")
        ax.plot(md.tau_s, md.dev, "^", ms=3, color=color, alpha=0.5, label=f"{ch} MDEV")
        m = np.unique(np.rint(np.geomspace(r.m[0], r.m[-1], 200)))
        tau = m / result.rate_hz  # whole samples: no staircase from rounding
        ax.plot(tau, np.sqrt(f.model_avar(tau)), "-", color=color, lw=1.5,
                label=f"{ch} fitted model")
        for term, av in f.term_avars(tau).items():
            ax.plot(tau, np.sqrt(av), "--", color=color, lw=0.8, alpha=0.7)
            k = int(np.argmax(av))
            ax.annotate(term, (tau[k], np.sqrt(av[k])), fontsize=7, color=color, alpha=0.8)
        slopes = np.gradient(np.log(r.dev), np.log(r.tau_s)) if r.tau_s.size > 1 else []
        for i in range(0, r.tau_s.size, 3):
            ax.annotate(f"{slopes[i]:+.2f}", (r.tau_s[i], r.ci_high[i]), fontsize=6,
                        color=color, textcoords="offset points", xytext=(0, 4), ha="center")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("averaging time tau (s)")
    ax.set_ylabel(f"Allan deviation ({unit})")
    ax.set_title(f"{sensor}: {Path(result.source).name}  ({result.rate_hz:g} Hz; "
                 "dashed: fitted terms; numbers: local ADEV slope)")
    return _finish(plt, fig, ax, out / f"sigma_tau_{sensor}")


def psd_plot(result: RecordingFit, data: dict[str, np.ndarray], sensor: str,
             out: Path) -> list[Path]:
    """Write ``psd_<sensor>.png/.svg`` (Welch, Hann, 4096-sample segments)."""
    from scipy.signal import welch

    chans, unit = _fitted_channels(result, sensor)
    if not chans:
        return []
    plt = _plt()
    fig, ax = plt.subplots(figsize=(9, 5.5))
    for ch in chans:
        y = data[ch]
        y = y[np.isfinite(y)]
        f, p = welch(y - y.mean(), fs=result.rate_hz, nperseg=min(1 << 12, y.size))
        ax.loglog(f[1:], p[1:], color=COLORS[ch[1]], lw=0.8, label=f"{ch} Welch PSD")
        n = result.fits[ch].params.get("white", 0.0)
        if n > 0:
            ax.axhline(2 * n * n, color=COLORS[ch[1]], ls="--", lw=0.8,
                       label=f"{ch} white 2N^2")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"PSD ({unit}^2/Hz, one-sided)")
    ax.set_title(f"{sensor} PSD: {Path(result.source).name}")
    return _finish(plt, fig, ax, out / f"psd_{sensor}")


def _html(result: RecordingFit, doc: dict, images: list[Path]) -> str:
    rows = []
    for ch, c in doc["channels"].items():
        terms = ", ".join(
            f"{k} = {c['params'][k]:.4g} [{c['ci95'][k][0]:.3g}, {c['ci95'][k][1]:.3g}]"
            for k in c["present"] if k in c["ci95"])
        units = ", ".join(f"{k} {v:.4g}" for k, v in c["datasheet_units"].items())
        rows.append(f"<tr><td>{ch}</td><td>{html.escape(terms)}</td>"
                    f"<td>{html.escape(units)}</td></tr>")
    comp = "".join(
        f"<li>{ch}: fitted N {v['fitted']:.4g}, datasheet typical {v['typical']:.4g}, "
        f"ratio {v['ratio']:.2f}</li>" for ch, v in doc["datasheet_comparison"].items())
    imgs = "".join(f'<img src="{p.name}" style="max-width:48%">' for p in images
                   if p.suffix == ".png")
    kal = html.escape(kalibr_yaml(doc["kalibr"]))
    return f"""<!doctype html><html><head><meta charset="utf-8">
<title>imubench report: {html.escape(Path(result.source).name)}</title>
<style>body{{font-family:sans-serif;margin:1em}} td,th{{border:1px solid #ccc;padding:3px;
font-size:12px}} table{{border-collapse:collapse}}</style></head><body>
<h1>Noise report: {html.escape(str(result.source))}</h1>
<p>rate {result.rate_hz:g} Hz, chip {html.escape(str(result.chip))}, method {result.method}.
Values in model units (dps, g); 95 % intervals. Files: model.toml (simulator model),
fit.json, imu.yaml (Kalibr).</p>
<table><tr><th>channel</th><th>terms present (value [95 % CI])</th>
<th>datasheet units</th></tr>{''.join(rows)}</table>
<h2>Datasheet comparison</h2><ul>{comp or '<li>chip unknown or no shipped model</li>'}</ul>
<h2>Kalibr imu.yaml</h2><pre>{kal}</pre>
<h2>Plots</h2>{imgs}
</body></html>
"""


def write_report(recording: str | Path, out_dir: str | Path, *, terms: str = "auto",
                 method: str = "wls", options: InputOptions | None = None) -> list[Path]:
    """Fit the recording (read with ``options``) and write every report file into
    ``out_dir``; return the paths."""
    from imubench.recording import load_recording

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rec = load_recording(recording, options)
    with progress(100, "report: fit", unit="%") as bar:
        result = fit_loaded(rec, str(recording), terms=terms, method=method,
                            on_channel=lambda done, total: bar.fraction(done / total))
    data = {ch: rec.channel(ch) for ch in result.fits}
    files: list[Path] = []
    for sensor in SENSORS:
        files += sigma_tau_plot(result, data, sensor, out)
        files += psd_plot(result, data, sensor, out)
    doc = result.to_dict()
    (out / "model.toml").write_text(result.noise_model().to_toml(), encoding="utf-8")
    (out / "fit.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    (out / "imu.yaml").write_text(kalibr_yaml(doc["kalibr"]), encoding="utf-8")
    (out / "index.html").write_text(_html(result, doc, files), encoding="utf-8")
    files += [out / "model.toml", out / "fit.json", out / "imu.yaml", out / "index.html"]
    return files


__all__ = ["psd_plot", "sigma_tau_plot", "write_report"]
