"""A simulated I2C bus with devices attached by 7-bit address.

:class:`SimI2CBus` satisfies :class:`lsm6ds.bus.I2CBus` (the smbus2 subset the drivers
use), so a driver runs unchanged on it. A device is anything with
``read(register, length) -> bytes`` and ``write(register, data: bytes)``
(:class:`lsm6ds_sim.chip.SimChip`). Semantics follow smbus2 on Linux:

- an absent address or an injected NACK raises ``OSError(errno.EREMOTEIO)``;
- ``read_i2c_block_data``/``write_i2c_block_data`` refuse more than 32 bytes like smbus2;
- ``i2c_rdwr`` accepts a write message holding the register address followed by a
  read message (a combined transaction with a repeated START), or a single write message
  (register + data).

With ``bus_hz`` set, every transaction advances the :class:`~lsm6ds_sim.clock.SimClock`
by its duration (:mod:`lsm6ds_sim.timing`), after the device served it: the bus is busy,
the chip keeps sampling. Counters in :attr:`SimI2CBus.stats`.
"""

from __future__ import annotations

import ctypes
import errno
from collections.abc import Sequence
from typing import Protocol

from lsm6ds.bus import I2C_M_RD, SMBUS_BLOCK_MAX, msg_bytes
from smbus2 import i2c_msg

from lsm6ds_sim.clock import SimClock
from lsm6ds_sim.faults import FaultInjector, FaultPlan
from lsm6ds_sim.timing import I2CTiming


class I2CDevice(Protocol):
    def read(self, register: int, length: int) -> bytes: ...

    def write(self, register: int, data: bytes) -> None: ...


class SimI2CBus:
    """Simulated I2C adapter.

    Args:
        clock: shared simulated clock.
        bus_hz: SCL frequency for the timing model; 0 or None = no timing model.
        faults: fault plan (NACK bursts, stuck bus, chip resets, forced overrun, reader
            stalls, ...).
        stall_register: the register whose read is followed by the plan's reader stalls
            (the chip's FIFO_STATUS1; None: no stalls).
    """

    def __init__(
        self,
        clock: SimClock | None = None,
        bus_hz: float | None = None,
        faults: FaultPlan | None = None,
        *,
        stall_register: int | None = None,
    ) -> None:
        self.stall_register = stall_register
        self.clock = clock if clock is not None else SimClock()
        self.timing = I2CTiming(bus_hz) if bus_hz else None
        self.faults = FaultInjector(faults) if faults is not None and faults.active else None
        self.devices: dict[int, I2CDevice] = {}
        self.stats: dict[str, float] = {
            "transactions": 0,
            "wire_bytes": 0,
            "busy_s": 0.0,
            "errors": 0,
        }
        self.closed = False

    def attach(self, addr: int, device: I2CDevice) -> None:
        if not 0x08 <= addr <= 0x77:
            raise ValueError(f"I2C address 0x{addr:02x} is outside 0x08-0x77")
        self.devices[addr] = device

    # -- transaction core --------------------------------------------------------
    def _begin(self, addr: int) -> I2CDevice:
        if self.closed:
            raise OSError(errno.EBADF, "simulated I2C bus is closed")
        now = self.clock.now()
        device = self.devices.get(addr)
        if self.faults is not None:
            if device is not None and hasattr(device, "sim_advance_to"):
                self.faults.apply_chip_faults(device, now)  # type: ignore[arg-type]
            try:
                self.faults.before_transaction(now)
            except OSError:
                self.stats["errors"] += 1
                self._end(1, 1)  # the address byte went out and was not acknowledged
                raise
        if device is None:
            self.stats["errors"] += 1
            self._end(1, 1)
            raise OSError(errno.EREMOTEIO, f"Remote I/O error (no device at 0x{addr:02x})")
        return device

    def _end(self, n_bytes: int, n_messages: int) -> None:
        self.stats["transactions"] += 1
        self.stats["wire_bytes"] += n_bytes + n_messages
        if self.timing is not None:
            dt = self.timing.transaction_s(n_bytes, n_messages)
            self.stats["busy_s"] += dt
            self.clock.advance(dt)

    # -- smbus2 surface -------------------------------------------------------------
    def read_byte_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
        dev = self._begin(i2c_addr)
        value = dev.read(register, 1)[0]
        self._end(2, 2)
        return value

    def write_byte_data(
        self, i2c_addr: int, register: int, value: int, force: bool | None = None
    ) -> None:
        dev = self._begin(i2c_addr)
        dev.write(register, bytes([value & 0xFF]))
        self._end(2, 1)

    def read_i2c_block_data(
        self, i2c_addr: int, register: int, length: int, force: bool | None = None
    ) -> list[int]:
        if length > SMBUS_BLOCK_MAX:
            raise ValueError(f"Desired block length over {SMBUS_BLOCK_MAX} bytes")
        dev = self._begin(i2c_addr)
        data = dev.read(register, length)
        self._end(1 + length, 2)
        return list(data)

    def write_i2c_block_data(
        self, i2c_addr: int, register: int, data: Sequence[int], force: bool | None = None
    ) -> None:
        if len(data) > SMBUS_BLOCK_MAX:
            raise ValueError(f"Data length cannot exceed {SMBUS_BLOCK_MAX} bytes")
        dev = self._begin(i2c_addr)
        dev.write(register, bytes(data))
        self._end(1 + len(data), 1)

    def i2c_rdwr(self, *i2c_msgs: i2c_msg) -> None:
        if not i2c_msgs:
            return
        addr = i2c_msgs[0].addr
        if any(m.addr != addr for m in i2c_msgs):
            raise OSError(errno.EINVAL, "simulated bus: one device per combined transaction")
        dev = self._begin(addr)
        register: int | None = None
        n_bytes = 0
        for msg in i2c_msgs:
            n_bytes += msg.len
            if msg.flags & I2C_M_RD:
                if register is None:
                    raise OSError(errno.EINVAL, "read message without a register address")
                data = dev.read(register, msg.len)
                ctypes.memmove(msg.buf, data, len(data))
                register = None
            else:
                payload = msg_bytes(msg)
                if not payload:
                    continue
                register = payload[0]
                if len(payload) > 1:
                    dev.write(register, payload[1:])
        self._end(n_bytes, len(i2c_msgs))
        if (
            self.faults is not None
            and self.stall_register is not None
            and msg_bytes(i2c_msgs[0])[:1] == bytes([self.stall_register])
        ):
            self.clock.sleep(self.faults.stall_after_read(self.clock.now()))

    def close(self) -> None:
        self.closed = True

    def __enter__(self) -> SimI2CBus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
