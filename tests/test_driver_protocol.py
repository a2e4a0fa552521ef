"""Byte-exact protocol tests of the LSM6DS driver, in the style of pymeasure's
``expected_protocol``: a recording bus logs every transaction and the test compares the
exact sequence (register writes of ``configure``, FIFO set-up, FIFO read transactions)."""

from __future__ import annotations

from typing import Any

import pytest
from lsm6ds.bus import I2C_M_RD, I2CBus, msg_bytes
from lsm6ds.driver import LSM6DS, ImuConfig
from lsm6ds.errors import BusBudgetError, ConfigurationError, DriverIOError, ProbeError
from lsm6ds.stream import FifoStream
from lsm6ds_sim.chip import SimChip
from lsm6ds_sim.clock import SimClock
from lsm6ds_sim.i2c import SimI2CBus
from smbus2 import i2c_msg

A = 0x6A


class RecordingBus:
    """Forwards to a bus and logs ('w', reg, value) / ('r', reg, n) / ('rdwr', reg, n)."""

    def __init__(self, inner: I2CBus) -> None:
        self.inner = inner
        self.log: list[tuple[Any, ...]] = []

    def read_byte_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
        self.log.append(("r", register, 1))
        return self.inner.read_byte_data(i2c_addr, register)

    def write_byte_data(
        self, i2c_addr: int, register: int, value: int, force: bool | None = None
    ) -> None:
        self.log.append(("w", register, value))
        self.inner.write_byte_data(i2c_addr, register, value)

    def read_i2c_block_data(
        self, i2c_addr: int, register: int, length: int, force: bool | None = None
    ) -> list[int]:
        self.log.append(("r", register, length))
        return self.inner.read_i2c_block_data(i2c_addr, register, length)

    def write_i2c_block_data(
        self, i2c_addr: int, register: int, data: Any, force: bool | None = None
    ) -> None:
        self.log.append(("wb", register, bytes(data)))
        self.inner.write_i2c_block_data(i2c_addr, register, data)

    def i2c_rdwr(self, *msgs: i2c_msg) -> None:
        assert len(msgs) == 2 and not msgs[0].flags & I2C_M_RD and msgs[1].flags & I2C_M_RD
        self.log.append(("rdwr", msg_bytes(msgs[0])[0], msgs[1].len))
        self.inner.i2c_rdwr(*msgs)


def rig(chip: str = "lsm6dsl", **kw: Any) -> tuple[SimClock, SimChip, RecordingBus, LSM6DS]:
    clock = SimClock()
    sim = SimChip(chip, clock, **kw)
    inner = SimI2CBus(clock)
    inner.attach(A, sim)
    bus = RecordingBus(inner)
    return clock, sim, bus, LSM6DS(bus, chip, A, sleep=clock.sleep, monotonic=clock.now)


def test_configure_exact_writes_lsm6dsl() -> None:
    _, sim, bus, dev = rig()
    dev.configure(ImuConfig(odr_hz=104, fs_dps=250, fs_g=2))
    assert bus.log == [
        ("w", 0x12, 0x44),  # CTRL3_C: BDU | IF_INC
        ("w", 0x10, 0x40),  # CTRL1_XL: 104 Hz, 2 g
        ("w", 0x11, 0x40),  # CTRL2_G: 104 Hz, 250 dps
        ("w", 0x15, 0x00),  # CTRL6_C: accel high performance
        ("w", 0x16, 0x00),  # CTRL7_G: gyro high performance
        ("w", 0x13, 0x00),  # CTRL4_C: no gyro LPF1
        ("w", 0x5C, 0x10),  # WAKE_UP_DUR: TIMER_HR (25 us)
        ("w", 0x19, 0x24),  # CTRL10_C: TIMER_EN | FUNC_EN
    ]
    assert sim.sim_stats["reserved_writes"] == 0


def test_configure_exact_writes_lsm6ds3h_low_power_2000dps_16g() -> None:
    _, sim, bus, dev = rig("lsm6ds3h")
    dev.configure(ImuConfig(odr_hz=416, fs_dps=2000, fs_g=16, high_performance=False))
    assert bus.log == [
        ("w", 0x12, 0x44),
        ("w", 0x10, 0x64),
        ("w", 0x11, 0x6C),
        ("w", 0x15, 0x10),
        ("w", 0x16, 0x80),
        ("w", 0x5C, 0x10),
        ("w", 0x58, 0x80),  # DS3H: TIMER_EN is TAP_CFG bit 7 (§10)
    ]
    assert sim.sim_stats["reserved_writes"] == 0


def test_probe_reset_sequence_and_mismatch_message() -> None:
    _, _, bus, dev = rig()
    assert dev.probe() == 0x6A
    bus.log.clear()
    dev.reset()
    assert bus.log == [("w", 0x12, 0x05), ("r", 0x12, 1), ("w", 0x12, 0x84)]
    wrong = LSM6DS(bus, "lsm6ds3h", A)
    with pytest.raises(ProbeError, match=r"0x6a \(looks like lsm6dsm/lsm6dsl\).*0x69"):
        wrong.probe()


def test_fifo_start_and_read_transactions() -> None:
    clock, _, bus, dev = rig()
    stream = FifoStream(dev, ImuConfig(odr_hz=104), watermark_s=0.1)
    stream.start(reset=False)
    fifo_log = bus.log[-7:]
    assert fifo_log == [
        ("w", 0x0A, 0x00),  # bypass: flush
        ("w", 0x06, 51),  # FTH = one pattern of 8 slots x 6 words + 3 timestamp words
        ("w", 0x07, 0x80),  # TIMER_PEDO_FIFO_EN
        ("w", 0x08, 0x09),  # gyro and accel in every slot
        ("w", 0x09, 0x28),  # DS4 (timestamp) decimation /8
        ("w", 0x42, 0xAA),  # timestamp reset
        ("w", 0x0A, 0x26),  # FIFO ODR 104 Hz, continuous
    ]
    bus.log.clear()
    clock.advance(20.5 / 104)  # 20 slots: 120 data words + 3 timestamp sets = 129 words
    chunk, left = stream.poll()
    assert bus.log == [
        ("rdwr", 0x3A, 4),  # FIFO_STATUS1..4
        ("rdwr", 0x3E, 204),  # two whole patterns (2 x 51 words) in one i2c_rdwr burst
        ("rdwr", 0x3A, 4),  # FIFO_STATUS1..4 again: where the burst really began
        ("rdwr", 0x20, 2),  # temperature
    ]
    assert chunk is not None and list(chunk.index) == list(range(16)) and left == 27


def test_io_errors_are_retried_then_raised() -> None:
    class Flaky(RecordingBus):
        fails = 2

        def read_byte_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
            if self.fails:
                self.fails -= 1
                raise OSError(121, "Remote I/O error")
            return super().read_byte_data(i2c_addr, register)

    clock = SimClock()
    inner = SimI2CBus(clock)
    inner.attach(A, SimChip("lsm6dsl", clock))
    dev = LSM6DS(Flaky(inner), "lsm6dsl", sleep=clock.sleep, monotonic=clock.now)
    assert dev.read_reg("WHO_AM_I") == 0x6A
    assert dev.counters["io_errors"] == 2 and dev.counters["retries"] == 2
    assert clock.now() == pytest.approx(0.001 + 0.002)  # backoff doubles
    dead = LSM6DS(inner, "lsm6dsl", 0x6B, sleep=clock.sleep, retries=2)
    with pytest.raises(DriverIOError, match=r"0x6b.*after 2 retries"):
        dead.read_reg("WHO_AM_I")


def test_bus_budget_refuses_6660_on_400khz() -> None:
    _, _, _, dev = rig()
    with pytest.raises(BusBudgetError, match=r"6660 Hz.*44,444 B/s.*3330 Hz"):
        FifoStream(dev, ImuConfig(odr_hz=6660), bus_hz=400e3)
    degraded = FifoStream(dev, ImuConfig(odr_hz=6660), bus_hz=400e3, on_overbudget="degrade")
    assert degraded.odr_hz == 3330 and degraded.degraded_from_hz == 6660
    # an explicit, equal accelerometer ODR is degraded with the gyro's (one FIFO ODR)
    both = FifoStream(dev, ImuConfig(odr_hz=6660, accel_odr_hz=6660), bus_hz=400e3,
                      on_overbudget="degrade")
    assert both.cfg.odr_hz == both.cfg.odr_xl_hz == 3330
    fits = FifoStream(dev, ImuConfig(odr_hz=3330), bus_hz=400e3)
    # 3330 x (12 + 6/16) = 41 209 B/s <= 95 % of 400e3 / 9; with /8 it would not fit
    assert fits.ts_decimation == 16 and fits.bytes_per_s <= 0.95 * 400e3 / 9


def test_impossible_configuration_is_refused() -> None:
    _, _, _, dev = rig("lsm6ds3h")
    with pytest.raises(ConfigurationError, match="gyro ODR 3330"):
        dev.configure(ImuConfig(odr_hz=3330))


def test_unequal_gyro_and_accel_odr_direct_reads_and_fifo_refusal() -> None:
    """Gyro 208 Hz, accelerometer 52 Hz: configure writes each ODR code (§3.1, §3.2) and
    the outputs update at their own rates; FIFO streaming refuses with a message that
    names both rates (a Batch has one sample index for the six channels)."""
    import numpy as np
    from lsm6ds_sim.model import NoiseModel
    from lsm6ds_sim.physics import SensorPhysics

    clock = SimClock()
    physics = SensorPhysics(NoiseModel.quiet().with_all(white=0.05), seed=1)
    bus = SimI2CBus(clock)
    bus.attach(0x6A, SimChip("lsm6dsl", clock, physics))
    dev = LSM6DS(bus, "lsm6dsl", 0x6A, sleep=clock.sleep, monotonic=clock.now)
    cfg = ImuConfig(odr_hz=208, accel_odr_hz=52)
    writes = dict(dev.config_writes(cfg))
    assert writes[0x10] >> 4 == 3 and writes[0x11] >> 4 == 5  # CTRL1_XL 52 Hz, CTRL2_G 208 Hz
    dev.configure(cfg)
    rows = []
    for _ in range(208):
        clock.sleep(1 / 208)
        rows.append(dev.read_outputs_raw())
    raw = np.array(rows)
    gyro_updates = np.count_nonzero(np.any(np.diff(raw[:, 1:4], axis=0) != 0, axis=1))
    accel_updates = np.count_nonzero(np.any(np.diff(raw[:, 4:7], axis=0) != 0, axis=1))
    assert gyro_updates >= 200 and 50 <= accel_updates <= 52
    with pytest.raises(ConfigurationError, match="gyro at 208 Hz and accelerometer at 52 Hz"):
        FifoStream(dev, cfg)
