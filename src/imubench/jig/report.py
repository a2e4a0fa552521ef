"""The run's result (``result.json``) and its HTML report with plots.

``result.json`` (format ``imubench-jig-result``, version 1): ``verdict``, ``exit_status``,
``serial``, ``station``, ``sensor``, ``run_id``, ``started_utc``, ``finished_utc``,
``wall_time_s``, ``source_time_s`` (the DUT's own time: virtual on a simulator),
``dut``, ``fixture``, ``station_file``, ``limits_file``, ``measurements`` (every field of
:class:`~imubench.jig.measurement.Measurement`), ``tests`` (each test's outcome and
message), ``calibration`` (file name in the run directory, or null), ``telemetry``,
``junit``, ``report``. Verdict: FAIL if a measurement failed or a test failed or errored
without a measurement saying why, else INCONCLUSIVE if any measurement was, else PASS;
exit status 0 / 1 / 3 for PASS / FAIL / INCONCLUSIVE.

The HTML report (``report.html``) shows the verdict, every measurement against its
limits with its interval, the failing tests, and three plots: sigma-tau with the
confidence intervals and the limit lines (the noise-density limit as ``N / sqrt(tau)``,
the bias-instability limit as ``0.664 B``), the calibration residuals (six positions and
rate table), and the offsets over the temperature sweep with the three fits; then the
board's tilt error budget before and after each calibration step.
"""

from __future__ import annotations

import html
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from imubench.jig.measurement import FAIL, INCONCLUSIVE, PASS, overall
from imubench.recording.commit import replace_text

FORMAT = "imubench-jig-result"
EXIT_STATUS = {PASS: 0, FAIL: 1, INCONCLUSIVE: 3}
CHANNELS = ("gx", "gy", "gz", "ax", "ay", "az")


def build_result(raw: dict[str, Any], *, serial: str, station: str, sensor: str, run_id: str,
                 started_utc: str, finished_utc: str, wall_time_s: float) -> dict[str, Any]:
    """The result document from the plugin's measurements.json content ``raw``."""
    measurements = raw.get("measurements", [])
    tests = raw.get("tests", [])
    verdicts = [m["verdict"] for m in measurements]
    measured_tests = {m["test"] for m in measurements}
    broken = [t for t in tests if t["outcome"] == "failed"
              and (t["nodeid"] not in measured_tests or t["when"] != "call")]
    if broken:
        verdicts.append(FAIL)
    unsure = [t for t in tests if t["outcome"] == "skipped"
              and str(t.get("message", "")).startswith("INCONCLUSIVE")
              and t["nodeid"] not in measured_tests]
    if unsure:
        verdicts.append(INCONCLUSIVE)  # a test that could not measure (too short a capture)
    if not measurements and not broken:
        verdicts.append(INCONCLUSIVE)  # nothing was measured: nothing can pass
    verdict = overall(verdicts)
    art = raw.get("artifacts", {})
    return {
        "format": FORMAT,
        "version": 1,
        "verdict": verdict,
        "exit_status": EXIT_STATUS[verdict],
        "serial": serial,
        "station": station,
        "sensor": sensor,
        "run_id": run_id,
        "started_utc": started_utc,
        "finished_utc": finished_utc,
        "wall_time_s": wall_time_s,
        "source_time_s": raw.get("source_time_s"),
        "dut": raw.get("dut"),
        "fixture": raw.get("fixture"),
        "station_file": raw.get("station_file"),
        "station_sha256": raw.get("station_sha256"),
        "limits_file": raw.get("limits_file"),
        "limits_sha256": raw.get("limits_sha256"),
        "software": raw.get("software"),
        "measurements": measurements,
        "tests": tests,
        "broken_tests": [t["nodeid"] for t in broken],
        "broken_reasons": {t["nodeid"]: first_line(t.get("message", "")) for t in broken},
        "inconclusive_tests": {t["nodeid"]: str(t["message"]).removeprefix("INCONCLUSIVE: ")
                               for t in unsure},
        "calibration": art.get("calibration_file"),
        "telemetry": raw.get("telemetry"),
        "junit": "junit.xml",
        "report": "report.html",
    }


def first_line(message: str) -> str:
    """The line of a test's failure message that says why (pytest puts the exception's
    ``Type: text`` last in its short form), at most 300 characters."""
    lines = [ln.strip() for ln in str(message).splitlines() if ln.strip()]
    if not lines:
        return ""
    why = next((ln for ln in reversed(lines) if "Error:" in ln), lines[-1])
    return why[:300]


# ------------------------------------------------------------------------- plots
def _plot_sigma_tau(art: dict[str, Any], path: Path) -> bool:
    data = art.get("sigma_tau")
    if not data:
        return False
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, chans, unit in ((axes[0], CHANNELS[:3], "dps"), (axes[1], CHANNELS[3:], "g")):
        for ch in chans:
            d = data.get(ch)
            if not d:
                continue
            tau = np.array(d["tau_s"], float)
            dev = np.array([np.nan if v is None else v for v in d["dev"]], float)
            lo = np.array([np.nan if v is None else v for v in d["ci_low"]], float)
            hi = np.array([np.nan if v is None else v for v in d["ci_high"]], float)
            line = ax.errorbar(tau, dev, yerr=[dev - lo, hi - dev], marker="o", ms=3,
                               capsize=2, label=ch)
            color = line[0].get_color()
            n_lim = d.get("density_limit")
            if n_lim is not None and math.isfinite(n_lim):
                ax.plot(tau, n_lim / np.sqrt(tau), ls="--", color=color, lw=0.8)
            b_lim = d.get("bias_instability_limit")
            if b_lim is not None and math.isfinite(b_lim):
                ax.axhline(0.664 * b_lim, ls=":", color=color, lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("tau (s)")
        ax.set_ylabel(f"OADEV ({unit})")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Overlapping Allan deviation with confidence intervals; dashed: noise "
                 "density limit, dotted: bias instability limit", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return True


def _plot_residuals(art: dict[str, Any], path: Path) -> bool:
    six, rt = art.get("six_position"), art.get("rate_table")
    if not six and not rt:
        return False
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    if six:
        faces = six["faces"]
        x = np.arange(len(faces))
        for j, axis in enumerate("xyz"):
            for key, style in (("residuals_12_mg", "o"), ("residuals_15_mg", "s")):
                r = np.array(six[key], float)[:, j]
                se = np.array(six["stderr_mg"], float)[:, j]
                axes[0].errorbar(x + 0.1 * j + (0.03 if style == "s" else 0), r, yerr=se,
                                 fmt=style, ms=4, capsize=2,
                                 label=f"a{axis} {'12' if style == 'o' else '15'} par.")
        axes[0].set_xticks(x + 0.1, faces)
        axes[0].axhline(0, color="k", lw=0.5)
        axes[0].set_ylabel("residual (mg)")
        axes[0].set_title("six-position fit residuals (+-SE)", fontsize=9)
        axes[0].legend(fontsize=7, ncol=2)
    if rt:
        r = np.array(rt["residuals_dps"], float)
        se = np.array(rt["stderr_dps"], float)
        x = np.arange(len(r))
        for j, axis in enumerate("xyz"):
            axes[1].errorbar(x + 0.1 * j, 1e3 * r[:, j], yerr=1e3 * se[:, j], fmt="o", ms=3,
                             capsize=2, label=f"g{axis}")
        axes[1].axhline(0, color="k", lw=0.5)
        axes[1].set_xlabel("rate-table capture")
        axes[1].set_ylabel("residual (mdps)")
        axes[1].set_title("rate-table fit residuals (+-SE)", fontsize=9)
        axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return True


def _plot_temperature(art: dict[str, Any], path: Path) -> bool:
    t = art.get("temperature")
    if not t:
        return False
    import matplotlib.pyplot as plt

    die = np.array(t["die_c"], float)
    grid = np.linspace(die.min(), die.max(), 100)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, sensor, scale, unit in ((axes[0], "gyro", 1e3, "mdps"), (axes[1], "accel", 1e3,
                                                                          "mg")):
        s = t.get(sensor)
        if not s:
            continue
        off = np.array(s["offsets"], float)
        for j, axis in enumerate("xyz"):
            p = ax.plot(die, scale * off[:, j], "o", label=f"{sensor[0]}{axis}")
            color = p[0].get_color()
            for method, style in (("polynomial", "-"), ("three-point-note", "--"),
                                  ("three-point-exact", ":")):
                f = s["fits"][method]
                d = grid - f["temp_ref_c"]
                y = f["offset"][j] + d * (f["coeff1"][j] + d * f["coeff2"][j])
                ax.plot(grid, scale * y, style, color=color, lw=0.8)
        ax.set_xlabel("die temperature (degC)")
        ax.set_ylabel(f"offset ({unit})")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle("offsets over the chamber sweep; solid: least-squares quadratic, dashed: "
                 "the note's three-point, dotted: exact quadratic through the 3 points",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return True


# ------------------------------------------------------------------------- HTML
def _fmt(v: Any) -> str:
    if v is None:
        return "&ndash;"
    if isinstance(v, float):
        return f"{v:.5g}"
    return html.escape(str(v))


def write_report(run_dir: Path, result: dict[str, Any], artifacts: dict[str, Any]) -> Path:
    """Write ``plots/*.png`` and ``report.html`` into ``run_dir``."""
    import matplotlib

    matplotlib.use("Agg")
    plots = run_dir / "plots"
    plots.mkdir(exist_ok=True)
    figures = []
    for name, fn, caption in (
        ("sigma_tau.png", _plot_sigma_tau, "Allan deviation (static capture)"),
        ("residuals.png", _plot_residuals, "Calibration residuals"),
        ("temperature.png", _plot_temperature, "Offsets over temperature"),
    ):
        if fn(artifacts, plots / name):
            figures.append((f"plots/{name}", caption))
    colour = {PASS: "#2e7d32", FAIL: "#c62828", INCONCLUSIVE: "#ef6c00"}
    rows = []
    for m in result["measurements"]:
        rows.append(
            f"<tr><td>{_fmt(m['name'])}</td><td>{_fmt(m['value'])}</td><td>{_fmt(m['unit'])}"
            f"</td><td>{_fmt(m['low'])}</td><td>{_fmt(m['high'])}</td><td>{_fmt(m['ci_low'])}"
            f" .. {_fmt(m['ci_high'])}</td><td style='color:{colour.get(m['verdict'], '#000')}'>"
            f"<b>{m['verdict']}</b></td><td class='m'>{_fmt(m.get('method', ''))}</td></tr>")
    broken = "".join(
        f"<li><code>{html.escape(t['nodeid'])}</code> ({t['when']}): "
        f"{html.escape(t['message'])}</li>" for t in result["tests"]
        if t["outcome"] == "failed")
    cal = result.get("calibration")
    tb = artifacts.get("tilt_budget")
    tilt = "" if not tb else (
        f'<h2>Tilt error budget (<a href="{html.escape(tb["file"])}">'
        f'{html.escape(tb["file"])}</a>)</h2><pre>{html.escape(tb["text"])}</pre>')
    doc = f"""<!doctype html><html><head><meta charset="utf-8">
<title>jig {html.escape(result['serial'])} {html.escape(result['run_id'])}</title>
<style>body{{font-family:sans-serif;margin:1.5em}} table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:2px 6px;font-size:13px}} td.m{{font-size:11px;color:#555}}
.v{{font-size:28px;color:{colour[result['verdict']]}}}</style></head><body>
<h1>Board {html.escape(result['serial'])}: <span class="v">{result['verdict']}</span></h1>
<p>station <b>{html.escape(result['station'])}</b>, run {html.escape(result['run_id'])},
{html.escape(result['started_utc'])} &ndash; {html.escape(result['finished_utc'])}
({result['wall_time_s']:.1f} s wall, {_fmt(result.get('source_time_s'))} s of DUT time);
DUT <code>{html.escape(str((result.get('dut') or {}).get('uri')))}</code>;
fixture {html.escape(str(result.get('fixture')))}; limits
<code>{html.escape(str(result.get('limits_file')))}</code>.
Files: <a href="result.json">result.json</a>, <a href="junit.xml">junit.xml</a>
{f', <a href="{html.escape(cal)}">{html.escape(cal)}</a>' if cal else ''}.</p>
<p>Verdict per measurement: PASS when the whole confidence interval lies inside the
limits, FAIL when it lies wholly outside, INCONCLUSIVE otherwise.</p>
{f'<h2>Failed tests</h2><ul>{broken}</ul>' if broken else ''}
<h2>Measurements</h2>
<table><tr><th>name</th><th>value</th><th>unit</th><th>low</th><th>high</th>
<th>confidence interval</th><th>verdict</th><th>method</th></tr>
{''.join(rows)}</table>
{''.join(f'<h2>{c}</h2><img src="{p}" alt="{c}">' for p, c in figures)}
{tilt}
</body></html>
"""
    path = run_dir / "report.html"
    path.write_text(doc, encoding="utf-8")
    return path


def write_result(run_dir: Path, result: dict[str, Any]) -> Path:
    """``result.json``, written whole or not at all (:func:`replace_text`)."""
    path = run_dir / "result.json"
    replace_text(path, json.dumps(result, indent=1, allow_nan=False) + "\n")
    return path


__all__ = ["EXIT_STATUS", "FORMAT", "build_result", "write_report", "write_result"]
