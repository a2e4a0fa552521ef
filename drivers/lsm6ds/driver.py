"""I2C driver of the LSM6DS3H / LSM6DSM / LSM6DSL: probe, reset, configure, outputs,
temperature, timestamp and self-test.

The driver talks to any :class:`lsm6ds.bus.I2CBus` (a real ``smbus2.SMBus`` or the
simulated bus) and takes its time functions as parameters (``sleep``, ``monotonic``), so
the same code runs on hardware in real time and on the simulator in virtual time. Every
transfer goes through :meth:`LSM6DS._xfer`, which retries an ``OSError`` with exponential
backoff and counts ``io_errors`` and ``retries``; after the retries it raises
:class:`~lsm6ds.errors.DriverIOError`.

Register addresses, fields and scales come from :mod:`lsm6ds.registers` (the simulator
reads the same tables). Reference section numbers refer to ``lsm6ds-registers.md``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np

from lsm6ds.bus import I2CBus, burst_read
from lsm6ds.errors import ConfigurationError, DriverIOError, ProbeError, SelfTestError
from lsm6ds.registers import (
    ACCEL_FS,
    BOOT_WAIT_S,
    GYRO_FS,
    ODR_HZ,
    SELF_TEST_ACCEL_G,
    SELF_TEST_GYRO_DPS,
    SW_RESET_WAIT_S,
    TIMESTAMP_RESET_VALUE,
    ChipMap,
    accel_fs_code,
    chip_map,
    gyro_fs_code,
)

T = TypeVar("T")


@dataclass(frozen=True)
class ImuConfig:
    """What :meth:`LSM6DS.configure` programs.

    Attributes:
        odr_hz: output data rate of the gyro (and of the accelerometer unless
            ``accel_odr_hz`` is given), Hz (§4.1 table value).
        fs_dps: gyro full scale, dps (125, 250, 500, 1000, 2000).
        fs_g: accelerometer full scale, g (2, 4, 8, 16).
        high_performance: keep XL_HM_MODE / G_HM_MODE = 0 (high-performance on, §4.3).
        gyro_lpf1: enable the gyro digital LPF1 (LSM6DSL/DSM CTRL4_C.LPF1_SEL_G only).
        bdu: block data update (CTRL3_C.BDU, recommended with the FIFO, §5).
        timestamp: enable the 24-bit timestamp counter at 25 us (§7-8).
    """

    odr_hz: float = 104.0
    accel_odr_hz: float | None = None
    """Accelerometer ODR when it differs from the gyro's, Hz (None: the same). Direct
    output reads support it; :class:`lsm6ds.stream.FifoStream` refuses it (see there)."""
    fs_dps: float = 250.0
    fs_g: float = 2.0
    high_performance: bool = True
    gyro_lpf1: bool = False
    bdu: bool = True
    timestamp: bool = True

    @property
    def odr_xl_hz(self) -> float:
        """Accelerometer ODR, Hz."""
        return self.odr_hz if self.accel_odr_hz is None else self.accel_odr_hz

    @property
    def gyro_sensitivity_dps(self) -> float:
        return GYRO_FS[gyro_fs_code(self.fs_dps)][1]

    @property
    def accel_sensitivity_g(self) -> float:
        return ACCEL_FS[accel_fs_code(self.fs_g)][1]


@dataclass
class AxisVerdict:
    """Self-test result of one axis: deflection (|on - off|) and its limits."""

    sensor: str
    axis: str
    deflection: float
    low: float
    high: float
    unit: str

    @property
    def passed(self) -> bool:
        return self.low <= self.deflection <= self.high

    def __str__(self) -> str:
        verdict = "ok" if self.passed else "FAIL"
        return (
            f"{self.sensor} {self.axis}: {self.deflection:.3f} {self.unit} "
            f"(limits {self.low:g}..{self.high:g}) {verdict}"
        )


@dataclass
class SelfTestResult:
    """Outcome of :meth:`LSM6DS.self_test`; ``str()`` names every failing axis."""

    axes: list[AxisVerdict] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return all(a.passed for a in self.axes)

    @property
    def failures(self) -> list[AxisVerdict]:
        return [a for a in self.axes if not a.passed]

    def __str__(self) -> str:
        if self.passed:
            return "self-test passed: " + "; ".join(str(a) for a in self.axes)
        return "self-test FAILED: " + "; ".join(str(a) for a in self.failures)


class LSM6DS:
    """One LSM6DS3H / LSM6DSM / LSM6DSL on an I2C bus.

    Args:
        bus: anything satisfying :class:`lsm6ds.bus.I2CBus`.
        chip: ``lsm6ds3h``, ``lsm6dsm`` or ``lsm6dsl`` (WHO_AM_I cannot tell DSL from DSM,
            §1, so the chip is a parameter and WHO_AM_I a sanity check).
        addr: 7-bit address (0x6A or 0x6B).
        sleep, monotonic: time functions (the simulator passes its clock's).
        retries: retries of a failed transfer before :class:`DriverIOError`.
        backoff_s: first retry delay, doubled per retry (capped at 0.5 s).
    """

    def __init__(
        self,
        bus: I2CBus,
        chip: str = "lsm6dsl",
        addr: int = 0x6A,
        *,
        sleep: Callable[[float], None] = time.sleep,
        monotonic: Callable[[], float] = time.monotonic,
        retries: int = 5,
        backoff_s: float = 0.001,
    ) -> None:
        self.bus = bus
        self.map: ChipMap = chip_map(chip)
        self.chip = self.map.name
        self.addr = addr
        self.sleep = sleep
        self.monotonic = monotonic
        self.retries = retries
        self.backoff_s = backoff_s
        self.counters: dict[str, int] = {
            "io_errors": 0,
            "retries": 0,
            "bus_bytes": 0,
            "transactions": 0,
        }
        self.config: ImuConfig | None = None
        self.expected: dict[int, int] = {}
        """Register -> value written by :meth:`configure` (for read-back checks)."""

    # ---------------------------------------------------------------- transfers
    def _xfer(self, what: str, fn: Callable[[], T], wire_bytes: int) -> T:
        delay = self.backoff_s
        for attempt in range(self.retries + 1):
            try:
                result = fn()
            except OSError as exc:
                self.counters["io_errors"] += 1
                if attempt == self.retries:
                    raise DriverIOError(
                        f"{self.chip} at 0x{self.addr:02x}: {what} failed after "
                        f"{self.retries} retries ({exc}); check wiring, address and pull-ups"
                    ) from exc
                self.counters["retries"] += 1
                self.sleep(delay)
                delay = min(delay * 2, 0.5)
                continue
            self.counters["transactions"] += 1
            self.counters["bus_bytes"] += wire_bytes
            return result
        raise AssertionError("unreachable")  # pragma: no cover

    def reg(self, name: str) -> int:
        return self.map.addr(name)

    def read_reg(self, name_or_addr: str | int) -> int:
        a = self.reg(name_or_addr) if isinstance(name_or_addr, str) else name_or_addr
        return self._xfer(
            f"read of register 0x{a:02x}", lambda: self.bus.read_byte_data(self.addr, a), 4
        )

    def write_reg(self, name_or_addr: str | int, value: int) -> None:
        a = self.reg(name_or_addr) if isinstance(name_or_addr, str) else name_or_addr
        self._xfer(
            f"write of 0x{value:02x} to register 0x{a:02x}",
            lambda: self.bus.write_byte_data(self.addr, a, value & 0xFF),
            3,
        )

    def read_block(self, name_or_addr: str | int, length: int) -> bytes:
        """``length`` bytes from a register onwards in one ``i2c_rdwr`` (IF_INC / FIFO)."""
        a = self.reg(name_or_addr) if isinstance(name_or_addr, str) else name_or_addr
        return self._xfer(
            f"{length}-byte read from register 0x{a:02x}",
            lambda: burst_read(self.bus, self.addr, a, length),
            length + 3,
        )

    def write_field(self, name: str, value: int) -> None:
        """Read-modify-write of a bit field."""
        reg, mask = self.map.field_addr_mask(name)
        shift = (mask & -mask).bit_length() - 1
        old = self.read_reg(reg)
        self.write_reg(reg, (old & ~mask) | ((value << shift) & mask))

    # ---------------------------------------------------------------- identity / reset
    def probe(self) -> int:
        """Check WHO_AM_I (§1); raise :class:`ProbeError` naming what was found."""
        try:
            who = self.read_reg("WHO_AM_I")
        except DriverIOError as exc:
            raise ProbeError(f"no answer from an {self.chip} at 0x{self.addr:02x}: {exc}") from exc
        if who != self.map.who_am_i:
            others = [m for m in ("lsm6ds3h", "lsm6dsm", "lsm6dsl") if chip_map(m).who_am_i == who]
            hint = f" (looks like {'/'.join(others)})" if others else ""
            raise ProbeError(
                f"WHO_AM_I at 0x{self.addr:02x} register 0x0F is 0x{who:02x}{hint}, but "
                f"{self.chip} answers 0x{self.map.who_am_i:02x}; check chip= and addr="
            )
        return who

    def reset(self, poll_limit: int = 20) -> None:
        """SW_RESET, wait 50 ms, BOOT, wait 50 ms (Linux st_lsm6dsx sequence, §1)."""
        ctrl3 = self.reg("CTRL3_C")
        self.write_reg(ctrl3, 0x04 | 0x01)  # IF_INC | SW_RESET
        self.sleep(SW_RESET_WAIT_S)
        for _ in range(poll_limit):
            if not self.read_reg(ctrl3) & 0x01:
                break
            self.sleep(SW_RESET_WAIT_S)
        else:
            raise ConfigurationError(
                f"{self.chip} at 0x{self.addr:02x}: CTRL3_C.SW_RESET did not self-clear"
            )
        self.write_reg(ctrl3, 0x04 | 0x80)  # IF_INC | BOOT
        self.sleep(BOOT_WAIT_S)
        self.config = None
        self.expected = {}

    # ---------------------------------------------------------------- configuration
    def config_writes(self, cfg: ImuConfig) -> list[tuple[int, int]]:
        """The exact (register, value) writes :meth:`configure` issues, in order."""
        m = self.map
        try:
            odr_xl = m.odr_code(cfg.odr_xl_hz, "accel")
            odr_g = m.odr_code(cfg.odr_hz, "gyro")
            fs_xl = accel_fs_code(cfg.fs_g)
            fs_g = gyro_fs_code(cfg.fs_dps)
        except ValueError as exc:
            raise ConfigurationError(str(exc)) from None
        writes = [
            (m.addr("CTRL3_C"), (0x40 if cfg.bdu else 0) | 0x04),  # BDU, IF_INC (§3.3)
            (m.addr("CTRL1_XL"), (odr_xl << 4) | (fs_xl << 2)),  # §3.1
            (m.addr("CTRL2_G"), (odr_g << 4) | (fs_g << 1)),  # §3.2
            (m.addr("CTRL6_C"), 0 if cfg.high_performance else 0x10),  # XL_HM_MODE §3.6
            (m.addr("CTRL7_G"), 0 if cfg.high_performance else 0x80),  # G_HM_MODE §3.7
        ]
        if self.chip != "lsm6ds3h":
            writes.append((m.addr("CTRL4_C"), 0x02 if cfg.gyro_lpf1 else 0x00))  # §3.4
        elif cfg.gyro_lpf1:
            raise ConfigurationError(
                "lsm6ds3h has no gyro LPF1 (reference §4.3); set gyro_lpf1=False"
            )
        if cfg.timestamp:
            writes.append((m.addr("WAKE_UP_DUR"), 0x10))  # TIMER_HR = 25 us (§7-8)
            reg, mask = m.field_addr_mask("TIMER_EN")
            if self.chip == "lsm6ds3h":
                writes.append((reg, mask))  # TAP_CFG.TIMER_EN (§10)
            else:
                writes.append((reg, mask | m.field("FUNC_EN").mask))  # CTRL10_C (§7-8)
        return writes

    def configure(self, cfg: ImuConfig) -> None:
        """Program ODR, full scale, power mode, filters, BDU, IF_INC and timestamp."""
        writes = self.config_writes(cfg)
        for reg, value in writes:
            self.write_reg(reg, value)
        self.config = cfg
        self.expected = dict(writes)

    def config_intact(self) -> bool:
        """Read back CTRL1_XL and CTRL2_G: False after a spontaneous chip reset."""
        data = self.read_block("CTRL1_XL", 2)
        return data[0] == self.expected.get(self.reg("CTRL1_XL")) and data[1] == self.expected.get(
            self.reg("CTRL2_G")
        )

    # ---------------------------------------------------------------- data
    def read_temperature_c(self) -> float:
        """OUT_TEMP: raw / (LSB/degC) + 25 degC with the chip's scale (§6)."""
        raw = int(np.frombuffer(self.read_block("OUT_TEMP_L", 2), dtype="<i2")[0])
        return raw / self.map.temp_lsb_per_c + self.map.temp_zero_c

    def read_outputs_raw(self) -> np.ndarray:
        """14-byte burst from OUT_TEMP_L: int16 [temp, gx, gy, gz, ax, ay, az] (§5)."""
        return np.frombuffer(self.read_block("OUT_TEMP_L", 14), dtype="<i2").copy()

    def read_outputs(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(gyro dps (3,), accel g (3,), temperature degC) of the current configuration."""
        if self.config is None:
            raise ConfigurationError("read_outputs before configure()")
        raw = self.read_outputs_raw()
        return (
            raw[1:4] * self.config.gyro_sensitivity_dps,
            raw[4:7] * self.config.accel_sensitivity_g,
            raw[0] / self.map.temp_lsb_per_c + self.map.temp_zero_c,
        )

    def reset_timestamp(self) -> float:
        """Write 0xAA to TIMESTAMP2_REG (§7-8); return the host time of the reset (the
        midpoint of the write transaction)."""
        t0 = self.monotonic()
        self.write_reg("TIMESTAMP2_REG", TIMESTAMP_RESET_VALUE)
        return 0.5 * (t0 + self.monotonic())

    def read_timestamp_ticks(self) -> int:
        data = self.read_block("TIMESTAMP0_REG", 3)
        return data[0] | (data[1] << 8) | (data[2] << 16)

    def wait_data_ready(self, mask: int = 0x03, timeout_s: float = 1.0) -> None:
        """Poll STATUS_REG until all bits of ``mask`` (XLDA|GDA) are set (§3.12)."""
        period = 1.0 / (self.config.odr_hz if self.config else 104.0)
        t_end = self.monotonic() + timeout_s
        while self.read_reg("STATUS_REG") & mask != mask:
            if self.monotonic() > t_end:
                raise ConfigurationError(
                    f"{self.chip}: STATUS_REG never showed data ready (mask 0x{mask:02x})"
                )
            self.sleep(period / 4)

    # ---------------------------------------------------------------- self-test
    def self_test(self, n_average: int = 5, settle_s: float = 0.1) -> SelfTestResult:
        """Datasheet self-test procedure (LSM6DSL/DSM datasheets, "self-test procedure";
        CTRL5_C encoding §3.5): configure accel 52 Hz / 4 g and gyro 208 Hz / 2000 dps,
        settle, average ``n_average`` samples with self-test off, enable positive
        self-test, settle, average again, compare |on - off| per axis with the limits
        (accel 0.09-1.7 g; gyro 150-700 dps at 2000 dps), switch self-test off and
        restore the previous configuration. The limits are datasheet values (✱, not in
        the fetched sources).
        """
        previous = self.config
        st_cfg_writes = [
            (self.reg("CTRL3_C"), 0x44),
            (self.reg("CTRL1_XL"), (3 << 4) | (accel_fs_code(4.0) << 2)),  # 52 Hz, 4 g
            (self.reg("CTRL2_G"), (5 << 4) | (gyro_fs_code(2000.0) << 1)),  # 208 Hz, 2000
            (self.reg("CTRL5_C"), 0x00),
        ]
        for reg, value in st_cfg_writes:
            self.write_reg(reg, value)
        acc_sens = ACCEL_FS[accel_fs_code(4.0)][1]
        gyr_sens = GYRO_FS[gyro_fs_code(2000.0)][1]

        def average() -> np.ndarray:
            self.sleep(settle_s)
            self.read_outputs_raw()  # discard the first sample (datasheet procedure)
            rows = []
            for _ in range(n_average):
                self.sleep(1.0 / 52.0)
                rows.append(self.read_outputs_raw()[1:7].astype(np.float64))
            return np.mean(rows, axis=0)

        try:
            off = average()
            self.write_reg("CTRL5_C", 0x01 | 0x04)  # ST_XL positive, ST_G positive
            on = average()
        finally:
            self.write_reg("CTRL5_C", 0x00)
            self.sleep(settle_s)
            if previous is not None:
                self.configure(previous)
        if not np.all(np.isfinite(on - off)):
            raise SelfTestError(f"{self.chip}: self-test produced no data")
        result = SelfTestResult()
        g_low, g_high = SELF_TEST_GYRO_DPS[2000.0]
        a_low, a_high = SELF_TEST_ACCEL_G
        for i, axis in enumerate("XYZ"):
            result.axes.append(
                AxisVerdict("gyro", axis, abs(on[i] - off[i]) * gyr_sens, g_low, g_high, "dps")
            )
        for i, axis in enumerate("XYZ"):
            result.axes.append(
                AxisVerdict(
                    "accel", axis, abs(on[3 + i] - off[3 + i]) * acc_sens, a_low, a_high, "g"
                )
            )
        return result


def odr_table_hz(chip: str) -> list[float]:
    """ODRs (Hz) usable for gyro and accelerometer together on ``chip`` (§4.1)."""
    m = chip_map(chip)
    return [ODR_HZ[c] for c in m.gyro_odr_codes if c and c in m.accel_odr_codes]
