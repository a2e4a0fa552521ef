"""``--report DIR``: the plots a user needs to believe the verdict, and an index.html.

Per channel: ``<ch>_adev.png/.svg`` (real OADEV against the model's mean and 5-95 %
band of the realisations, before and after adding the winning effect, on the fit part and
on the held-out part) and ``<ch>_evidence.png/.svg`` (the evidence behind the verdict:
temperature scatter, spectrum with its line, impulse histogram, or the per-tau z of the
Allan curves for the curve-shaped effects).
"""

from __future__ import annotations

import html
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from imubench.batch import UNITS
from imubench.gap.candidates import temperature_response, temperature_slope
from imubench.gap.curves import Comparison
from imubench.gap.errors import GapError
from imubench.gap.evidence import STEP_WINDOW_BLOCKS
from imubench.gap.explain import explain_channel, params_text
from imubench.gap.result import ChannelDiagnosis


def _adev_panel(ax: Any, title: str, before: Comparison, after: Comparison | None,
                label: str, unit: str) -> None:
    t = before.tau_s
    ax.fill_between(t, before.adev_sim_lo, before.adev_sim_hi, color="tab:blue", alpha=0.2,
                    label="model 5-95 %")
    ax.loglog(t, before.adev_sim, "-", color="tab:blue", label="model (mean)")
    if after is not None:
        ax.fill_between(t, after.adev_sim_lo, after.adev_sim_hi, color="tab:green",
                        alpha=0.2, label=f"model + {label} 5-95 %")
        ax.loglog(t, after.adev_sim, "--", color="tab:green", label=f"model + {label}")
    err = np.abs(before.adev_real * (np.exp(before.sigma) - 1.0))
    ax.errorbar(t, before.adev_real, yerr=err, fmt="o", color="k", ms=3, label="real")
    for r in before.regions:
        ax.axvspan(r.tau_min_s / 1.2, r.tau_max_s * 1.2, color="tab:red", alpha=0.08)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_title(f"{title}: gap {before.gap:.3f}"
                 + (f" -> {after.gap:.3f} with {label}" if after is not None
                    else " (no effect kept)"), fontsize=9)
    ax.set_xlabel("tau (s)")
    ax.set_ylabel(f"Allan deviation ({unit})")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)


def _evidence(ax: Any, d: ChannelDiagnosis) -> str:
    unit = UNITS.get(d.channel, "unit of the data")
    ev = d.evidence
    eff = d.verdict
    if eff == "temperature" and "temperature" in ev:
        tf = ev["temperature"]
        ax.plot(tf.block_temp_c, tf.block_rate, ".", ms=3, label="real (block means)")
        w = d.winner
        assert w is not None
        p = w.params
        tt = np.linspace(tf.block_temp_c.min(), tf.block_temp_c.max(), 50)
        yy = (temperature_response(p, tt, d.temp_ref_c) + np.mean(tf.block_rate)
              - np.mean(temperature_response(p, tf.block_temp_c, d.temp_ref_c)))
        tm = float(np.mean(tf.block_temp_c))
        slope = temperature_slope(p, tm, d.temp_ref_c)
        ax.plot(tt, yy, "r-", label=f"fit: {slope:.3g} {unit}/degC at {tm:.1f} degC")
        ax.set_xlabel("temperature (degC)")
        ax.set_ylabel(f"{d.channel} block mean ({unit})")
        ax.legend(fontsize=7)
        return f"temperature scatter ({'whole record' if w.whole_record else 'fit part'})"
    if eff == "ramp" and "ramp" in ev and d.winner is not None:
        t, means = ev["ramp"]
        ok = np.isfinite(means)
        ax.plot(t[ok], means[ok], ".", ms=3, color="k", label="real (block means)")
        slope = d.winner.params["ramp"]
        mid = float(np.mean(t[ok]))
        ax.plot(t[ok], float(np.mean(means[ok])) + slope * (t[ok] - mid), "r-",
                label=f"ramp {slope:.3g} {unit}/s")
        ax.set_xlabel("time in the fit part (s)")
        ax.set_ylabel(f"{d.channel} block mean ({unit})")
        ax.legend(fontsize=7)
        return "block means over time (fit part)"
    if eff == "bias_step" and "bias_step" in ev and d.winner is not None:
        t, means = ev["bias_step"]
        ok = np.isfinite(means)
        ax.plot(t[ok], means[ok], ".", ms=3, color="k", label="real (block means)")
        at, size = d.winner.params["step_time_s"], d.winner.params["step_size"]
        after = t >= at
        before = means[ok & ~after][-STEP_WINDOW_BLOCKS:]  # the fit's local level
        base = float(np.mean(before)) if before.size else float(np.mean(means[ok]))
        level = base + np.where(after, size, 0.0)
        ax.plot(t, level, "r-", label=f"step {size:.3g} {unit} at {at:.6g} s")
        ax.axvline(at, color="r", ls=":", lw=0.8)
        ax.set_xlabel("time in the record (s)")
        ax.set_ylabel(f"{d.channel} block mean ({unit})")
        ax.legend(fontsize=7)
        return "block means over the whole record (the step is located on it)"
    if eff == "outliers" and "outliers" in ev:
        of = ev["outliers"]
        ax.hist(of.detected / of.sigma, bins=40, color="tab:red")
        ax.axvline(of.threshold / of.sigma, color="k", ls="--")
        ax.axvline(-of.threshold / of.sigma, color="k", ls="--")
        ax.set_xlabel("impulse residual (robust sigmas)")
        ax.set_ylabel("count")
        return (f"impulses beyond the threshold: rate {of.outlier_rate:.3g}/s, amplitude "
                f"{of.outlier_amplitude:.3g} {unit}")
    if eff in ("sine", "resonance") or d.before.bands:
        f, real, sim = ev["psd"]
        ax.loglog(f[1:], real[1:], "k-", lw=0.7, label="real")
        ax.loglog(f[1:], sim[1:], "b-", lw=1.0, label="model (mean of realisations)")
        w = d.winner
        sine = next((c for c in d.kept if c.effect == "sine"), None)  # also kept 2nd or 3rd
        if sine is not None:
            ax.axvline(sine.params["sine_freq"], color="r", ls=":", lw=0.8, alpha=0.6,
                       label=f"line {sine.params['sine_freq']:.4g} Hz")  # the peak stays visible
        if eff == "resonance" and w is not None:
            p = w.params
            fc, width = p["resonance_freq_hz"], p["resonance_width_hz"]
            line = p["resonance_height"] / (1.0 + (2.0 * (f - fc) / width) ** 2)
            ax.loglog(f[1:], (sim + line)[1:], "r--", lw=1.0,
                      label=f"model + resonance {fc:.4g} Hz, -3 dB width {width:.3g} Hz")
        ax.set_xlabel("frequency (Hz)")
        ax.set_ylabel(f"PSD ({unit}^2/Hz)")
        ax.legend(fontsize=7)
        return "Welch spectrum (fit part)"
    ax.semilogx(d.before.tau_s, d.before.z, "o-", label="model")
    if d.final_fit is not None:
        ax.semilogx(d.before.tau_s, d.final_fit.z, "s--",
                    label="model + " + " + ".join(c.effect for c in d.kept))
    ax.axhline(0, color="k", lw=0.5)
    for zz in (-3.5, 3.5):
        ax.axhline(zz, color="r", ls=":", lw=0.8)
    ax.set_xlabel("tau (s)")
    ax.set_ylabel("z = ln(real/model) / band")
    ax.legend(fontsize=7)
    return "per-tau z of the Allan curves (fit part)"


def write_report(out_dir: Path, result: dict[str, Any], diags: dict[str, ChannelDiagnosis],
                 rate_hz: float) -> Path:
    """Write the plots and index.html into out_dir; returns the index path."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise GapError(f"--report {out_dir}: cannot create ({exc.strerror})") from exc
    rows = []
    for ch, d in diags.items():
        label = " + ".join(c.effect for c in d.kept)
        n_pan = 2 if d.holdout_before is not None else 1
        fig, axes = plt.subplots(1, n_pan, figsize=(6 * n_pan, 4.5), squeeze=False)
        unit = UNITS.get(ch, "unit of the data")
        _adev_panel(axes[0][0], f"{ch} fit part", d.before, d.final_fit, label, unit)
        if d.holdout_before is not None:
            _adev_panel(axes[0][1], f"{ch} held out", d.holdout_before, d.final_holdout,
                        label, unit)
        fig.suptitle(f"{ch}: verdict {d.verdict}" + (f" ({d.reason})" if d.reason else "")
                     + (f"; kept {label}" if label else ""))
        fig.tight_layout()
        for ext in ("png", "svg"):
            fig.savefig(out_dir / f"{ch}_adev.{ext}", dpi=110)
        plt.close(fig)
        fig, ax = plt.subplots(figsize=(6, 4.5))
        caption = _evidence(ax, d)
        ax.set_title(f"{ch}: {caption}", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        fig.tight_layout()
        for ext in ("png", "svg"):
            fig.savefig(out_dir / f"{ch}_evidence.{ext}", dpi=110)
        plt.close(fig)
        c = result["channels"][ch]
        kept = [k["effect"] for k in c.get("kept", [])]
        units = result["units"]["params"][ch]
        eff_rows = "".join(
            f"<tr><td>{html.escape(e['effect'])}</td>"
            f"<td>{html.escape(params_text(e['params'], units))}</td>"
            f"<td>{_num(e['gap_after'])}</td><td>{_num(e.get('holdout_gap_after'))}"
            f"</td><td>{_num(e['score'])}</td><td>{_kept_cell(e, kept)}</td></tr>"
            for e in c["effects"])
        hold = c.get("holdout") or {}
        rows.append(
            f"<h2>{ch}: verdict <b>{html.escape(c['verdict'])}</b></h2>"
            f"<p>gap {_num(c['gap_before'])} &rarr; {_num(c['gap_after'])} (fit part); "
            f"held out {_num(hold.get('gap_before'))} &rarr; {_num(hold.get('gap_after'))}; "
            f"regions: {html.escape(_regions(c['regions']))}</p>"
            "<ul>" + "".join(f"<li>{html.escape(s)}</li>"
                             for s in explain_channel(c, result["realisations"], units))
            + "</ul>"
            f"<img src='{ch}_adev.png'><img src='{ch}_evidence.png'>"
            + _kept_table(c.get("kept", []), units)
            + "<h3>First step's candidates</h3>"
            "<table border=1><tr><th>effect</th><th>params</th><th>gap after</th>"
            f"<th>held-out gap after</th><th>score</th><th>kept?</th></tr>{eff_rows}</table>"
            + _limits_table(c.get("limits"))
        )
    index = out_dir / "index.html"
    index.write_text(
        "<!doctype html><html><head><meta charset='utf-8'><title>imubench gap</title>"
        "</head><body><h1>Sim-to-real gap</h1>"
        f"<p>recording {html.escape(str(result['recording']))}, model "
        f"{html.escape(str(result['model']))}, {rate_hz:g} Hz, "
        f"{result['realisations']} realisations, seed {result['seed']}</p>"
        + "".join(rows) + "</body></html>\n", encoding="utf-8")
    return index


def _kept_table(kept: list[dict[str, Any]], units: dict[str, str]) -> str:
    """The kept effects in order, each with its parameters +- their standard errors (and
    a bootstrap bias beyond them) and the gaps after it; empty when none was kept."""
    if not kept:
        return ""
    rows = "".join(
        f"<tr><td>{i}</td><td>{html.escape(k['effect'])}</td>"
        f"<td>{html.escape(params_text(k['params'], units, k))}</td>"
        f"<td>{_num(k['gap_after'])}</td><td>{_num(k.get('holdout_gap_after'))}</td></tr>"
        for i, k in enumerate(kept, 1))
    return ("<h3>Kept effects (values +- one standard error)</h3><table border=1><tr>"
            "<th>step</th><th>effect</th><th>params</th><th>gap after</th>"
            f"<th>held-out gap after</th></tr>{rows}</table>")


def _num(v: Any) -> str:
    return "-" if v is None else f"{v:.3g}"


def _regions(regs: list[dict[str, Any]]) -> str:
    if not regs:
        return "none"
    return "; ".join(f"{r['tau_min_s']:.3g}-{r['tau_max_s']:.3g} s {r['direction']}"
                     for r in regs)


def _kept_cell(e: dict[str, Any], kept: list[str]) -> str:
    """'kept' (step 1), 'kept at step k' (the effect was refitted and kept after the
    effects before it), the refusal, or 'not examined' (a better-scoring candidate was
    kept at that step)."""
    if e.get("accepted"):
        return "kept"
    if e["effect"] in kept[1:]:
        i = kept.index(e["effect"])
        return f"kept at step {i + 1} (refitted after " + html.escape(", ".join(kept[:i])) + ")"
    return html.escape(e.get("rejected_because") or "not examined")


def _limits_table(lim: dict[str, Any] | None) -> str:
    if not lim:
        return ""
    rows = "".join(
        f"<tr><td>{html.escape(eff)}</td><td>{html.escape(e['key'])}</td>"
        f"<td>{_num(e.get('smallest_identified'))}</td><td>"
        + ", ".join(f"{t['size']:.3g}: {t['identified']}/{t['of']}" for t in e["tried"])
        + "</td></tr>" for eff, e in lim["effects"].items())
    return (f"<h3>Detection limits on this recording</h3><p>{html.escape(lim['note'])}</p>"
            "<table border=1><tr><th>effect</th><th>key</th><th>smallest identified</th>"
            f"<th>sizes tried (identified/injections)</th></tr>{rows}</table>")
