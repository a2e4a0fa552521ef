"""I2C bus timing model: how long a transaction occupies the bus.

Every byte on the wire takes 9 bit-times (8 data bits + ACK). A transaction adds a START
(1 bit-time), a STOP (1 bit-time) and the bus-free time between a STOP and the next START
(t_BUF, 4.7 us at 100 kHz and 1.3 us at 400 kHz, I2C-bus specification UM10204 table 10),
and every extra message of a combined transfer a repeated START (1 bit-time) and its own
address byte. Clock stretching and host software latency are not modelled (add
``host_overhead_s`` per transaction if wanted).

The payload limit of the link is therefore ``bus_hz / 9`` bytes per second (44 444 B/s at
400 kHz), the figure the driver's bus budget and the acceptance tests use.
"""

from __future__ import annotations

from dataclasses import dataclass

BITS_PER_BYTE = 9
"""8 data bits + ACK/NACK."""

T_BUF_S: dict[int, float] = {100_000: 4.7e-6, 400_000: 1.3e-6, 1_000_000: 0.5e-6}
"""Bus-free time between STOP and START (UM10204 table 10), by bus speed."""


def payload_limit_bytes_per_s(bus_hz: float) -> float:
    """Upper bound of bytes per second through an I2C bus at ``bus_hz``: bus_hz / 9."""
    return bus_hz / BITS_PER_BYTE


@dataclass(frozen=True)
class I2CTiming:
    """Duration of I2C transactions at ``bus_hz``.

    Attributes:
        bus_hz: SCL frequency, Hz (100e3 or 400e3 usually).
        host_overhead_s: extra time per transaction (driver/kernel latency), s.
    """

    bus_hz: float
    host_overhead_s: float = 0.0

    @property
    def bit_s(self) -> float:
        return 1.0 / self.bus_hz

    @property
    def t_buf_s(self) -> float:
        return T_BUF_S.get(int(self.bus_hz), 1.3e-6)

    def transaction_s(self, n_bytes: int, n_messages: int = 1) -> float:
        """Bus time of one transaction of ``n_messages`` messages carrying ``n_bytes`` data
        bytes (register address bytes included, address bytes of the messages not):
        ``(9 (n_bytes + n_messages) + 2 + (n_messages - 1)) / bus_hz + t_BUF``."""
        bits = (
            BITS_PER_BYTE * (n_bytes + n_messages)  # data + one address byte per message
            + 2  # START + STOP
            + (n_messages - 1)  # repeated STARTs
        )
        return bits * self.bit_s + self.t_buf_s + self.host_overhead_s

    def wire_bytes(self, n_bytes: int, n_messages: int = 1) -> int:
        """Bytes on the wire for such a transaction (data + address bytes)."""
        return n_bytes + n_messages
