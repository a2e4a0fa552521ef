"""Register maps of the LSM6DS3H, LSM6DSM and LSM6DSL as data.

One truth read by the driver (:mod:`lsm6ds.driver`) and by the simulator
(:mod:`lsm6ds_sim.chip`). Every entry cites the section of the shared reference
``lsm6ds-registers.md`` it comes from (section numbers in brackets, e.g. [§3.3]).

A :class:`ChipMap` holds, per chip: the registers (address, reset value, writable-bit
mask; reserved bits are not writable, [§3] "reserved, write 0"), the bit fields by name
(register, mask), the WHO_AM_I value [§1], the ODR codes [§4.1], full-scale codes and
sensitivities [§4.2], the temperature scale [§6], the FIFO depth and DIFF_FIFO width
[§9.1-9.2] and the timestamp tick [§7-8].
"""

from __future__ import annotations

from dataclasses import dataclass, field

CHIPS: tuple[str, ...] = ("lsm6ds3h", "lsm6dsm", "lsm6dsl")
"""Chip names accepted everywhere (lower case)."""

ADDRESSES: tuple[int, ...] = (0x6A, 0x6B)
"""7-bit I2C addresses: SA0 = 0 -> 0x6A, SA0 = 1 -> 0x6B [§1]."""

ODR_HZ: dict[int, float] = {
    0: 0.0,
    1: 12.5,
    2: 26.0,
    3: 52.0,
    4: 104.0,
    5: 208.0,
    6: 416.0,
    7: 833.0,
    8: 1660.0,
    9: 3330.0,
    10: 6660.0,
    11: 1.6,
}
"""ODR code -> nominal output data rate, Hz, for CTRL1_XL, CTRL2_G and FIFO_CTRL5 [§4.1].
Code 11 (1.6 Hz) exists only for the accelerometer of the LSM6DSL/DSM in low power."""

ACCEL_FS: dict[int, tuple[float, float]] = {
    0b00: (2.0, 0.061e-3),
    0b01: (16.0, 0.488e-3),
    0b10: (4.0, 0.122e-3),
    0b11: (8.0, 0.244e-3),
}
"""FS_XL code -> (full scale in g, sensitivity in g/LSB) [§4.2]; note 01 = 16 g."""

GYRO_FS: dict[int, tuple[float, float]] = {
    0b000: (250.0, 8.75e-3),
    0b001: (125.0, 4.375e-3),
    0b010: (500.0, 17.5e-3),
    0b100: (1000.0, 35.0e-3),
    0b110: (2000.0, 70.0e-3),
}
"""CTRL2_G bits 3:1 (FS_G[1:0], FS_125) as one code -> (full scale dps, dps/LSB) [§3.2, §4.2]."""

FIFO_MODES: dict[str, int] = {
    "bypass": 0b000,
    "fifo": 0b001,
    "continuous_to_fifo": 0b011,
    "bypass_to_continuous": 0b100,
    "continuous": 0b110,
}
"""FIFO_CTRL5[2:0] FIFO_MODE codes [§9.3]."""

DECIMATION: dict[int, int] = {0: 0, 1: 1, 2: 2, 3: 3, 4: 4, 5: 8, 6: 16, 7: 32}
"""FIFO decimation code -> factor (0 = data set not in FIFO) [§9.4]."""

TIMESTAMP_TICK_S: dict[bool, float] = {True: 25e-6, False: 6.4e-3}
"""WAKE_UP_DUR.TIMER_HR -> timestamp tick, s [§7-8]."""

TIMESTAMP_RESET_VALUE = 0xAA
"""Writing this to TIMESTAMP2_REG resets the 24-bit counter [§7-8]."""

FIFO_DEPTH_WORDS = 2046
"""FIFO depth: 682 six-byte data sets = 4092 bytes = 2046 16-bit words [§9.2] (Linux
``max_fifo_size``)."""

SW_RESET_WAIT_S = 0.050
BOOT_WAIT_S = 0.050
"""Waits after SW_RESET and BOOT as Linux st_lsm6dsx uses them [§1]."""

BOOT_TIME_S = 0.015
"""Power-on boot time before the first access [§1]."""


@dataclass(frozen=True)
class Register:
    """One register: name, address, reset value, writable-bit mask (0 = read-only)."""

    name: str
    address: int
    reset: int = 0x00
    writable: int = 0xFF


@dataclass(frozen=True)
class Field:
    """A bit field: register name and mask (the shift follows from the mask)."""

    register: str
    mask: int

    @property
    def shift(self) -> int:
        return (self.mask & -self.mask).bit_length() - 1


@dataclass(frozen=True)
class ChipMap:
    """Register map and scales of one chip."""

    name: str
    who_am_i: int
    registers: dict[str, Register]
    fields: dict[str, Field]
    temp_lsb_per_c: float
    temp_zero_c: float
    fifo_diff_bits: int
    gyro_odr_codes: tuple[int, ...]
    accel_odr_codes: tuple[int, ...]
    fifo_odr_codes: tuple[int, ...] = tuple(range(0, 11))
    by_address: dict[int, Register] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.by_address.update({r.address: r for r in self.registers.values()})

    def addr(self, name: str) -> int:
        """Address of register ``name``; KeyError names the chip."""
        try:
            return self.registers[name].address
        except KeyError:
            raise KeyError(f"{self.name} has no register {name!r}") from None

    def field(self, name: str) -> Field:
        try:
            return self.fields[name]
        except KeyError:
            raise KeyError(f"{self.name} has no register field {name!r}") from None

    def field_addr_mask(self, name: str) -> tuple[int, int]:
        f = self.field(name)
        return self.addr(f.register), f.mask

    @property
    def reset_values(self) -> dict[int, int]:
        """Address -> reset value for every defined register [§3.13]; WHO_AM_I holds the
        chip's identity [§1]."""
        values = {r.address: r.reset for r in self.registers.values()}
        values[self.addr("WHO_AM_I")] = self.who_am_i
        return values

    def odr_code(self, odr_hz: float, sensor: str) -> int:
        """ODR code for ``odr_hz`` (exact table value) of sensor ``gyro``/``accel``/``fifo``."""
        codes = {
            "gyro": self.gyro_odr_codes,
            "accel": self.accel_odr_codes,
            "fifo": self.fifo_odr_codes,
        }[sensor]
        for code in codes:
            if abs(ODR_HZ[code] - odr_hz) < 1e-6 * max(1.0, odr_hz):
                return code
        allowed = ", ".join(f"{ODR_HZ[c]:g}" for c in codes if c)
        raise ValueError(
            f"{self.name}: {sensor} ODR {odr_hz:g} Hz is not available; "
            f"choose one of {allowed} Hz (reference §4.1)"
        )


def gyro_fs_code(fs_dps: float) -> int:
    """CTRL2_G bits 3:1 code for full scale ``fs_dps`` (245 accepted for DS3H's 250)."""
    if fs_dps == 245:
        fs_dps = 250.0
    for code, (fs, _) in GYRO_FS.items():
        if fs == fs_dps:
            return code
    raise ValueError(
        f"gyro full scale {fs_dps:g} dps is not one of "
        f"{', '.join(f'{v[0]:g}' for v in GYRO_FS.values())} (reference §4.2)"
    )


def accel_fs_code(fs_g: float) -> int:
    for code, (fs, _) in ACCEL_FS.items():
        if fs == fs_g:
            return code
    raise ValueError(
        f"accelerometer full scale {fs_g:g} g is not one of 2, 4, 8, 16 (reference §4.2)"
    )


# -- register tables --------------------------------------------------------------------

_RO = 0x00  # writable mask of a read-only register

_COMMON: list[Register] = [
    Register("FUNC_CFG_ACCESS", 0x01),
    Register("SENSOR_SYNC_TIME_FRAME", 0x04, writable=0x0F),
    Register("FIFO_CTRL1", 0x06),
    Register("FIFO_CTRL3", 0x08, writable=0x3F),
    Register("FIFO_CTRL5", 0x0A, writable=0x7F),
    Register("INT1_CTRL", 0x0D),
    Register("INT2_CTRL", 0x0E),
    Register("WHO_AM_I", 0x0F, writable=_RO),
    Register("CTRL1_XL", 0x10),
    Register("CTRL2_G", 0x11, writable=0xFE),
    Register("CTRL3_C", 0x12, reset=0x04),
    Register("CTRL5_C", 0x14),
    Register("CTRL7_G", 0x16),
    Register("CTRL8_XL", 0x17, writable=0xFD),
    Register("MASTER_CONFIG", 0x1A, writable=0xDF),
    Register("WAKE_UP_SRC", 0x1B, writable=_RO),
    Register("TAP_SRC", 0x1C, writable=_RO),
    Register("D6D_SRC", 0x1D, writable=_RO),
    Register("STATUS_REG", 0x1E, writable=_RO),
    *[
        Register(n, a, writable=_RO)
        for n, a in [
            ("OUT_TEMP_L", 0x20),
            ("OUT_TEMP_H", 0x21),
            ("OUTX_L_G", 0x22),
            ("OUTX_H_G", 0x23),
            ("OUTY_L_G", 0x24),
            ("OUTY_H_G", 0x25),
            ("OUTZ_L_G", 0x26),
            ("OUTZ_H_G", 0x27),
            ("OUTX_L_XL", 0x28),
            ("OUTX_H_XL", 0x29),
            ("OUTY_L_XL", 0x2A),
            ("OUTY_H_XL", 0x2B),
            ("OUTZ_L_XL", 0x2C),
            ("OUTZ_H_XL", 0x2D),
            ("FIFO_STATUS1", 0x3A),
            ("FIFO_STATUS2", 0x3B),
            ("FIFO_STATUS3", 0x3C),
            ("FIFO_STATUS4", 0x3D),
            ("FIFO_DATA_OUT_L", 0x3E),
            ("FIFO_DATA_OUT_H", 0x3F),
            ("TIMESTAMP0_REG", 0x40),
            ("TIMESTAMP1_REG", 0x41),
            ("STEP_TIMESTAMP_L", 0x49),
            ("STEP_TIMESTAMP_H", 0x4A),
            ("STEP_COUNTER_L", 0x4B),
            ("STEP_COUNTER_H", 0x4C),
        ]
    ],
    *[Register(f"SENSORHUB{i + 1}_REG", 0x2E + i, writable=_RO) for i in range(12)],
    *[Register(f"SENSORHUB{i + 13}_REG", 0x4D + i, writable=_RO) for i in range(6)],
    # TIMESTAMP2_REG is read-only except for the 0xAA reset command [§7-8]; the chip
    # model handles that write specially.
    Register("TIMESTAMP2_REG", 0x42, writable=_RO),
    Register("TAP_CFG", 0x58),
    Register("TAP_THS_6D", 0x59),
    Register("INT_DUR2", 0x5A),
    Register("WAKE_UP_THS", 0x5B),
    Register("WAKE_UP_DUR", 0x5C),
    Register("FREE_FALL", 0x5D),
    Register("MD1_CFG", 0x5E),
    Register("MD2_CFG", 0x5F),
    *[
        Register(n, a, writable=_RO)
        for n, a in [
            ("OUT_MAG_RAW_X_L", 0x66),
            ("OUT_MAG_RAW_X_H", 0x67),
            ("OUT_MAG_RAW_Y_L", 0x68),
            ("OUT_MAG_RAW_Y_H", 0x69),
            ("OUT_MAG_RAW_Z_L", 0x6A),
            ("OUT_MAG_RAW_Z_H", 0x6B),
        ]
    ],
]

_DSL_FAMILY: list[Register] = [
    Register("SENSOR_SYNC_RES_RATIO", 0x05, writable=0x03),
    Register("FIFO_CTRL2", 0x07, writable=0xCF),  # b5:4 reserved [§9.1]
    Register("FIFO_CTRL4", 0x09),
    Register("CTRL4_C", 0x13, writable=0xFE),  # b0 reserved [§3.4]
    Register("CTRL6_C", 0x15, writable=0xFB),  # b2 reserved [§3.6]
    Register("CTRL9_XL", 0x18, reset=0xE0, writable=0xF4),  # [§3.9, §3.13]
    Register("CTRL10_C", 0x19, writable=0xBF),  # b6 reserved [§3.10]
    Register("FUNC_SRC1", 0x53, writable=_RO),
    Register("FUNC_SRC2", 0x54, writable=_RO),
    Register("WRIST_TILT_IA", 0x55, writable=_RO),
    Register("X_OFS_USR", 0x73),
    Register("Y_OFS_USR", 0x74),
    Register("Z_OFS_USR", 0x75),
]

_DS3H_ONLY: list[Register] = [
    Register("FIFO_CTRL2", 0x07, writable=0xCF),  # b3:0 FTH[11:8] [§9.1]
    Register("FIFO_CTRL4", 0x09, writable=0x7F),  # b7 reserved [§9.1]
    Register("ORIENT_CFG_G", 0x0B, writable=0x3F),
    Register("CTRL4_C", 0x13),
    Register("CTRL6_C", 0x15, writable=0xF0),  # b3:0 reserved [§3.6]
    Register("CTRL9_XL", 0x18, reset=0x38, writable=0x3C),  # [§3.9, §3.13]
    Register("CTRL10_C", 0x19, reset=0x38, writable=0x3F),  # [§3.10, §3.13]
    Register("FUNC_SRC", 0x53, writable=_RO),
    Register("CTRL_SPIAux", 0x70),
]

_COMMON_FIELDS: dict[str, Field] = {
    "ODR_XL": Field("CTRL1_XL", 0xF0),
    "FS_XL": Field("CTRL1_XL", 0x0C),
    "ODR_G": Field("CTRL2_G", 0xF0),
    "FS_G": Field("CTRL2_G", 0x0E),  # FS_G[1:0] + FS_125
    "BOOT": Field("CTRL3_C", 0x80),
    "BDU": Field("CTRL3_C", 0x40),
    "IF_INC": Field("CTRL3_C", 0x04),
    "BLE": Field("CTRL3_C", 0x02),
    "SW_RESET": Field("CTRL3_C", 0x01),
    "ROUNDING": Field("CTRL5_C", 0xE0),
    "ST_G": Field("CTRL5_C", 0x0C),
    "ST_XL": Field("CTRL5_C", 0x03),
    "XL_HM_MODE": Field("CTRL6_C", 0x10),
    "G_HM_MODE": Field("CTRL7_G", 0x80),
    "FUNC_EN": Field("CTRL10_C", 0x04),
    "XLDA": Field("STATUS_REG", 0x01),
    "GDA": Field("STATUS_REG", 0x02),
    "TDA": Field("STATUS_REG", 0x04),
    "FTH_L": Field("FIFO_CTRL1", 0xFF),
    "TIMER_PEDO_FIFO_EN": Field("FIFO_CTRL2", 0x80),
    "TIMER_PEDO_FIFO_DRDY": Field("FIFO_CTRL2", 0x40),
    "DEC_FIFO_GYRO": Field("FIFO_CTRL3", 0x38),
    "DEC_FIFO_XL": Field("FIFO_CTRL3", 0x07),
    "ONLY_HIGH_DATA": Field("FIFO_CTRL4", 0x40),
    "DEC_DS4_FIFO": Field("FIFO_CTRL4", 0x38),
    "DEC_DS3_FIFO": Field("FIFO_CTRL4", 0x07),
    "ODR_FIFO": Field("FIFO_CTRL5", 0x78),
    "FIFO_MODE": Field("FIFO_CTRL5", 0x07),
    "WATERM": Field("FIFO_STATUS2", 0x80),
    "OVER_RUN": Field("FIFO_STATUS2", 0x40),
    "FIFO_FULL": Field("FIFO_STATUS2", 0x20),
    "FIFO_EMPTY": Field("FIFO_STATUS2", 0x10),
    "TIMER_HR": Field("WAKE_UP_DUR", 0x10),
    "INT1_FTH": Field("INT1_CTRL", 0x08),
}

_DSL_FIELDS: dict[str, Field] = {
    "TIMER_EN": Field("CTRL10_C", 0x20),
    "FIFO_TEMP_EN": Field("FIFO_CTRL2", 0x08),
    "FTH_H": Field("FIFO_CTRL2", 0x07),
    "STOP_ON_FTH": Field("FIFO_CTRL4", 0x80),
    "DIFF_FIFO_H": Field("FIFO_STATUS2", 0x07),
    "LPF1_SEL_G": Field("CTRL4_C", 0x02),
    "FTYPE": Field("CTRL6_C", 0x03),
}

_DS3H_FIELDS: dict[str, Field] = {
    "TIMER_EN": Field("TAP_CFG", 0x80),
    "FIFO_TEMP_EN": Field("CTRL4_C", 0x10),
    "FTH_H": Field("FIFO_CTRL2", 0x0F),
    "STOP_ON_FTH": Field("CTRL4_C", 0x01),
    "DIFF_FIFO_H": Field("FIFO_STATUS2", 0x0F),
    "XL_BW_SCAL_ODR": Field("CTRL4_C", 0x80),
    "XEN_G": Field("CTRL10_C", 0x08),
    "YEN_G": Field("CTRL10_C", 0x10),
    "ZEN_G": Field("CTRL10_C", 0x20),
    "XEN_XL": Field("CTRL9_XL", 0x08),
    "YEN_XL": Field("CTRL9_XL", 0x10),
    "ZEN_XL": Field("CTRL9_XL", 0x20),
}


def _regs(*groups: list[Register]) -> dict[str, Register]:
    out: dict[str, Register] = {}
    for group in groups:
        for reg in group:
            out[reg.name] = reg
    return dict(sorted(out.items(), key=lambda kv: kv[1].address))


LSM6DSL = ChipMap(
    name="lsm6dsl",
    who_am_i=0x6A,
    registers=_regs(_COMMON, _DSL_FAMILY, [Register("DRDY_PULSE_CFG_G", 0x0B, writable=0x81)]),
    fields={**_COMMON_FIELDS, **_DSL_FIELDS},
    temp_lsb_per_c=256.0,
    temp_zero_c=25.0,
    fifo_diff_bits=11,
    gyro_odr_codes=tuple(range(0, 11)),
    accel_odr_codes=tuple(range(0, 12)),
)
LSM6DSM = ChipMap(
    name="lsm6dsm",
    who_am_i=0x6A,
    registers=_regs(
        _COMMON,
        _DSL_FAMILY,
        [
            Register("DRDY_PULSE_CFG", 0x0B, writable=0x81),
            Register("INT_OIS", 0x6F),
            Register("CTRL1_OIS", 0x70),
            Register("CTRL2_OIS", 0x71),
            Register("CTRL3_OIS", 0x72),
        ],
    ),
    fields={**_COMMON_FIELDS, **_DSL_FIELDS},
    temp_lsb_per_c=256.0,
    temp_zero_c=25.0,
    fifo_diff_bits=11,
    gyro_odr_codes=tuple(range(0, 11)),
    accel_odr_codes=tuple(range(0, 12)),
)
LSM6DS3H = ChipMap(
    name="lsm6ds3h",
    who_am_i=0x69,
    registers=_regs(_COMMON, _DS3H_ONLY),
    fields={**_COMMON_FIELDS, **_DS3H_FIELDS},
    temp_lsb_per_c=16.0,
    temp_zero_c=25.0,
    fifo_diff_bits=12,
    gyro_odr_codes=tuple(range(0, 9)),
    accel_odr_codes=tuple(range(0, 11)),
)

CHIP_MAPS: dict[str, ChipMap] = {"lsm6dsl": LSM6DSL, "lsm6dsm": LSM6DSM, "lsm6ds3h": LSM6DS3H}


def chip_map(name: str) -> ChipMap:
    """The :class:`ChipMap` of ``name`` (case-insensitive); ValueError lists the chips."""
    try:
        return CHIP_MAPS[name.lower()]
    except KeyError:
        raise ValueError(f"unknown chip {name!r}; choose one of {', '.join(CHIPS)}") from None


# Self-test limits (absolute change of output when the self-test is on), datasheet tables
# "mechanical characteristics" of LSM6DSL/DSM/DS3H (✱ not in the fetched sources: the
# reference §3.5 gives only the CTRL5_C encoding). Accel in g at any FS, gyro in dps at
# 250 dps (2000 dps limits are 150..700 dps).
SELF_TEST_ACCEL_G: tuple[float, float] = (0.090, 1.700)
SELF_TEST_GYRO_DPS: dict[float, tuple[float, float]] = {
    125.0: (20.0, 80.0),
    250.0: (20.0, 80.0),
    500.0: (40.0, 160.0),
    1000.0: (75.0, 300.0),
    2000.0: (150.0, 700.0),
}
