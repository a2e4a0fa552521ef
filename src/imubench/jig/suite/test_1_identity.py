"""Identity: WHO_AM_I (register 0x0F) against the chip's value."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from imubench.jig.dut import Dut
    from imubench.jig.plugin import Measure



def test_who_am_i(dut: Dut, measure: Measure) -> None:
    if dut.registers is None:
        pytest.skip(f"{dut.uri}: no register access on this source")
    who = dut.read_who_am_i()
    measure("identity.who_am_i", who, (who, who), method="register WHO_AM_I (0x0F) read")
