"""The report's figures: sigma-tau with IEEE 952 readouts, and amplitude spectral density.

Both follow the same rules:

- **Axes follow the data.** The limits are the measured points' range (OADEV with its 95 %
  limits; band-averaged ASD) widened by :data:`MARGIN_DECADES` on each side, and the model
  may widen the vertical range by at most :data:`MODEL_EXTRA_DECADES` more. Model and
  per-term lines are evaluated only over the measured tau / frequency range and clipped
  at the limits, so a term that is tiny somewhere (a fitted sine, a Markov term) never
  stretches the plot.
- **Labels never overlap.** Readout markers' letters, term names and local-slope numbers
  are candidates in that priority; :func:`imubench.noisefit.labels.keep_non_overlapping`
  drops every one that would touch a kept label, the legend, or leave the axes.
- **Compact legend.** One entry per channel (colour) and one per line style.

Sigma-tau: OADEV at octave taus with 95 % chi-squared error bars
(:func:`imubench.stats.oadev`, ``confidence=0.95``), the model's ADEV (solid), each term's
ADEV (dashed), the IEEE 952 readout points (:mod:`imubench.noisefit.ieee952`: N on the
white line at tau = 1 s, B at the measured minimum, K on the random-walk line at 3 s), a
right axis in datasheet units (deg/h for gyros, ug for accelerometers) and a table of the
readouts in datasheet units with 95 % intervals under the plot.

PSD: amplitude spectral density sqrt(S(f)) (two-sided, IEEE 952 convention: the white
floor reads N) in mdps/sqrt(Hz) or ug/sqrt(Hz), band-averaged in log bands, with the model
and each term's ASD (:mod:`imubench.noisefit.spectrum`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from imubench.noisefit.ieee952 import READ_TAU_S, Readout, readout_quantities
from imubench.noisefit.labels import keep_non_overlapping
from imubench.noisefit.spectrum import BandPSD, term_psds

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
    from matplotlib.legend import Legend
    from matplotlib.text import Text

    from imubench.noisefit.fit import ChannelFit
    from imubench.stats.result import StatResult

DPI: int = 110
"""Figure and file resolution (one value: labels are placed at the saved geometry)."""
MARGIN_DECADES: float = 0.08
"""Room left around the measured points on each log axis (decades)."""
MODEL_EXTRA_DECADES: float = 0.3
"""How far beyond the measured vertical range the model line may widen the axis."""
COLORS: dict[str, str] = {"x": "tab:blue", "y": "tab:orange", "z": "tab:green"}
TERM_LABELS: dict[str, str] = {
    "white": "white N", "flicker": "flicker B", "random_walk": "random walk K",
    "ramp": "ramp R", "quantization": "quantization Q", "markov": "Gauss-Markov",
    "sine": "sine", "output_white": "output white", "resonance": "resonance",
}
"""Names written on the per-term lines."""
READOUT_MARKERS: dict[str, str] = {"N": "s", "B": "v", "K": "D"}


@dataclass(frozen=True)
class SensorStyle:
    """Units of one sensor's plots: model unit, right-axis unit and factor, ASD unit and
    factor (model unit -> shown unit)."""

    unit: str
    right_unit: str
    right_factor: float
    asd_unit: str
    asd_factor: float


STYLES: dict[str, SensorStyle] = {
    "gyro": SensorStyle("dps", "°/h", 3600.0, "mdps/√Hz", 1e3),
    "accel": SensorStyle("g", "µg", 1e6, "µg/√Hz", 1e6),
}



LABEL_BOX: dict[str, object] = {"boxstyle": "square,pad=0.1", "fc": "white", "ec": "none",
                                "alpha": 0.75}
"""Background of the slope and term labels: drawn above the markers and lines, on a
translucent white box, so a data point or a curve never hides one."""

def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def log_limits(values: np.ndarray, margin: float = MARGIN_DECADES) -> tuple[float, float]:
    """(low, high) of the positive finite ``values`` widened by ``margin`` decades."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v) & (v > 0)]
    f = 10.0 ** margin
    return float(v.min() / f), float(v.max() * f)


def _widen(lim: tuple[float, float], model: np.ndarray) -> tuple[float, float]:
    """``lim`` widened to hold ``model``, by at most :data:`MODEL_EXTRA_DECADES`."""
    m = model[np.isfinite(model) & (model > 0)]
    if m.size == 0:
        return lim
    cap = 10.0 ** MODEL_EXTRA_DECADES
    return max(min(lim[0], float(m.min())), lim[0] / cap), min(max(lim[1], float(m.max())),
                                                                 lim[1] * cap)


def _inside(y: np.ndarray, lim: tuple[float, float]) -> np.ndarray:
    """``y`` with points outside ``lim`` set to NaN (lines stop at the frame)."""
    return np.where((y >= lim[0]) & (y <= lim[1]), y, np.nan)


def _legend(ax: Axes, channels: tuple[str, ...],
            styles: list[tuple[str, dict[str, Any]]]) -> Legend:
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=COLORS[ch[1]], lw=2) for ch in channels]
    labels = list(channels)
    for text, kw in styles:
        handles.append(Line2D([], [], color="0.25", **kw))
        labels.append(text)
    return ax.legend(handles, labels, fontsize=7, ncol=min(len(labels), 4), loc="best",
                     framealpha=0.85)


def _term_label(ax: Axes, term: str, tau: np.ndarray, y: np.ndarray, total: np.ndarray,
                color: str) -> Text | None:
    """The term's name at the visible point where it carries the largest share of the
    model (where its line is nearest the total), or None if no point is visible."""
    ok = np.isfinite(y) & (total > 0)
    if not ok.any():
        return None
    share = np.where(ok, y / np.where(total > 0, total, np.inf), -1.0)
    k = int(np.argmax(share))
    right_half = k > tau.size // 2  # write towards the middle, not out of the frame
    return ax.annotate(TERM_LABELS.get(term, term), (tau[k], y[k]), fontsize=7, color=color,
                       textcoords="offset points", xytext=(-3 if right_half else 3, -9),
                       ha="right" if right_half else "left", zorder=6, bbox=LABEL_BOX)


def _tau_grid(curve: StatResult, rate_hz: float) -> np.ndarray:
    """Whole-sample taus spanning the measured curve (no staircase from rounding)."""
    m = np.unique(np.rint(np.geomspace(curve.m[0], curve.m[-1], 200)))
    return m / rate_hz


def sigma_tau_figure(title: str, fits: dict[str, ChannelFit], curves: dict[str, StatResult],
                     readouts: dict[str, dict[str, Readout]], sensor: str) -> Figure:
    """The sigma-tau figure of one sensor's channels (module docstring)."""
    plt = _pyplot()
    from matplotlib.ticker import LogFormatter

    style = STYLES[sensor]
    chans = tuple(fits)
    fig = plt.figure(figsize=(9.0, 7.2), dpi=DPI)
    grid = fig.add_gridspec(2, 1, height_ratios=(5.2, 1.0))
    ax = fig.add_subplot(grid[0])
    tab_ax = fig.add_subplot(grid[1])
    tab_ax.axis("off")
    meas = np.concatenate([np.r_[c.dev, c.ci_low, c.ci_high] for c in curves.values()])
    taus = np.concatenate([c.tau_s for c in curves.values()])
    xlim = log_limits(taus)
    ylim = log_limits(meas)
    models: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for ch in chans:
        tau = _tau_grid(curves[ch], fits[ch].rate_hz)
        models[ch] = (tau, np.sqrt(fits[ch].model_avar(tau)))
    ylim = _widen(ylim, np.concatenate([m for _, m in models.values()]))
    labels: list[Text] = []
    term_labels: list[Text] = []
    slope_labels: list[Text] = []
    labelled_terms: set[str] = set()
    shown: set[str] = set()  # readout symbols with a marker inside the axes
    for ch in chans:
        color = COLORS[ch[1]]
        c = curves[ch]
        ax.errorbar(c.tau_s, c.dev, yerr=[c.dev - c.ci_low, c.ci_high - c.dev], fmt="o",
                    ms=3.5, color=color, capsize=2, lw=0.9, zorder=3)
        tau, total = models[ch]
        ax.plot(tau, _inside(total, ylim), "-", color=color, lw=1.4)
        for term, av in fits[ch].term_avars(tau).items():
            y = _inside(np.sqrt(av), ylim)
            ax.plot(tau, y, "--", color=color, lw=0.8, alpha=0.65)
            if term not in labelled_terms:
                t = _term_label(ax, term, tau, y, total, color)
                if t is not None:
                    labelled_terms.add(term)
                    term_labels.append(t)
        for sym, r in readouts[ch].items():
            if r.tau_s is None or r.dev is None or r.kind == "none":
                continue
            if not (xlim[0] <= r.tau_s <= xlim[1] and ylim[0] <= r.dev <= ylim[1]):
                continue
            ax.plot([r.tau_s], [r.dev], READOUT_MARKERS[sym], ms=7, mfc="none", mec=color,
                    mew=1.6, zorder=4)
            shown.add(sym)
            labels.append(ax.annotate(sym, (r.tau_s, r.dev), fontsize=8, color=color,
                                      fontweight="bold", textcoords="offset points",
                                      xytext=(6, 4)))
        positive = bool(np.all(c.dev > 0))  # a constant channel has ADEV 0: no slope
        slopes = (np.gradient(np.log(c.dev), np.log(c.tau_s))
                  if c.tau_s.size > 1 and positive else [])
        for i in range(1, len(slopes), 2):
            slope_labels.append(ax.annotate(f"{slopes[i]:+.2f}", (c.tau_s[i], c.ci_low[i]),
                                            fontsize=6, color=color,
                                            textcoords="offset points", xytext=(0, -4),
                                            ha="center", va="top", zorder=6,
                                            bbox=LABEL_BOX))
    for tau_read in READ_TAU_S.values():
        if xlim[0] <= tau_read <= xlim[1]:
            ax.axvline(tau_read, color="0.6", ls=":", lw=0.8, zorder=1)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_xlabel("averaging time τ (s)")
    ax.set_ylabel(f"Allan deviation ({style.unit})")
    f = style.right_factor
    right = ax.secondary_yaxis("right", functions=(lambda v: v * f, lambda v: v / f))
    right.set_ylabel(f"Allan deviation ({style.right_unit})")
    right.yaxis.set_major_formatter(LogFormatter())  # plain numbers: 60, 100, not 6x10^1
    right.yaxis.set_minor_formatter(LogFormatter(labelOnlyBase=False))
    ax.grid(True, which="both", alpha=0.25)
    ax.set_title(title, fontsize=9)
    glyphs = {"N": "□", "B": "▽", "K": "◇"}  # READOUT_MARKERS' shapes
    entries: list[tuple[str, dict[str, Any]]] = [
        ("OADEV ± 95 %", {"marker": "o", "ls": "none", "ms": 4}),
        ("model", {"ls": "-"}), ("terms", {"ls": "--", "lw": 0.8})]
    if shown:  # only the readouts drawn (K at 3 s can lie below the data's range)
        entries.append(("readouts " + " ".join(f"{k} {g}" for k, g in glyphs.items()
                                                if k in shown),
                        {"marker": "s", "ls": "none", "mfc": "none"}))
    legend = _legend(ax, chans, entries)
    _readout_table(tab_ax, chans, readouts)
    fig.tight_layout()
    keep_non_overlapping(fig, ax, labels + term_labels + slope_labels, occupied=[legend])
    return fig


def _readout_table(ax: Axes, chans: tuple[str, ...],
                   readouts: dict[str, dict[str, Readout]]) -> None:
    """The IEEE 952 readouts in datasheet units with 95 % intervals, one row a channel."""
    qs = readout_quantities(chans[0])
    n_q, b_q, k_q = qs["N"][-1], qs["B"][0], qs["K"][0]
    # "N at τ = 1 s" read as the curve's value there: 3.6 °/√h beside a curve at 1.16 on
    # a phone gyro whose short Markov term reaches the -1/2 line only from ~14 s (an
    # outside reviewer); it is the line's value, extrapolated as Annex C reads it
    cols = [f"N: −½ line at τ = 1 s ({n_q.unit})", f"B = σmin / 0.664 ({b_q.unit})",
            "τ of σmin (s)", f"K: +½ line at τ = 3 s ({k_q.unit})"]
    rows = []
    for ch in chans:
        r = readouts[ch]
        tau_b = r["B"].tau_s
        rows.append([r["N"].text(n_q, unit=False), r["B"].text(b_q, unit=False),
                     "-" if tau_b is None else f"{tau_b:.3g}", r["K"].text(k_q, unit=False)])
    table = ax.table(cellText=rows, rowLabels=list(chans), colLabels=cols, loc="center",
                     cellLoc="center")
    table.auto_set_font_size(False)
    table.set_fontsize(7.5)
    table.scale(1.0, 1.25)
    ax.set_title("IEEE 952 readouts, 95 % intervals (N, K: the fitted lines read at τ = 1 "
                 "and 3 s, not the curve there; B: measured minimum)", fontsize=8)


def psd_figure(title: str, fits: dict[str, ChannelFit], bands: dict[str, BandPSD],
               sensor: str) -> Figure:
    """The amplitude-spectral-density figure of one sensor's channels (module docstring)."""
    plt = _pyplot()
    style = STYLES[sensor]
    chans = tuple(fits)
    fig, ax = plt.subplots(figsize=(9.0, 5.6), dpi=DPI)
    s = style.asd_factor
    asd = {ch: np.sqrt(bands[ch].psd) * s for ch in chans}
    xlim = log_limits(np.concatenate([bands[ch].f_hz for ch in chans]))
    ylim = log_limits(np.concatenate(list(asd.values())))
    terms = {ch: term_psds(fits[ch], bands[ch]) for ch in chans}
    totals = {ch: np.sqrt(sum(terms[ch].values(), np.zeros(bands[ch].f_hz.size))) * s
              for ch in chans}
    ylim = _widen(ylim, np.concatenate(list(totals.values())))
    term_labels: list[Text] = []
    labelled: set[str] = set()
    for ch in chans:
        color = COLORS[ch[1]]
        f = bands[ch].f_hz
        ax.plot(f, asd[ch], ".-", color=color, ms=3, lw=0.8, alpha=0.85)
        ax.plot(f, _inside(totals[ch], ylim), "-", color=color, lw=1.6)
        for term, psd in terms[ch].items():
            y = _inside(np.sqrt(psd) * s, ylim)
            ax.plot(f, y, "--", color=color, lw=0.8, alpha=0.65)
            if term not in labelled:
                t = _term_label(ax, term, f, y, totals[ch], color)
                if t is not None:
                    labelled.add(term)
                    term_labels.append(t)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"two-sided amplitude spectral density ({style.asd_unit})")
    ax.grid(True, which="both", alpha=0.25)
    ax.set_title(title, fontsize=9)
    legend = _legend(ax, chans, [
        ("measured, log-band mean", {"marker": ".", "ls": "-", "lw": 0.8}),
        ("model", {"ls": "-"}), ("terms (IEEE 952 Annex C)", {"ls": "--", "lw": 0.8}),
    ])
    fig.tight_layout()
    keep_non_overlapping(fig, ax, term_labels, occupied=[legend])
    return fig


def save_figure(fig: Figure, stem: Path) -> list[Path]:
    """Write ``stem.png`` and ``stem.svg`` at :data:`DPI`, close the figure, return the
    paths."""
    plt = _pyplot()
    paths = [stem.with_suffix(".png"), stem.with_suffix(".svg")]
    for p in paths:
        fig.savefig(p, dpi=DPI)
    plt.close(fig)
    return paths


__all__ = ["COLORS", "DPI", "STYLES", "SensorStyle", "log_limits", "psd_figure",
           "save_figure", "sigma_tau_figure"]
