"""The device under test: any source URI, read in captures between fixture moves.

A :class:`Dut` keeps one source stream open for the whole run (a simulated chip's
physics and a real chip's FIFO both carry on between captures). Fixture moves happen at
the source's current time; :meth:`Dut.settle` then marks every sample older than
``now + settle_s`` as unusable, so a capture never mixes data from before a move (a FIFO
still holds older samples when the fixture moves). :meth:`Dut.capture` returns the next
``seconds`` of usable samples on a dense index grid (NaN where samples were lost, with
the gaps' reasons). Register access (WHO_AM_I, self-test) is available on chip sources
(``sim://``, ``i2c://``) before the first capture; other sources have none
(:attr:`Dut.registers` is None) and the tests that need it are skipped.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote, urlsplit

import numpy as np
from lsm6ds.driver import LSM6DS, SelfTestResult
from lsm6ds.registers import GYRO_FS, gyro_fs_code
from lsm6ds_sim.model import DATASHEET_PREFIX

from imubench.batch import CHANNELS, Batch, Gap
from imubench.jig.errors import JigError
from imubench.jig.station import DefectsSection
from imubench.sources.base import Source, SourceInfo
from imubench.sources.chip import ChipSource, SimHandles
from imubench.sources.registry import SourceURI, open_source, with_default_param

PATH_PARAMS = ("model",)
"""URI parameters holding a file path, resolved against the station file's directory (a
shipped ``datasheet:CHIP`` model name is left as it is)."""
SELF_TEST_FS_DPS = 2000.0
"""Gyro full scale of the datasheet self-test procedure (``LSM6DS.self_test``)."""


def resolve_uri_paths(uri: str, base: Path) -> str:
    """``uri`` with relative file parameters (:data:`PATH_PARAMS`) made absolute."""
    parsed = SourceURI.parse(uri)
    text = uri
    for name in PATH_PARAMS:
        value = parsed.params.get(name)
        if (value and not value.startswith(DATASHEET_PREFIX)
                and not Path(value).expanduser().is_absolute()):
            absolute = str((base / value).resolve())
            query = urlsplit(text).query
            pairs = [p for p in query.split("&") if p]
            pairs = [f"{name}={quote(absolute, safe='/')}" if p.split("=", 1)[0] == name else p
                     for p in pairs]
            text = text[: len(text) - len(query)] + "&".join(pairs)
    return text


@dataclass(frozen=True)
class Capture:
    """One capture: ``n`` sample periods from sample index ``index0``.

    Attributes:
        label: what was captured (``static +Z``, ``rate +100 dps about x``, ...).
        odr_hz: the rate of the samples, Hz: the ODR measured from the chip's timestamp
            counter where the source measures it (a part 9.5 % slow read its noise
            density 4.8 % low at the nominal rate), else the nominal ODR.
        index0: sample index of the first sample.
        values: (n, 6) float64 dps and g in gx..az order, NaN where lost.
        temp_c: (n,) die temperature, NaN where lost or not measured.
        t0_s: source time of the first sample, s.
        gaps: the holes inside the capture with their reasons.
        lsb: (6,) output resolution per channel (dps, g), 0 where unknown.
        clipped: (6,) samples per channel at the output's limits (raw -32768 or 32767:
            the input was beyond the full scale; 0 where raw counts are not known).
    """

    label: str
    odr_hz: float
    index0: int
    values: np.ndarray
    temp_c: np.ndarray
    t0_s: float
    gaps: tuple[Gap, ...]
    lsb: np.ndarray
    clipped: np.ndarray

    def __len__(self) -> int:
        return len(self.values)

    @property
    def duration_s(self) -> float:
        return len(self.values) / self.odr_hz

    @property
    def lost(self) -> int:
        """Samples missing from the capture's index grid."""
        return int(np.isnan(self.values[:, 0]).sum())

    def channel(self, name: str) -> np.ndarray:
        return self.values[:, CHANNELS.index(name)]

    def frozen_run(self) -> int:
        """The longest run of consecutive samples that repeat the one before on every
        channel at once: a frozen output (noise moves each axis by an LSB or more
        between samples, so six axes repeating together even twice is rare)."""
        same = np.all(self.values[1:] == self.values[:-1], axis=1)
        if not same.any():
            return 0
        edges = np.diff(np.r_[0, same.astype(np.int8), 0])
        return int((np.nonzero(edges < 0)[0] - np.nonzero(edges > 0)[0]).max())


DUT_IO_TIMEOUT_S = 10.0
"""A board that answers no transaction for this long (source time) has gone: its tests fail
naming it, where a board unplugged mid-run hung the jig without a word (the URI's own
``io_timeout_s`` wins)."""


class Dut:
    """The board under test behind a source URI (module docstring).

    Args:
        uri: the source URI.
        defects: defects to inject into a simulated chip (``sim://`` only).
    """

    def __init__(self, uri: str, defects: DefectsSection | None = None) -> None:
        self.uri = uri
        self.source: Source = open_source(with_default_param(uri, "io_timeout_s",
                                                             DUT_IO_TIMEOUT_S))
        self.info: SourceInfo = self.source.info
        chip = self.source if isinstance(self.source, ChipSource) else None
        self.registers: LSM6DS | None = chip.dev if chip is not None else None
        self.sim: SimHandles | None = chip.sim if chip is not None else None
        self.lsb = np.array([self.info.gyro_sensitivity_dps or 0.0] * 3
                            + [self.info.accel_sensitivity_g or 0.0] * 3)
        self._streaming = False
        self._valid_from_s = 0.0
        self._pending: Batch | None = None
        if defects is not None and defects.any:
            self._inject(defects)
        self.source.prepare()  # slow set-up (a simulator's first noise blocks) now

    def _inject(self, d: DefectsSection) -> None:
        if self.sim is None:
            raise JigError(f"DUT {self.uri!r}: defects can only be injected into sim://")
        chip = self.sim.chip
        if d.self_test_gyro_dps is not None:
            lsb = GYRO_FS[gyro_fs_code(SELF_TEST_FS_DPS)][1]
            chip.sim_self_test_gyro_lsb = np.full(3, d.self_test_gyro_dps / lsb)
        if d.self_test_accel_g is not None:
            chip.sim_self_test_accel_g = np.full(3, d.self_test_accel_g)
        if d.stuck_axis:
            chip.sim_stick_axis(d.stuck_axis)
        if d.fifo_drop_rate:
            chip.sim_set_fifo_drop_rate(d.fifo_drop_rate, seed=int(self.info.config["seed"]))

    # -- registers (before streaming) ------------------------------------------------
    def _registers(self, what: str) -> LSM6DS:
        if self.registers is None:
            raise JigError(f"DUT {self.uri!r}: {what} needs register access (sim:// or i2c://)")
        if self._streaming:
            raise JigError(f"DUT {self.uri!r}: {what} must run before the first capture"
                           " (it reconfigures the chip)")
        return self.registers

    def who_am_i(self) -> int:
        """WHO_AM_I, checked against the chip named in the URI (raises on a mismatch)."""
        return self._registers("WHO_AM_I").probe()

    def read_who_am_i(self) -> int:
        """The raw WHO_AM_I register, whatever it holds."""
        return self._registers("WHO_AM_I").read_reg("WHO_AM_I")

    def self_test(self) -> SelfTestResult:
        """The datasheet self-test (``lsm6ds.driver.LSM6DS.self_test``)."""
        return self._registers("self-test").self_test()

    # -- streaming ----------------------------------------------------------------------
    @property
    def elapsed_s(self) -> float:
        """Source time since the stream started (0 before)."""
        return self.source.elapsed_s if self._streaming else 0.0

    def settle(self, seconds: float) -> None:
        """Use no sample older than ``seconds`` from now (call after every move)."""
        self._valid_from_s = self.elapsed_s + max(0.0, seconds)

    def _next(self) -> Batch:
        if self._pending is not None:
            b, self._pending = self._pending, None
            return b
        if not self._streaming:
            self.source.open()
            self._streaming = True
        batch = self.source.read()
        if batch is None:
            raise JigError(f"DUT {self.uri!r}: the stream ended during a capture")
        return batch

    def capture(self, seconds: float, label: str) -> Capture:
        """The next ``seconds`` of usable samples (module docstring)."""
        odr = self.info.odr_hz
        n = max(1, round(seconds * odr))
        parts: list[Batch] = []
        gaps: list[Gap] = []
        first: int | None = None
        while True:
            b = self._next()
            if not len(b):
                gaps.extend(g for g in b.gaps if first is not None)
                continue
            if first is None:
                ok = np.nonzero(b.t_s >= self._valid_from_s)[0]
                if not len(ok):
                    continue
                k = int(ok[0])
                first = int(b.index[k])
                b = _tail(b, k)
            end = first + n
            inside = int(np.searchsorted(b.index, end))
            if inside < len(b):
                self._pending = _tail(b, inside)
                b = b.head(inside)
            if len(b):
                parts.append(b)
                gaps.extend(g for g in b.gaps if g.at > first)
            if self._pending is not None or (len(b) and int(b.index[-1]) >= end - 1):
                break
        rate = self.measured_odr_hz or odr
        return _dense(label, rate, first, n, parts, tuple(gaps), self.lsb)

    def wait_temperature_stable(self, stable_c: float, window_s: float,
                                timeout_s: float) -> tuple[float, float]:
        """Read and discard data until the die temperature changed by less than
        ``stable_c`` over the last ``window_s`` of source time; returns (seconds
        waited, last temperature). Raises after ``timeout_s``."""
        start = self.elapsed_s
        history: list[tuple[float, float]] = []
        while True:
            b = self._next()
            if not len(b):
                continue
            finite = np.isfinite(b.temp_c)
            if not finite.any():
                raise JigError(f"DUT {self.uri!r}: no die temperature in the data; a"
                               " temperature sweep needs one")
            for t, temp in zip(b.t_s[finite][:: max(1, finite.sum() // 8)],
                               b.temp_c[finite][:: max(1, finite.sum() // 8)], strict=True):
                history.append((float(t), float(temp)))
            t_now = history[-1][0]
            history = [h for h in history if h[0] >= t_now - window_s]
            temps = [h[1] for h in history]
            if t_now - history[0][0] >= 0.9 * window_s and max(temps) - min(temps) < stable_c:
                self.settle(0.0)
                return self.elapsed_s - start, temps[-1]
            if self.elapsed_s - start > timeout_s:
                raise JigError(
                    f"DUT {self.uri!r}: die temperature not stable within {timeout_s:g} s"
                    f" (last {window_s:g} s spanned {max(temps) - min(temps):.3f} degC)"
                )

    @property
    def measured_odr_hz(self) -> float | None:
        return self.source.measured_odr_hz

    def telemetry(self) -> dict[str, object]:
        return self.source.telemetry().as_dict()

    def close(self) -> None:
        self.source.close()


def _tail(b: Batch, k: int) -> Batch:
    """Samples ``k..`` of ``b`` with the gaps that end after sample ``k - 1``."""
    if k == 0:
        return b
    after = int(b.index[k - 1])
    return Batch(b.index[k:], b.t_s[k:], b.values[k:], b.temp_c[k:],
                 None if b.raw is None else b.raw[k:],
                 tuple(g for g in b.gaps if g.at > after))


def _dense(label: str, odr: float, first: int, n: int, parts: list[Batch],
           gaps: tuple[Gap, ...], lsb: np.ndarray) -> Capture:
    values = np.full((n, len(CHANNELS)), np.nan)
    temp = np.full(n, np.nan)
    clipped = np.zeros(len(CHANNELS), dtype=np.int64)
    t0 = float("nan")
    for b in parts:
        pos = b.index - first
        values[pos] = b.values
        temp[pos] = b.temp_c
        if b.raw is not None:
            clipped += np.count_nonzero((b.raw == INT16_MIN) | (b.raw == INT16_MAX), axis=0)
        if not np.isfinite(t0):
            t0 = float(b.t_s[0])
    return Capture(label, odr, first, values, temp, t0, gaps, lsb, clipped)


INT16_MIN, INT16_MAX = -32768, 32767
"""The output registers' limits: a sample there was clipped at the full scale."""


__all__ = ["Capture", "Dut", "resolve_uri_paths"]
