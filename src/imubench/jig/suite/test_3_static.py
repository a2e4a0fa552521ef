"""The static capture: zero-rate level, noise density, angle random walk, bias
instability (with their confidence intervals), temperature sensor against the chamber,
FIFO and timestamp integrity, measured ODR."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import pytest

from imubench.batch import CHANNELS
from imubench.calibration.means import capture_mean
from imubench.jig import analysis

if TYPE_CHECKING:
    from imubench.jig.dut import Dut
    from imubench.jig.fixtures.base import Fixture
    from imubench.jig.plugin import Measure
    from imubench.jig.procedures import Point
    from imubench.jig.session import JigSession
    from imubench.stats.result import StatResult


GYRO = ("gx", "gy", "gz")
TICK_S = 25e-6


def _sensor(ch: str) -> str:
    return "gyro" if ch.startswith("g") else "accel"


@pytest.fixture(scope="module")
def static(jig: JigSession) -> Point:
    return jig.procedures.static()


@pytest.fixture(scope="module")
def allan(static: Point, jig: JigSession) -> dict[str, StatResult]:
    """OADEV at octave taus of every channel (also the sigma-tau plot's data)."""
    out = {}
    plot = jig.artifacts.setdefault("sigma_tau", {})
    for ch in CHANNELS:
        res = analysis.oadev(static.capture.channel(ch), static.capture.odr_hz, jig.confidence)
        out[ch] = res
        lim = jig.limits
        scale = analysis.SCALE[f"{_sensor(ch)}_density"]
        bi_scale = analysis.SCALE[f"{_sensor(ch)}_bias"]
        plot[ch] = {
            "tau_s": res.tau_s, "dev": res.dev, "ci_low": res.ci_low, "ci_high": res.ci_high,
            "unit": "dps" if ch in GYRO else "g",
            "density_limit": (lim[f"noise_density.{ch}"].high or math.nan) / scale,
            "bias_instability_limit": (lim[f"bias_instability.{ch}"].high or math.nan) / bi_scale,
        }
    return out


@pytest.mark.parametrize("ch", GYRO)
def test_zero_rate_level(static: Point, jig: JigSession, measure: Measure, ch: str) -> None:
    v = analysis.mean_value(static.means[CHANNELS.index(ch)], jig.confidence)
    measure(f"zero_rate_level.{ch}", v.value, v.ci, method=v.method)


def _density(static: Point, jig: JigSession, ch: str) -> analysis.Value:
    """The white density of ``ch`` (unit/sqrt(Hz)), fitted once per run: noise density
    and ARW are both read off it."""
    return jig.cached(f"white_density.{ch}",
                      lambda: analysis.noise_density(static.capture, ch, jig.confidence))


@pytest.mark.parametrize("ch", CHANNELS)
def test_noise_density(static: Point, jig: JigSession, measure: Measure, ch: str) -> None:
    v = _density(static, jig, ch)
    v = v.scaled(analysis.SCALE[f"{_sensor(ch)}_density"])
    measure(f"noise_density.{ch}", v.value, v.ci, method=v.method)


@pytest.mark.parametrize("ch", GYRO)
def test_angle_random_walk(static: Point, jig: JigSession, measure: Measure, ch: str) -> None:
    v = analysis.angle_random_walk(_density(static, jig, ch))
    measure(f"angle_random_walk.{ch}", v.value, v.ci, method=v.method)


@pytest.mark.parametrize("ch", CHANNELS)
def test_bias_instability(
    allan: dict[str, StatResult], jig: JigSession, measure: Measure, ch: str,
) -> None:
    v, _ = analysis.bias_instability(allan[ch])
    v = v.scaled(analysis.SCALE[f"{_sensor(ch)}_bias"])
    measure(f"bias_instability.{ch}", v.value, v.ci, method=v.method)


def test_temperature_sensor(
    static: Point, jig: JigSession, fixture: Fixture, measure: Measure,
) -> None:
    cap = static.capture
    m = capture_mean(cap.temp_c, cap.odr_hz, 1.0 / 256.0, "static die temperature")
    chamber = fixture.chamber_temperature_c()
    v = analysis.mean_value(m, jig.confidence)
    v = analysis.Value(v.value - chamber, (v.ci[0] - chamber, v.ci[1] - chamber),
                       v.method + f"; minus the chamber reading {chamber:g} degC")
    v = analysis.with_extra_uncertainty(v, jig.station.fixture.chamber_accuracy_c,
                                        jig.confidence)
    measure("temperature_sensor.offset", v.value, v.ci, method=v.method)


def test_fifo_integrity(static: Point, measure: Measure) -> None:
    cap = static.capture
    lost = cap.lost
    reasons = sorted({g.reason for g in cap.gaps})
    measure("fifo.lost_samples", lost, (lost, lost),
            method=f"holes in the sample index of {len(cap)} samples (timestamps checked by"
            f" the driver); reasons: {', '.join(reasons) or 'none'}")


def test_output_data_rate(static: Point, dut: Dut, measure: Measure) -> None:
    odr = dut.info.odr_hz
    measured = dut.measured_odr_hz
    if measured is None:
        measure("fifo.odr_error", math.nan, (math.nan, math.nan),
                method="the source does not measure its ODR (no timestamps)")
        return
    err = (measured / odr - 1.0) * 100.0
    half = 2.0 * TICK_S / max(dut.elapsed_s, 1e-9) * 100.0
    measure("fifo.odr_error", err, (err - half, err + half),
            method=f"ODR {measured:.4f} Hz from the chip timestamp against the host clock"
            f" over {dut.elapsed_s:.0f} s; +-2 ticks of 25 us")
