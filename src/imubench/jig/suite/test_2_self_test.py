"""Gyro and accelerometer self-test against the datasheet limits (the driver's
datasheet procedure: accel 52 Hz / 4 g, gyro 208 Hz / 2000 dps, |on - off|)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest
from lsm6ds.registers import ACCEL_FS, GYRO_FS, accel_fs_code, gyro_fs_code

from imubench.jig import analysis

if TYPE_CHECKING:
    from imubench.jig.dut import Dut
    from imubench.jig.plugin import Measure
    from imubench.jig.session import JigSession


SELF_TEST_SAMPLES = 5
"""Samples averaged per state by ``LSM6DS.self_test`` (its default ``n_average``)."""
SELF_TEST_ODR = {"gyro": 208.0, "accel": 52.0}
SELF_TEST_LSB = {"gyro": GYRO_FS[gyro_fs_code(2000.0)][1], "accel": ACCEL_FS[accel_fs_code(4.0)][1]}
TYP_DENSITY = {"gyro": ("noise_density.gx", 1e-3), "accel": ("noise_density.ax", 1e-6)}
"""Typical noise density (limits file, reported units) and its scale to dps or g."""


def test_self_test(dut: Dut, jig: JigSession, measure: Measure) -> None:
    if dut.registers is None:
        pytest.skip(f"{dut.uri}: no register access on this source")
    result = dut.self_test()
    for ax in result.axes:
        name, scale = TYP_DENSITY[ax.sensor]
        v = analysis.self_test_value(ax.deflection, jig.typ(name) * scale,
                                     SELF_TEST_ODR[ax.sensor], SELF_TEST_LSB[ax.sensor],
                                     SELF_TEST_SAMPLES, jig.confidence)
        measure(f"self_test.{ax.sensor}_{ax.axis.lower()}", v.value, v.ci, method=v.method)
