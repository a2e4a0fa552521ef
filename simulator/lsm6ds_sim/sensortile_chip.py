"""What the simulated SensorTile firmware reads its IMU through.

The firmware only needs :class:`ChipPort` — "give me the current output registers as the
BSP converts them" — so it runs against:

* :class:`I2cChipPort`: a simulated LSM6DSM (:class:`lsm6ds_sim.chip.SimChip`, or
  anything on a bus that satisfies :class:`lsm6ds.bus.I2CBus`) read like the ST BSP
  does: STATUS_REG (0x1E) for data-ready, then a 14-byte burst from OUT_TEMP_L (0x20):
  temp, gyro, accel int16 LE.
  :func:`simulated_lsm6dsm` builds that chip (``lsm6ds_sim.chip.SimChip`` with
  ``lsm6ds_sim.physics.SensorPhysics``).

Counts become mg / mdps as the ST BSP does it (``LSM6DSM_ACC_GetAxes``):
``(int32_t)((float)raw * sensitivity)``, float32 arithmetic truncated toward zero, with
sensitivities 0.061 mg/LSB (±2 g) and 8.75 mdps/LSB (±245/250 dps) [§4.2].
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np
from lsm6ds.bus import I2CBus
from lsm6ds.registers import ACCEL_FS, GYRO_FS, accel_fs_code, chip_map, gyro_fs_code

if TYPE_CHECKING:
    from lsm6ds_sim.clock import SimClock
    from lsm6ds_sim.model import NoiseModel

Triple = tuple[int, int, int]

_MAP = chip_map("lsm6dsm")
LSM6DSM_ADDR = 0x6A

ACCEL_SENS_MG = ACCEL_FS[accel_fs_code(2.0)][1] * 1e3
"""mg/LSB at ±2 g (0.061; BSP ``LSM6DSM_ACC_SENSITIVITY_FS_2G``)."""
GYRO_SENS_MDPS = GYRO_FS[gyro_fs_code(250.0)][1] * 1e3
"""mdps/LSB at ±245/250 dps (8.75; BSP ``LSM6DSM_GYRO_SENSITIVITY_FS_245DPS``)."""


def bsp_scale(counts: np.ndarray | list[int], sensitivity: float) -> Triple:
    """``(int32_t)((float)raw * sensitivity)`` for three axes (float32, toward zero)."""
    vals = np.asarray(counts, dtype=np.float32) * np.float32(sensitivity)
    t = np.trunc(vals).astype(np.int64)
    return (int(t[0]), int(t[1]), int(t[2]))


@dataclass(frozen=True)
class ChipOutputs:
    """One reading of the chip by the firmware."""

    gyro_mdps: Triple
    accel_mg: Triple
    temp_c: float
    gyro_new: bool = True
    accel_new: bool = True


@runtime_checkable
class ChipPort(Protocol):
    """The tiny interface the firmware needs: the current outputs (at the clock's now)."""

    def read_outputs(self) -> ChipOutputs: ...


class I2cChipPort:
    """A chip on an I2C bus read like the SensorTile BSP: STATUS_REG then a 14-byte burst.

    ``configure()`` writes CTRL3_C = BDU | IF_INC (0x44), CTRL1_XL = 104 Hz ±2 g (0x40)
    and CTRL2_G = 104 Hz 250 dps (0x40), the DataLogExtended defaults.
    """

    def __init__(self, bus: I2CBus, addr: int = LSM6DSM_ADDR) -> None:
        self.bus = bus
        self.addr = addr

    def configure(self, odr_code: int = 4) -> None:
        bus = self.bus
        bus.write_byte_data(self.addr, _MAP.addr("CTRL3_C"), 0x44)  # BDU | IF_INC
        bus.write_byte_data(self.addr, _MAP.addr("CTRL1_XL"), (odr_code << 4) | 0x00)
        bus.write_byte_data(self.addr, _MAP.addr("CTRL2_G"), (odr_code << 4) | 0x00)

    def read_outputs(self) -> ChipOutputs:
        status = self.bus.read_byte_data(self.addr, _MAP.addr("STATUS_REG"))
        raw = bytes(self.bus.read_i2c_block_data(self.addr, _MAP.addr("OUT_TEMP_L"), 14))
        words = np.frombuffer(raw, dtype="<i2").astype(np.int64)
        return ChipOutputs(
            gyro_mdps=bsp_scale(words[1:4], GYRO_SENS_MDPS),
            accel_mg=bsp_scale(words[4:7], ACCEL_SENS_MG),
            temp_c=float(words[0]) / _MAP.temp_lsb_per_c + _MAP.temp_zero_c,
            gyro_new=bool(status & 0x02),
            accel_new=bool(status & 0x01),
        )


def datasheet_model() -> NoiseModel:
    """White noise at LSM6DSM datasheet-typical densities (§11, unverified): gyro
    3.8 mdps/sqrt(Hz), accel 90 ug/sqrt(Hz); the default when no model file is given."""
    from lsm6ds_sim.model import NoiseModel

    model = NoiseModel.quiet()
    for ch in ("gx", "gy", "gz"):
        model = model.with_channel(ch, white=3.8e-3)
    for ch in ("ax", "ay", "az"):
        model = model.with_channel(ch, white=90e-6)
    return model


def simulated_lsm6dsm(
    clock: SimClock,
    seed: int = 0,
    model: NoiseModel | None = None,
    odr_code: int = 4,
    crystal_ppm: float = 0.0,
    bus_hz: float | None = 400_000.0,
) -> I2cChipPort:
    """:class:`lsm6ds_sim.chip.SimChip` (LSM6DSM) with :class:`SensorPhysics` on
    the simulated I2C bus (:class:`lsm6ds_sim.i2c.SimI2CBus`, ``bus_hz`` timing model),
    configured like the DataLogExtended firmware (``odr_code`` 4 = 104 Hz, +-2 g, 250 dps,
    BDU + IF_INC)."""
    from lsm6ds_sim.chip import SimChip
    from lsm6ds_sim.i2c import SimI2CBus
    from lsm6ds_sim.physics import SensorPhysics

    physics = SensorPhysics(model if model is not None else datasheet_model(), seed=seed)
    chip = SimChip("lsm6dsm", clock, physics, crystal_ppm=crystal_ppm, seed=seed)
    bus = SimI2CBus(clock, bus_hz=bus_hz)
    bus.attach(LSM6DSM_ADDR, chip)
    port = I2cChipPort(bus, LSM6DSM_ADDR)
    port.configure(odr_code)
    return port
