"""Register maps as data (reference lsm6ds-registers.md, sections cited per test)."""

from __future__ import annotations

import pytest
from lsm6ds.registers import (
    ACCEL_FS,
    CHIP_MAPS,
    GYRO_FS,
    ODR_HZ,
    accel_fs_code,
    chip_map,
    gyro_fs_code,
)


def test_who_am_i_per_chip_section_1() -> None:
    assert chip_map("lsm6ds3h").who_am_i == 0x69
    assert chip_map("lsm6dsm").who_am_i == 0x6A
    assert chip_map("LSM6DSL").who_am_i == 0x6A


def test_common_addresses_section_2() -> None:
    for m in CHIP_MAPS.values():
        assert m.addr("WHO_AM_I") == 0x0F
        assert m.addr("CTRL1_XL") == 0x10 and m.addr("CTRL10_C") == 0x19
        assert m.addr("STATUS_REG") == 0x1E and m.addr("OUT_TEMP_L") == 0x20
        assert m.addr("OUTX_L_G") == 0x22 and m.addr("OUTX_L_XL") == 0x28
        assert m.addr("FIFO_STATUS1") == 0x3A and m.addr("FIFO_DATA_OUT_L") == 0x3E
        assert m.addr("TIMESTAMP2_REG") == 0x42 and m.addr("WAKE_UP_DUR") == 0x5C


def test_reset_values_section_3_13() -> None:
    for name in ("lsm6dsl", "lsm6dsm"):
        r = chip_map(name).reset_values
        assert r[0x12] == 0x04 and r[0x18] == 0xE0 and r[0x19] == 0x00
    r = chip_map("lsm6ds3h").reset_values
    assert r[0x12] == 0x04 and r[0x18] == 0x38 and r[0x19] == 0x38
    assert r[0x10] == 0 and r[0x11] == 0 and r[0x0A] == 0


def test_full_scale_tables_section_4_2() -> None:
    assert ACCEL_FS[accel_fs_code(16)] == (16.0, 0.488e-3)  # non-monotonic code 01
    assert accel_fs_code(16) == 0b01 and accel_fs_code(4) == 0b10
    assert GYRO_FS[gyro_fs_code(125)] == (125.0, 4.375e-3)
    assert gyro_fs_code(2000) == 0b110 and gyro_fs_code(245) == gyro_fs_code(250)
    with pytest.raises(ValueError, match="3 g"):
        accel_fs_code(3)


def test_odr_codes_and_chip_limits_section_4_1() -> None:
    assert ODR_HZ[4] == 104.0 and ODR_HZ[9] == 3330.0 and ODR_HZ[11] == 1.6
    assert chip_map("lsm6dsl").odr_code(6660, "gyro") == 10
    with pytest.raises(ValueError, match="gyro ODR 3330"):
        chip_map("lsm6ds3h").odr_code(3330, "gyro")  # DS3H gyro max 1.66 kHz
    assert chip_map("lsm6dsm").odr_code(1.6, "accel") == 11
    with pytest.raises(ValueError):
        chip_map("lsm6ds3h").odr_code(1.6, "accel")


def test_chip_differences_section_10() -> None:
    dsl, ds3h = chip_map("lsm6dsl"), chip_map("lsm6ds3h")
    assert dsl.field_addr_mask("TIMER_EN") == (0x19, 0x20)
    assert ds3h.field_addr_mask("TIMER_EN") == (0x58, 0x80)
    assert dsl.field_addr_mask("STOP_ON_FTH") == (0x09, 0x80)
    assert ds3h.field_addr_mask("STOP_ON_FTH") == (0x13, 0x01)
    assert dsl.field_addr_mask("FIFO_TEMP_EN") == (0x07, 0x08)
    assert ds3h.field_addr_mask("FIFO_TEMP_EN") == (0x13, 0x10)
    assert (dsl.fifo_diff_bits, ds3h.fifo_diff_bits) == (11, 12)
    assert (dsl.temp_lsb_per_c, ds3h.temp_lsb_per_c) == (256.0, 16.0)
    assert "DRDY_PULSE_CFG_G" in dsl.registers and "ORIENT_CFG_G" in ds3h.registers
    assert "CTRL1_OIS" in chip_map("lsm6dsm").registers and "CTRL1_OIS" not in dsl.registers
    assert "X_OFS_USR" in dsl.registers and "X_OFS_USR" not in ds3h.registers


def test_unknown_chip_names_choices() -> None:
    with pytest.raises(ValueError, match="lsm6ds3h, lsm6dsm, lsm6dsl"):
        chip_map("lsm9ds1")
