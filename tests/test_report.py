"""imubench report: files, plot data (axis ranges, label overlaps, readouts), --model."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from lsm6ds_sim.model import NoiseModel, load_model
from lsm6ds_sim.physics import simulate
from matplotlib.figure import Figure
from matplotlib.text import Text

from imubench.cli import main
from imubench.noisefit import recording_fit
from imubench.noisefit.ieee952 import ieee952_readouts
from imubench.noisefit.labels import keep_non_overlapping
from imubench.noisefit.plots import psd_figure, sigma_tau_figure
from imubench.noisefit.recording_fit import channel_from_model
from imubench.noisefit.report import oadev_curve
from imubench.noisefit.spectrum import band_psd, term_psds
from imubench.noisefit.tangent import FLICKER_FLOOR
from tests.test_fit_cli import RATE, write_recording

GYRO = ("gx", "gy", "gz")
ACCEL = ("ax", "ay", "az")
# white + flicker + random walk, and on gz a 5 Hz sine (the term that once stretched the
# sigma-tau axes over 7 decades)
MODEL = (NoiseModel.quiet().with_all(white=0.004, flicker=0.0015, random_walk=2e-4)
         .with_channel("gz", sine_amplitude=0.0033, sine_freq=5.0)
         .with_channel("ax", white=8e-5, flicker=3e-5, random_walk=1e-5)
         .with_channel("ay", white=8e-5, flicker=3e-5, random_walk=1e-5)
         .with_channel("az", white=8e-5, flicker=3e-5, random_walk=1e-5))


@pytest.fixture(scope="module")
def sim() -> dict[str, np.ndarray]:
    return simulate(MODEL, 60_000, RATE, 5)


def _sensor(sim: dict[str, np.ndarray], chans: tuple[str, ...]):  # type: ignore[no-untyped-def]
    fits = {ch: channel_from_model(MODEL[ch], sim[ch], RATE, ch) for ch in chans}
    curves = {ch: oadev_curve(sim[ch], RATE) for ch in chans}
    readouts = {ch: ieee952_readouts(fits[ch], curves[ch]) for ch in chans}
    return fits, curves, readouts


def _overlaps(fig: Figure, texts: list[Text]) -> list[tuple[str, str]]:
    fig.canvas.draw()
    r = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    shown = [t for t in texts if t.get_visible() and t.get_text().strip()]
    boxes = [t.get_window_extent(r) for t in shown]
    return [(shown[i].get_text(), shown[j].get_text()) for i in range(len(shown))
            for j in range(i + 1, len(shown)) if boxes[i].overlaps(boxes[j])]


def _decades_beyond(lim: tuple[float, float], lo: float, hi: float) -> tuple[float, float]:
    return math.log10(lo / lim[0]), math.log10(lim[1] / hi)


@pytest.mark.parametrize("chans", [GYRO, ACCEL])
def test_sigma_tau_axes_hold_the_data_and_are_not_stretched(
        sim: dict[str, np.ndarray], chans: tuple[str, ...]) -> None:
    fits, curves, readouts = _sensor(sim, chans)
    fig = sigma_tau_figure("t", fits, curves, readouts, "gyro" if chans == GYRO else "accel")
    ax = fig.axes[0]
    taus = np.concatenate([c.tau_s for c in curves.values()])
    devs = np.concatenate([np.r_[c.ci_low, c.ci_high, c.dev] for c in curves.values()])
    x = _decades_beyond(ax.get_xlim(), taus.min(), taus.max())
    y = _decades_beyond(ax.get_ylim(), devs.min(), devs.max())
    assert all(0 <= d <= 1.0 for d in (*x, *y)), (x, y)
    # the sine's own line is below the data almost everywhere: it must be clipped, not
    # drawn below the frame
    for line in ax.get_lines():
        if line.get_transform() != ax.transData:  # the tau = 1 s / 3 s guides
            continue
        yd = np.asarray(line.get_ydata(), dtype=float)
        yd = yd[np.isfinite(yd)]
        assert yd.size == 0 or (yd.min() >= ax.get_ylim()[0] * 0.999
                                and yd.max() <= ax.get_ylim()[1] * 1.001)


@pytest.mark.parametrize("chans", [GYRO, ACCEL])
def test_sigma_tau_labels_never_overlap(sim: dict[str, np.ndarray],
                                        chans: tuple[str, ...]) -> None:
    fits, curves, readouts = _sensor(sim, chans)
    fig = sigma_tau_figure("t", fits, curves, readouts, "gyro" if chans == GYRO else "accel")
    ax = fig.axes[0]
    legend = ax.get_legend()
    assert len(legend.get_texts()) <= 7  # compact: channels + line styles
    texts = list(ax.texts)
    assert len(texts) >= 4  # readout letters, term names, slopes survive
    assert _overlaps(fig, texts + list(legend.get_texts())) == []
    frame = ax.get_window_extent()
    for t in texts:
        b = t.get_window_extent()
        assert frame.x0 <= b.x0 and b.x1 <= frame.x1 and frame.y0 <= b.y0 and b.y1 <= frame.y1


def test_keep_non_overlapping_drops_what_would_overlap() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4, 3), dpi=100)
    ax.set_xlim(0, 10)
    ax.set_ylim(0, 10)
    crowd = [ax.text(5, 5, f"label {i}") for i in range(5)]
    apart = ax.text(1, 9, "alone")
    outside = ax.text(9.9, 1, "cut off at the frame")
    assert len(_overlaps(fig, crowd)) == 10  # the check does see overlaps
    kept = keep_non_overlapping(fig, ax, [*crowd, apart, outside])
    assert kept == [crowd[0], apart]
    assert _overlaps(fig, list(ax.texts)) == []
    plt.close(fig)


def test_readouts_in_datasheet_units_with_intervals(sim: dict[str, np.ndarray]) -> None:
    fits, curves, readouts = _sensor(sim, GYRO)
    r = readouts["gx"]
    assert r["N"].tau_s == 1.0 and r["N"].value == pytest.approx(0.004)
    assert r["K"].tau_s == 3.0 and r["K"].value == pytest.approx(2e-4)
    c = curves["gx"]
    i = int(np.argmin(np.abs(c.tau_s - r["B"].tau_s)))
    if r["B"].kind == "value":
        assert r["B"].value == pytest.approx(c.dev[i] / FLICKER_FLOOR)
        assert r["B"].interval == pytest.approx((c.ci_low[i] / FLICKER_FLOOR,
                                                 c.ci_high[i] / FLICKER_FLOOR))
    else:  # no established floor: bounded by the least upper limit, above every point's
        assert r["B"].kind == "upper" and r["B"].interval is None
        assert r["B"].value == pytest.approx(np.nanmin(c.ci_high) / FLICKER_FLOOR)
        assert r["B"].value > np.nanmin(c.dev) / FLICKER_FLOOR
    assert r["N"].interval is None  # a model file has none; none is invented
    for sensor, chans, units in (("gyro", GYRO, ("°/√h", "°/h", "°/h/√h")),
                                 ("accel", ACCEL, ("m/s/√h", "µg", "µg/√s"))):
        fits, curves, readouts = _sensor(sim, chans)
        fig = sigma_tau_figure("t", fits, curves, readouts, sensor)
        table = fig.axes[1].tables[0]
        cells = {k: c.get_text().get_text() for k, c in table.get_celld().items()}
        header = " ".join(v for (row, _), v in cells.items() if row == 0)
        for u in units:
            assert f"({u})" in header
        assert "N: −½ line at τ = 1 s" in header and "K: +½ line at τ = 3 s" in header
        assert "0.664" in header
        row_gx = [v for (row, col), v in sorted(cells.items()) if row == 1 and col >= 0]
        # B: a value with its interval, or an upper bound while the floor is not established
        assert re.fullmatch(r"< [\d.]+|[\d.]+ \[[\d.]+, [\d.]+\]", row_gx[1])
        assert all(v.strip() and v != "-" for v in row_gx)
        assert fig.axes[0].get_ylabel().endswith(("(dps)", "(g)"))
        right = fig.axes[0].child_axes[0]  # the secondary axis in datasheet units
        assert right.get_ylabel() == ("Allan deviation (°/h)" if sensor == "gyro"
                                      else "Allan deviation (µg)")
        lo, hi = fig.axes[0].get_ylim()
        factor = 3600.0 if sensor == "gyro" else 1e6
        assert right.get_ylim() == pytest.approx((lo * factor, hi * factor))


def test_band_psd_reads_white_density_and_model_matches() -> None:
    y = simulate(NoiseModel.single_term("gx", white=0.004), 200_000, RATE, 2)["gx"]
    bands = band_psd(y, RATE)
    assert np.all(np.diff(np.log10(bands.f_hz)) < 0.2)  # log bands, 10 per decade
    high = bands.bins > 100
    # two-sided convention: the white floor reads N itself
    assert np.sqrt(np.average(bands.psd[high], weights=bands.bins[high])) == \
        pytest.approx(0.004, rel=0.02)
    fit = channel_from_model(NoiseModel.single_term("gx", white=0.004)["gx"], y, RATE, "gx")
    assert term_psds(fit, bands)["white"] == pytest.approx(np.full(bands.f_hz.size, 1.6e-5))


def test_psd_figure_amplitude_units_model_and_range(sim: dict[str, np.ndarray]) -> None:
    for sensor, chans, unit in (("gyro", GYRO, "mdps/√Hz"), ("accel", ACCEL, "µg/√Hz")):
        fits = {ch: channel_from_model(MODEL[ch], sim[ch], RATE, ch) for ch in chans}
        bands = {ch: band_psd(sim[ch], RATE) for ch in chans}
        fig = psd_figure("t", fits, bands, sensor)
        ax = fig.axes[0]
        assert ax.get_ylabel() == f"two-sided amplitude spectral density ({unit})"
        assert "unit" not in ax.get_ylabel() and ax.get_xlabel() == "frequency (Hz)"
        scale = 1e3 if sensor == "gyro" else 1e6
        asd = np.concatenate([np.sqrt(b.psd) * scale for b in bands.values()])
        y = _decades_beyond(ax.get_ylim(), asd.min(), asd.max())
        assert all(0 <= d <= 1.0 for d in y), y
        # measured + model + 3 terms per channel (+ the sine on gz)
        assert len(ax.get_lines()) >= 5 * len(chans)
        assert _overlaps(fig, list(ax.texts) + list(ax.get_legend().get_texts())) == []


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_recording(tmp_path_factory.mktemp("rep") / "r.imbr", MODEL, 40_000)


def test_report_writes_plots_fit_and_pages(recording: Path, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "rep"
    rc = main(["report", str(recording), "--out", str(out), "--terms", "white,flicker"])
    assert rc == 0, capsys.readouterr().err
    for name in ("sigma_tau_gyro", "sigma_tau_accel", "psd_gyro", "psd_accel"):
        png = (out / f"{name}.png").read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000
        assert "<svg" in (out / f"{name}.svg").read_text()[:2000]
    assert load_model(out / "model.toml")["gx"].white > 0
    doc = json.loads((out / "fit.json").read_text())
    assert set(doc["channels"]) == {"gx", "gy", "gz", "ax", "ay", "az"}
    index = (out / "index.html").read_text()
    assert 'href="gyro.html"' in index and "Kalibr" in index
    gyro = (out / "gyro.html").read_text()
    assert gyro.count("data:image/png;base64,") == 2
    for label in ("rate noise density", "angle random walk", "bias instability",
                  "rate random walk", "mdps/√Hz", "°/√h", "°/h/√h", "datasheet typical"):
        assert label in gyro
    assert "arw_deg_per_sqrt_h" not in gyro  # human labels, not raw keys
    gx = doc["channels"]["gx"]
    # the noise density is the white-equivalent one: white before and after the filter
    n = gx["datasheet_units"]["noise_density_mdps_per_sqrt_hz"]
    assert n == pytest.approx(1000 * math.hypot(gx["params"]["white"],
                                                gx["params"]["output_white"]))
    key = "white_equivalent" if "white_equivalent" in gx["ci95"] else "white"
    lo, hi = (v * 1000 for v in gx["ci95"][key])
    assert lo <= n <= hi
    assert re.search(rf"{n:.3f}\d* \[{lo:.3f}\d*, {hi:.3f}\d*\]", gyro)
    accel = (out / "accel.html").read_text()
    for label in ("velocity random walk", "m/s/√h", "µg/√Hz"):
        assert label in accel
    assert "gyroscope_noise_density" in (out / "imu.yaml").read_text()


def test_report_model_reuses_the_file_without_fitting(
        recording: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    model = NoiseModel.quiet().with_channel("gx", white=0.00437, flicker=0.00123) \
        .with_channel("ax", white=8.8e-5)
    path = tmp_path / "m.toml"
    path.write_text(model.to_toml())

    def no_fit(*args: object, **kwargs: object) -> None:
        raise AssertionError("report --model must not refit")

    monkeypatch.setattr(recording_fit, "fit_channel", no_fit)
    out = tmp_path / "rep"
    rc = main(["report", str(recording), "--model", str(path), "--out", str(out)])
    assert rc == 0, capsys.readouterr().err
    doc = json.loads((out / "fit.json").read_text())
    assert set(doc["channels"]) == {"gx", "ax"}
    assert doc["channels"]["gx"]["params"]["white"] == 0.00437
    gyro = (out / "gyro.html").read_text()
    assert "4.37 <span class=note>(no interval)</span>" in gyro  # N in mdps/√Hz
    assert f"{0.00123 * 3600:.4g} <span class=note>(no interval)</span>" in gyro
    assert "holds no confidence intervals" in gyro
    assert "0.0043" not in (out / "accel.html").read_text()
    assert load_model(out / "model.toml").to_dict() == load_model(path).to_dict()
    assert not (out / "imu.yaml").exists()  # no random walk, no interval: not made up
    assert "imu.yaml not written" in (out / "index.html").read_text()


def test_report_bad_model_file(recording: Path, tmp_path: Path,
                               capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[channels.gx]\nwhite = -1\n")
    assert main(["report", str(recording), "--model", str(bad), "--out",
                 str(tmp_path / "o")]) == 2
    assert "bad.toml" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()  # refused before anything is written


def test_report_names_where_a_model_does_not_describe_the_recording(
        recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--model`` with another sensor's model (``datasheet:CHIP`` too): the pages and
    fit.json say, per channel, where the model leaves the measured OADEV's interval; the
    model that made the recording gets no such note."""
    truth = tmp_path / "truth.toml"
    truth.write_text(MODEL.to_toml())
    other = tmp_path / "other.toml"
    other.write_text(NoiseModel.quiet().with_channel("gx", white=0.012, flicker=0.0015,
                                                     random_walk=2e-4).to_toml())
    for path, noisy in ((str(truth), set()), (str(other), {"gx"}),
                        ("datasheet:lsm6dsl", None)):
        out = tmp_path / f"rep_{len(path)}"
        assert main(["report", str(recording), "--model", path, "--out", str(out)]) == 0, \
            capsys.readouterr().err
        doc = json.loads((out / "fit.json").read_text())
        flagged = {n.split(":")[0] for n in doc["model_notes"]}
        if noisy is not None:
            assert flagged == noisy, doc["model_notes"]
        assert doc["model_file"] == path
        assert load_model(out / "model.toml").to_dict() == load_model(path).to_dict()
        if flagged:
            assert "does not describe this recording" in (out / "gyro.html").read_text()


def test_report_out_that_is_a_file_is_refused(recording: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "f").write_text("")
    assert main(["report", str(recording), "--out", str(tmp_path / "f")]) == 2
    assert "is a file" in capsys.readouterr().err


def test_report_model_with_fit_options_is_refused(recording: Path, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "m.toml"
    path.write_text(MODEL.to_toml())
    for option in (["--terms", "white"], ["--terms", "auto"], ["--method", "wls"]):
        # the defaults too: a fit option says the user expects a fit
        assert main(["report", str(recording), "--model", str(path), *option,
                     "--out", str(tmp_path / "o")]) == 2
        assert "--model" in capsys.readouterr().err and not (tmp_path / "o").exists()


def test_report_bad_recording(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "r.txt"
    bad.write_text("x")
    assert main(["report", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "r.txt" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_interval_text_keeps_both_ends_readable() -> None:
    """Two significant digits on the narrower half; an interval over decades is printed
    in significant digits, never with a 0.0 end (a [0.0076, 24.8] Hz bandwidth)."""
    from imubench.noisefit.ieee952 import fmt_interval

    assert fmt_interval(0.2401, 0.2389, 0.2413) == "0.2401 [0.2389, 0.2413]"
    assert fmt_interval(8.0, 0.00759, 24.8) == "8 [0.00759, 24.8]"
    assert fmt_interval(28.9, 28.6, 29.2) == "28.90 [28.60, 29.20]"


def test_legend_lists_only_the_readouts_drawn(sim: dict[str, np.ndarray]) -> None:
    """A readout outside the axes (K read at 3 s far below the data) gets no marker, and
    the legend does not announce it."""
    from dataclasses import replace

    fits, curves, readouts = _sensor(sim, GYRO)
    low = {ch: {**r, "K": replace(r["K"], dev=1e-9, value=1e-9)} for ch, r in readouts.items()}
    texts = [t.get_text() for t in
             sigma_tau_figure("t", fits, curves, low, "gyro").axes[0].get_legend().get_texts()]
    entry = next(t for t in texts if t.startswith("readouts"))
    assert "N □" in entry and "K" not in entry, texts
    inside = {ch: {**r, "K": replace(r["K"], dev=float(np.median(curves[ch].dev)))}
              for ch, r in readouts.items()}
    texts = [t.get_text() for t in
             sigma_tau_figure("t", fits, curves, inside, "gyro").axes[0].get_legend()
             .get_texts()]
    assert any("K ◇" in t for t in texts), texts
