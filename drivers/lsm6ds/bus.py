"""The I2C bus protocol the drivers use: the subset of :class:`smbus2.SMBus` they call.

A real ``smbus2.SMBus`` and the simulated bus (:class:`lsm6ds_sim.i2c.SimI2CBus`) both
satisfy it; drivers never know which they have. smbus2 block reads are limited to 32
bytes (``I2C_SMBUS_BLOCK_MAX``), so long FIFO reads go through :meth:`I2CBus.i2c_rdwr`
with a write message holding the register address followed by a read message
(reference §5).
"""

from __future__ import annotations

from collections.abc import Sequence
from ctypes import string_at
from typing import Protocol, runtime_checkable

from smbus2 import i2c_msg

SMBUS_BLOCK_MAX = 32
"""Longest ``read_i2c_block_data`` / ``write_i2c_block_data`` smbus2 allows, bytes."""

I2C_M_RD = 0x0001
"""``i2c_msg.flags`` bit of a read message (linux/i2c.h)."""


@runtime_checkable
class I2CBus(Protocol):
    """What a driver may call on a bus (signatures of smbus2 0.4/0.5)."""

    def read_byte_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int: ...

    def write_byte_data(
        self, i2c_addr: int, register: int, value: int, force: bool | None = None
    ) -> None: ...

    def read_i2c_block_data(
        self, i2c_addr: int, register: int, length: int, force: bool | None = None
    ) -> list[int]: ...

    def write_i2c_block_data(
        self, i2c_addr: int, register: int, data: Sequence[int], force: bool | None = None
    ) -> None: ...

    def i2c_rdwr(self, *i2c_msgs: i2c_msg) -> None: ...


def msg_bytes(msg: i2c_msg) -> bytes:
    """The bytes of an ``i2c_msg`` buffer without a per-byte Python loop."""
    return string_at(msg.buf, msg.len)


def burst_read(bus: I2CBus, addr: int, register: int, length: int) -> bytes:
    """Read ``length`` bytes from ``register`` in one combined write+read transaction."""
    write = i2c_msg.write(addr, [register])
    read = i2c_msg.read(addr, length)
    bus.i2c_rdwr(write, read)
    return msg_bytes(read)
