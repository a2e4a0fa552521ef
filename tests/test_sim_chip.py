"""Register behaviours of the simulated chips, one test per behaviour of the reference
``lsm6ds-registers.md`` (section cited in each test name / docstring)."""

from __future__ import annotations

import errno

import numpy as np
import pytest
from lsm6ds.bus import burst_read
from lsm6ds_sim.chip import SimChip
from lsm6ds_sim.clock import SimClock
from lsm6ds_sim.faults import FaultPlan
from lsm6ds_sim.i2c import SimI2CBus

A = 0x6A
CHIPS = ("lsm6ds3h", "lsm6dsm", "lsm6dsl")


def make(chip: str = "lsm6dsl", bus_hz: float | None = None, **kw: object):
    clock = SimClock()
    sim = SimChip(chip, clock, **kw)  # type: ignore[arg-type]
    bus = SimI2CBus(clock, bus_hz)
    bus.attach(A, sim)
    return clock, sim, bus


def start_fifo(
    bus: SimI2CBus,
    odr_code: int = 4,
    ctrl3: int = 0x09,
    ctrl4: int = 0,
    ctrl2: int = 0,
    mode: int = 6,
) -> None:
    bus.write_byte_data(A, 0x10, odr_code << 4)
    bus.write_byte_data(A, 0x11, odr_code << 4)
    bus.write_byte_data(A, 0x07, ctrl2)
    bus.write_byte_data(A, 0x08, ctrl3)
    bus.write_byte_data(A, 0x09, ctrl4)
    bus.write_byte_data(A, 0x0A, (odr_code << 3) | mode)


def level(bus: SimI2CBus) -> tuple[int, int]:
    s = bus.read_i2c_block_data(A, 0x3A, 2)
    return s[0] | ((s[1] & 0x07) << 8), s[1]


@pytest.mark.parametrize("chip,who", [("lsm6ds3h", 0x69), ("lsm6dsm", 0x6A), ("lsm6dsl", 0x6A)])
def test_who_am_i_section_1(chip: str, who: int) -> None:
    _, _, bus = make(chip)
    assert bus.read_byte_data(A, 0x0F) == who


@pytest.mark.parametrize("chip", CHIPS)
def test_reset_values_section_3_13(chip: str) -> None:
    _, _, bus = make(chip)
    assert bus.read_byte_data(A, 0x12) == 0x04  # CTRL3_C: IF_INC = 1
    ctrl9, ctrl10 = bus.read_i2c_block_data(A, 0x18, 2)
    assert (ctrl9, ctrl10) == ((0x38, 0x38) if chip == "lsm6ds3h" else (0xE0, 0x00))
    assert bus.read_i2c_block_data(A, 0x10, 2) == [0, 0]
    assert level(bus) == (0, 0x10)  # FIFO bypass, empty flag set


def test_sw_reset_restores_and_self_clears_section_1() -> None:
    clock, _, bus = make()
    bus.write_byte_data(A, 0x10, 0x40)
    bus.write_byte_data(A, 0x12, 0x05)
    assert bus.read_byte_data(A, 0x12) & 0x01  # still resetting
    clock.advance(0.001)
    assert bus.read_byte_data(A, 0x12) == 0x04
    assert bus.read_byte_data(A, 0x10) == 0x00


def test_boot_bit_self_clears_section_3_3() -> None:
    clock, _, bus = make()
    bus.write_byte_data(A, 0x10, 0x40)
    bus.write_byte_data(A, 0x12, 0x84)
    assert bus.read_byte_data(A, 0x12) & 0x80
    clock.advance(0.02)
    assert bus.read_byte_data(A, 0x12) == 0x04
    assert bus.read_byte_data(A, 0x10) == 0x40  # BOOT reloads trimming, not the config


def test_if_inc_auto_increment_section_3_3() -> None:
    _, _, bus = make()
    assert bus.read_i2c_block_data(A, 0x0F, 4) == [0x6A, 0, 0, 0x04]
    bus.write_byte_data(A, 0x12, 0x00)  # IF_INC off: same register repeated
    assert bus.read_i2c_block_data(A, 0x0F, 3) == [0x6A] * 3


def test_rounding_wraps_output_burst_section_3_5() -> None:
    clock, _, bus = make()
    bus.write_byte_data(A, 0x10, 0x40)
    bus.write_byte_data(A, 0x14, 0x20)  # ROUNDING = 1: accel only
    clock.advance(0.05)
    data = bus.read_i2c_block_data(A, 0x28, 12)
    assert data[:6] == data[6:]


def test_output_registers_and_status_section_3_12_and_5() -> None:
    clock, _, bus = make()
    bus.write_byte_data(A, 0x10, 0x40)  # 104 Hz, 2 g
    bus.write_byte_data(A, 0x11, 0x40)
    assert bus.read_byte_data(A, 0x1E) == 0
    clock.advance(0.02)
    assert bus.read_byte_data(A, 0x1E) & 0x07 == 0x07  # XLDA GDA TDA
    raw = np.frombuffer(burst_read(bus, A, 0x20, 14), "<i2")
    assert raw[6] == round(1.0 / 0.061e-3)  # +1 g on Z at 0.061 mg/LSB (§4.2)
    assert bus.read_byte_data(A, 0x1E) == 0  # cleared by reading the outputs


@pytest.mark.parametrize("chip,lsb", [("lsm6dsl", 256), ("lsm6ds3h", 16)])
def test_temperature_scale_section_6(chip: str, lsb: int) -> None:
    class Warm:
        def generate(self, n: int, dt_s: float):
            from lsm6ds_sim.physics import TrueSamples

            return TrueSamples(np.zeros((n, 3)), np.zeros((n, 3)), np.full(n, 35.0))

    clock, _, bus = make(chip, physics=Warm())
    bus.write_byte_data(A, 0x10, 0x40)
    clock.advance(0.05)
    assert np.frombuffer(burst_read(bus, A, 0x20, 2), "<i2")[0] == 10 * lsb


def test_bdu_latches_pairs_section_3_3() -> None:
    def split_read(bdu: bool) -> tuple[int, int]:
        clock, _sim, bus = make(sim_counting=True)
        bus.write_byte_data(A, 0x12, 0x44 if bdu else 0x04)
        bus.write_byte_data(A, 0x11, 0x40)
        clock.advance(1.0)
        low = bus.read_byte_data(A, 0x22)  # OUTX_L_G
        clock.advance(300 / 104)  # 300 more samples: the counter's high byte moves
        high = bus.read_byte_data(A, 0x23)
        return low, high

    low, high = split_read(bdu=True)
    assert (high << 8 | low) == 104  # one sample: the one whose L byte was read
    low, high = split_read(bdu=False)
    assert (high << 8 | low) != 104  # torn: L from sample 104, H from sample 404


def test_fifo_level_after_k_periods_section_9_2() -> None:
    clock, _, bus = make()
    start_fifo(bus)
    clock.advance(10.5 / 104)  # 10 periods (+ half a period)
    assert level(bus)[0] == 10 * 6  # gyro + accel data sets, 3 words each


def test_fifo_words_are_pattern_ordered_gyro_then_accel_section_9_4() -> None:
    clock, _, bus = make(sim_counting=True)
    start_fifo(bus)
    clock.advance(5.5 / 104)
    words = np.frombuffer(burst_read(bus, A, 0x3E, 60), "<i2").reshape(-1, 6)
    assert np.all(np.diff(words[:, 0]) == 1)  # gyro X counts samples
    assert np.all(words[:, 5] == round(1 / 0.061e-3))  # accel Z = 1 g
    assert level(bus)[0] == 0


def test_fifo_decimation_and_pattern_index_section_9_4() -> None:
    clock, _, bus = make(sim_counting=True)
    start_fifo(bus, ctrl3=(1 << 3) | 2)  # gyro every slot, accel /2
    clock.advance(4.5 / 104)
    # pattern: slot0 = G A (6 words), slot1 = G (3 words): 9 words per pattern
    assert level(bus)[0] == 18
    assert bus.read_i2c_block_data(A, 0x3C, 2) == [0, 0]
    burst_read(bus, A, 0x3E, 12)  # G A of slot 0
    assert bus.read_i2c_block_data(A, 0x3C, 2) == [6, 0]  # next word: slot 1 gyro
    burst_read(bus, A, 0x3E, 6)
    assert bus.read_i2c_block_data(A, 0x3C, 2) == [0, 0]


def test_fifo_data_out_wraps_and_pops_bytewise_section_9_4() -> None:
    clock, _, bus = make(sim_counting=True)
    start_fifo(bus)
    clock.advance(2.5 / 104)
    b1 = burst_read(bus, A, 0x3E, 3)  # odd length: word 0 and the low byte of word 1
    b2 = burst_read(bus, A, 0x3F, 1)  # the high byte of word 1
    words = np.frombuffer(b1[:2] + b1[2:3] + b2, "<i2")
    assert words[1] == 0  # gyro Y of a sensor at rest
    assert level(bus)[0] == 12 - 2


def test_overrun_continuous_overwrites_oldest_section_9_3() -> None:
    clock, _sim, bus = make(sim_counting=True)
    start_fifo(bus, mode=6)
    clock.advance(400 / 104)  # 400 samples x 6 words > 2046
    n, flags = level(bus)
    assert flags & 0x40  # OVER_RUN
    assert n <= 2046 and n % 3 == 0
    first = np.frombuffer(burst_read(bus, A, 0x3E, 12), "<i2")
    assert first[0] > 400 - 341  # oldest samples overwritten: the newest are kept


def test_overrun_fifo_mode_stops_section_9_3() -> None:
    clock, _, bus = make(sim_counting=True)
    start_fifo(bus, mode=1)
    clock.advance(400 / 104)
    n, flags = level(bus)
    assert flags & 0x20 and not flags & 0x40  # FULL, nothing overwritten
    assert n == 2046
    first = np.frombuffer(burst_read(bus, A, 0x3E, 12), "<i2")
    assert first[0] == 1  # the first sample after the start is still there


def test_stop_on_threshold_and_watermark_flag_section_9_1() -> None:
    clock, _, bus = make()
    bus.write_byte_data(A, 0x06, 60)  # FTH = 60 words
    start_fifo(bus, mode=1, ctrl4=0x80)  # STOP_ON_FTH
    clock.advance(30 / 104)
    n, flags = level(bus)
    assert n == 60 and flags & 0x80


def test_fifo_odr_zero_disables_section_9_3() -> None:
    clock, _, bus = make()
    start_fifo(bus)
    bus.write_byte_data(A, 0x0A, 0x06)  # continuous but ODR_FIFO = 0
    clock.advance(1.0)
    assert level(bus)[0] == 0


def test_bypass_empties_fifo_section_9_3() -> None:
    clock, _, bus = make()
    start_fifo(bus)
    clock.advance(0.5)
    bus.write_byte_data(A, 0x0A, 0x00)
    assert level(bus) == (0, 0x10)


def test_diff_fifo_width_section_9_1() -> None:
    # DS3H reports the level with 12 bits in FIFO_STATUS2[3:0]; DSL with 11 bits
    clock, _, bus = make("lsm6ds3h")
    start_fifo(bus)
    clock.advance(300 / 104)
    s = bus.read_i2c_block_data(A, 0x3A, 2)
    assert s[0] | ((s[1] & 0x0F) << 8) == 300 * 6 and (s[1] & 0x0F) == 7


def test_timestamp_counter_resolution_and_reset_section_7_8() -> None:
    clock, _, bus = make()
    bus.write_byte_data(A, 0x19, 0x24)  # TIMER_EN | FUNC_EN
    bus.write_byte_data(A, 0x5C, 0x10)  # TIMER_HR: 25 us
    clock.advance(0.1)
    t = bus.read_i2c_block_data(A, 0x40, 3)
    assert t[0] | t[1] << 8 | t[2] << 16 == 4000
    bus.write_byte_data(A, 0x42, 0xAA)
    clock.advance(0.01)
    t = bus.read_i2c_block_data(A, 0x40, 3)
    assert t[0] | t[1] << 8 | t[2] << 16 == 400
    bus.write_byte_data(A, 0x5C, 0x00)  # 6.4 ms per LSB
    t = bus.read_i2c_block_data(A, 0x40, 3)
    assert t[0] | t[1] << 8 | t[2] << 16 == 400 // 256


def test_timestamp_enable_on_ds3h_is_tap_cfg_section_10() -> None:
    clock, _, bus = make("lsm6ds3h")
    bus.write_byte_data(A, 0x19, 0x24)  # DSL's TIMER_EN position: no timer on DS3H
    bus.write_byte_data(A, 0x5C, 0x10)
    clock.advance(0.1)
    assert bus.read_i2c_block_data(A, 0x40, 3) == [0, 0, 0]
    bus.write_byte_data(A, 0x58, 0x80)
    clock.advance(0.1)
    t = bus.read_i2c_block_data(A, 0x40, 3)
    assert t[0] | t[1] << 8 | t[2] << 16 == 4000


def test_timestamp_in_fifo_byte_order_section_7_8() -> None:
    clock, _, bus = make()
    bus.write_byte_data(A, 0x19, 0x24)
    bus.write_byte_data(A, 0x5C, 0x10)
    start_fifo(bus, ctrl2=0x80, ctrl4=1 << 3)  # TIMER_PEDO_FIFO_EN, DS4 every slot
    bus.write_byte_data(A, 0x42, 0xAA)
    clock.advance(200.5 / 104)  # 200 x 9 words fit the 2046-word FIFO
    data = burst_read(bus, A, 0x3E, 18 * 200)
    sets = np.frombuffer(data, np.uint8).reshape(200, 18)[:, 12:18]
    ts = (sets[:, 1].astype(int) << 16) | (sets[:, 0].astype(int) << 8) | sets[:, 3]
    assert np.allclose(np.diff(ts), 40000 / 104, atol=1)  # 384.6 ticks of 25 us


def test_self_test_deflection_section_3_5() -> None:
    clock, _sim, bus = make()
    bus.write_byte_data(A, 0x11, 0x5C)  # 208 Hz, 2000 dps
    bus.write_byte_data(A, 0x10, 0x38)  # 52 Hz, 4 g
    clock.advance(0.1)
    off = np.frombuffer(burst_read(bus, A, 0x22, 12), "<i2").astype(float)
    bus.write_byte_data(A, 0x14, 0x05)  # ST_G positive, ST_XL positive
    clock.advance(0.1)
    on = np.frombuffer(burst_read(bus, A, 0x22, 12), "<i2").astype(float)
    gyro_dps = (on - off)[:3] * 70e-3
    accel_g = (on - off)[3:] * 0.122e-3
    assert np.all((gyro_dps > 150) & (gyro_dps < 700))  # datasheet range at 2000 dps
    assert np.all((accel_g > 0.09) & (accel_g < 1.7))


def test_reserved_and_readonly_writes_section_3() -> None:
    _, sim, bus = make()
    bus.write_byte_data(A, 0x0F, 0x00)  # WHO_AM_I is read-only
    assert bus.read_byte_data(A, 0x0F) == 0x6A
    bus.write_byte_data(A, 0x11, 0x41)  # CTRL2_G bit 0 is reserved: reads back 0
    assert bus.read_byte_data(A, 0x11) == 0x40
    assert sim.sim_stats["reserved_writes"] == 1 and sim.sim_stats["readonly_writes"] == 1


def test_saturation_at_full_scale_section_4_2() -> None:
    class Spin:
        def generate(self, n: int, dt_s: float):
            from lsm6ds_sim.physics import TrueSamples

            return TrueSamples(np.full((n, 3), 400.0), np.zeros((n, 3)), np.full(n, 25.0))

    clock, _, bus = make(physics=Spin())
    bus.write_byte_data(A, 0x11, 0x40)  # 250 dps full scale
    clock.advance(0.05)
    assert list(np.frombuffer(burst_read(bus, A, 0x22, 6), "<i2")) == [32767] * 3


def test_crystal_error_changes_actual_odr() -> None:
    clock, _, bus = make(crystal_ppm=37500.0)  # 104 Hz nominal -> 107.9 Hz
    start_fifo(bus)
    clock.advance(10.0)
    assert level(bus)[0] // 6 == 341  # full FIFO after 3.16 s either way; check rate:
    _, sim, bus = make(crystal_ppm=37500.0)
    start_fifo(bus)
    sim.clock.advance(1.0)
    assert level(bus)[0] // 6 == 107  # floor(107.9)


def test_smbus_block_limit_and_nack() -> None:
    _clock, _, bus = make()
    with pytest.raises(ValueError):
        bus.read_i2c_block_data(A, 0x3E, 33)
    with pytest.raises(OSError) as err:
        bus.read_byte_data(0x6B, 0x0F)
    assert err.value.errno == errno.EREMOTEIO


def test_bus_timing_model_advances_clock() -> None:
    clock, _, bus = make(bus_hz=400e3)
    burst_read(bus, A, 0x3E, 100)
    # 1 register byte + 100 data bytes + 2 address bytes, 9 bits each, START/STOP/Sr
    expected = (9 * 103 + 2 + 1) / 400e3 + 1.3e-6
    assert clock.now() == pytest.approx(expected)


def test_nack_bursts_have_no_side_effect() -> None:
    clock = SimClock()
    sim = SimChip("lsm6dsl", clock)
    bus = SimI2CBus(clock, None, FaultPlan(nack_rate=0.5, seed=3))
    bus.attach(A, sim)
    ok = fails = 0
    for _ in range(200):
        try:
            bus.write_byte_data(A, 0x10, 0x40)
            ok += 1
        except OSError as exc:
            assert exc.errno == errno.EREMOTEIO
            fails += 1
    assert 60 < fails < 140 and ok + fails == 200
