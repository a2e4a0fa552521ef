"""The captures of the acceptance run, each taken once per run and shared by the tests
that need it (:class:`Procedures` caches them):

* static: the board at rest, ``+Z`` up, ``capture.static_s`` seconds (noise, zero-rate
  level, FIFO and timestamp integrity, temperature sensor at ambient);
* six positions: ``+X -X +Y -Y +Z -Z`` up, ``capture.position_s`` each (accelerometer
  calibration, zero-g offset);
* rate table: each axis vertical, at rest and at ``+-r`` for every ``r`` of
  ``capture.rates_dps``, ``capture.rate_s`` each (gyro sensitivity, cross-axis);
* temperature sweep: for each chamber set point of ``capture.temperatures_c`` the die
  temperature is left to settle (stable within ``temp_stable_c`` over ``temp_window_s``)
  and the board is captured ``+Z`` and ``-Z`` up (``temp_capture_s`` each): the flip
  separates the Z accelerometer's offset from its gain; the chamber returns to ambient.

Every capture is preceded by the fixture move and ``capture.settle_s`` of settling.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imubench.batch import CHANNELS
from imubench.calibration.accel import SIX_POSITIONS
from imubench.calibration.errors import CalibrationError
from imubench.calibration.means import MeanEstimate, capture_mean
from imubench.jig.dut import INT16_MAX, Capture, Dut
from imubench.jig.errors import StationError
from imubench.jig.fixtures.base import AXES, Fixture
from imubench.jig.station import CaptureSection


@dataclass(frozen=True)
class Point:
    """One capture at a known input with the mean of each channel."""

    label: str
    capture: Capture
    means: tuple[MeanEstimate, ...]
    specific_force_g: np.ndarray
    rate_dps: np.ndarray

    def mean(self, cols: slice) -> np.ndarray:
        return np.array([m.mean for m in self.means[cols]])

    def stderr(self, cols: slice) -> np.ndarray:
        return np.array([m.stderr for m in self.means[cols]])

    @property
    def die_temp_c(self) -> float:
        return float(np.nanmean(self.capture.temp_c))


@dataclass(frozen=True)
class TemperaturePoint:
    """One chamber set point: the two flipped captures and the chamber's reading."""

    set_point_c: float
    chamber_c: float
    settle_s: float
    up: Point
    down: Point

    @property
    def die_temp_c(self) -> float:
        return 0.5 * (self.up.die_temp_c + self.down.die_temp_c)

    @property
    def time_s(self) -> float:
        """Source time of the middle of the two captures, s."""
        first, last = self.up.capture, self.down.capture
        return 0.5 * (first.t0_s + last.t0_s + last.duration_s)

    def offsets(self, cols: slice) -> tuple[np.ndarray, np.ndarray]:
        """(3,) offsets and standard errors: the mean of the flipped pair (for the
        accelerometer, (A(+Z) + A(-Z)) / 2 removes gravity on every axis)."""
        m = 0.5 * (self.up.mean(cols) + self.down.mean(cols))
        se = 0.5 * np.hypot(self.up.stderr(cols), self.down.stderr(cols))
        return m, se


def point(label: str, cap: Capture, force: np.ndarray, rate: np.ndarray) -> Point:
    """The capture's channel means; CalibrationError when a channel was clipped at its
    full scale (a rate step beyond the gyro's range: the mean of clipped samples made a
    3.5 % gain error read 2.5 % and pass, and a healthy board read -26.7 %)."""
    clipped = [f"{ch} {int(k)} samples" for ch, k in zip(CHANNELS, cap.clipped, strict=True)
               if k]
    if clipped:
        raise CalibrationError(
            f"{label}: the output was clipped at its full scale ({', '.join(clipped)} at "
            "the register's limit): lower the rate or the force, or raise the full scale")
    frozen = cap.frozen_run()
    if frozen >= FROZEN_SAMPLES:  # its mean would be one sample's, its noise none
        raise CalibrationError(
            f"{label}: the output did not change on any axis for {frozen} samples "
            f"({frozen / cap.odr_hz:.3g} s): a frozen output")
    means = tuple(capture_mean(cap.channel(ch), cap.odr_hz, float(cap.lsb[i]),
                               f"{label} {ch}") for i, ch in enumerate(CHANNELS))
    return Point(label, cap, means, np.asarray(force, float), np.asarray(rate, float))


FROZEN_SAMPLES = 8
"""Consecutive samples repeating the one before on all six axes that make a capture's
output frozen (a board whose output froze for 6 s got gain errors of -37 % or passed,
and a 30 s freeze in the static capture read as 30 % less noise)."""
RATE_HEADROOM = 0.9
"""Share of the gyro output's range (int16 counts x sensitivity) a station rate may use:
the rest is left for the zero-rate level and a gain error."""


class Procedures:
    """The run's captures, each taken on first use (module docstring)."""

    def __init__(self, dut: Dut, fixture: Fixture, cfg: CaptureSection) -> None:
        self.dut = dut
        self.fixture = fixture
        self.cfg = cfg
        self._static: Point | None = None
        self._six: list[Point] | None = None
        self._rates: list[tuple[str, float, Point]] | None = None
        self._sweep: list[TemperaturePoint] | None = None

    def _at_face(self, face: str, seconds: float, label: str) -> Point:
        self.fixture.face(face)
        self.dut.settle(self.cfg.settle_s)
        cap = self.dut.capture(seconds, label)
        return point(label, cap, np.array(SIX_POSITIONS[face]), np.zeros(3))

    def static(self) -> Point:
        if self._static is None:
            self._static = self._at_face("+Z", self.cfg.static_s, "static +Z up")
        return self._static

    def six_position(self) -> list[Point]:
        if self._six is None:
            self._six = [self._at_face(face, self.cfg.position_s, f"position {face} up")
                         for face in SIX_POSITIONS]
        return self._six

    def rate_table(self) -> list[tuple[str, float, Point]]:
        """(axis, rate_dps, point) for each axis at 0 and +-r; StationError, before the
        table turns, when a station rate lies beyond what the DUT's output can hold at
        its full scale (a station setting, not the board: it was a FAIL)."""
        sens = self.dut.info.gyro_sensitivity_dps
        top = max((abs(r) for r in self.cfg.rates_dps), default=0.0)
        if sens is not None and top > RATE_HEADROOM * INT16_MAX * sens:
            raise StationError(
                f"station capture.rates_dps reaches {top:g} dps, beyond what the DUT's "
                f"gyro output holds at its full scale ({INT16_MAX * sens:.4g} dps at "
                f"{self.dut.info.fs_dps:g} dps full scale, with {1 - RATE_HEADROOM:.0%} "
                "left for the zero-rate level): lower the rates or raise fs_dps in the "
                "DUT URI")
        if self._rates is None:
            out = []
            for axis in AXES:
                for rate in (0.0, *(s * r for r in self.cfg.rates_dps for s in (1, -1))):
                    self.fixture.spin(axis, rate)
                    self.dut.settle(self.cfg.settle_s)
                    label = f"rate {rate:+g} dps about {axis}"
                    cap = self.dut.capture(self.cfg.rate_s, label)
                    u = np.zeros(3)
                    u[AXES.index(axis)] = rate
                    force = np.zeros(3)
                    force[AXES.index(axis)] = 1.0
                    out.append((axis, rate, point(label, cap, force, u)))
                self.fixture.spin(axis, 0.0)
            self.fixture.face("+Z")
            self._rates = out
        return self._rates

    def temperature_sweep(self) -> list[TemperaturePoint]:
        if self._sweep is None:
            c = self.cfg
            out = []
            for set_point in c.temperatures_c:
                self.fixture.set_chamber(set_point)
                self.fixture.face("+Z")
                self.dut.settle(0.0)
                waited, _ = self.dut.wait_temperature_stable(
                    c.temp_stable_c, c.temp_window_s, c.temp_timeout_s)
                chamber = self.fixture.chamber_temperature_c()
                up = self._at_face("+Z", c.temp_capture_s, f"{set_point:g} degC +Z up")
                down = self._at_face("-Z", c.temp_capture_s, f"{set_point:g} degC -Z up")
                out.append(TemperaturePoint(set_point, chamber, waited, up, down))
            self.fixture.set_chamber(c.ambient_c)
            self.fixture.face("+Z")
            self._sweep = out
        return self._sweep


__all__ = ["Point", "Procedures", "TemperaturePoint", "point"]
