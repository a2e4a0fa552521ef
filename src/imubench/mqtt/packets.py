"""MQTT 3.1.1 control packets: framing, decoding of client packets, encoding of replies.

Source: OASIS MQTT Version 3.1.1 (Plus Errata 01), 2015 (cited as "§" sections below).
Only the packets a broker receives are decoded and only those it sends are encoded.
Every structural violation raises ``MalformedPacket`` with the section it breaks.
"""

from __future__ import annotations

import asyncio
import struct
from dataclasses import dataclass, field

from imubench.mqtt.errors import MalformedPacket

# Control packet types, §2.2.1
CONNECT, CONNACK, PUBLISH, PUBACK, PUBREC, PUBREL, PUBCOMP = 1, 2, 3, 4, 5, 6, 7
SUBSCRIBE, SUBACK, UNSUBSCRIBE, UNSUBACK, PINGREQ, PINGRESP, DISCONNECT = (
    8,
    9,
    10,
    11,
    12,
    13,
    14,
)
PACKET_NAMES = {
    1: "CONNECT",
    2: "CONNACK",
    3: "PUBLISH",
    4: "PUBACK",
    5: "PUBREC",
    6: "PUBREL",
    7: "PUBCOMP",
    8: "SUBSCRIBE",
    9: "SUBACK",
    10: "UNSUBSCRIBE",
    11: "UNSUBACK",
    12: "PINGREQ",
    13: "PINGRESP",
    14: "DISCONNECT",
    15: "AUTH",
}

# CONNACK return codes, §3.2.2.3
CONNACK_ACCEPTED = 0x00
CONNACK_BAD_PROTOCOL = 0x01
CONNACK_ID_REJECTED = 0x02
CONNACK_UNAVAILABLE = 0x03
CONNACK_BAD_CREDENTIALS = 0x04
CONNACK_NOT_AUTHORIZED = 0x05
# MQTT 5.0 §3.2.2.2 reason code, used only to refuse MQTT 5 clients in their own format.
CONNACK_V5_UNSUPPORTED_PROTOCOL = 0x84
SUBACK_FAILURE = 0x80

MAX_REMAINING_LENGTH = 268_435_455  # §2.2.3: four length bytes


@dataclass(frozen=True)
class Message:
    """An application message as routed by the broker."""

    topic: str
    payload: bytes
    qos: int = 0
    retain: bool = False


@dataclass
class Connect:
    """Decoded CONNECT variable header and payload (§3.1)."""

    protocol_name: str
    protocol_level: int
    clean_session: bool
    keepalive_s: int
    client_id: str
    will: Message | None = None
    username: str | None = None
    password: bytes | None = None


@dataclass
class Publish:
    """Decoded PUBLISH (§3.3)."""

    message: Message
    packet_id: int | None
    dup: bool


@dataclass
class Subscribe:
    """Decoded SUBSCRIBE (§3.8): packet id and (filter, requested QoS) pairs."""

    packet_id: int
    topics: list[tuple[str, int]] = field(default_factory=list)


@dataclass
class Unsubscribe:
    """Decoded UNSUBSCRIBE (§3.10)."""

    packet_id: int
    topics: list[str] = field(default_factory=list)


def encode_remaining_length(length: int) -> bytes:
    """Variable byte integer of §2.2.3 (7 bits per byte, high bit = continuation)."""
    if not 0 <= length <= MAX_REMAINING_LENGTH:
        raise ValueError(f"remaining length {length} outside 0..{MAX_REMAINING_LENGTH}")
    out = bytearray()
    while True:
        byte, length = length % 128, length // 128
        out.append(byte | (0x80 if length else 0))
        if not length:
            return bytes(out)


async def read_packet(reader: asyncio.StreamReader, max_size: int) -> tuple[int, int, bytes]:
    """Read one control packet; return ``(packet_type, flags, body)``.

    Raises ``asyncio.IncompleteReadError`` on EOF, ``MalformedPacket`` when the remaining
    length uses more than four bytes (§2.2.3) or exceeds ``max_size`` bytes.
    """
    first = (await reader.readexactly(1))[0]
    length = 0
    for shift in range(4):
        byte = (await reader.readexactly(1))[0]
        length |= (byte & 0x7F) << (7 * shift)
        if not byte & 0x80:
            break
    else:
        raise MalformedPacket("remaining length longer than four bytes (§2.2.3)")
    if length > max_size:
        raise MalformedPacket(f"packet of {length} bytes exceeds the broker limit {max_size}")
    body = await reader.readexactly(length) if length else b""
    return first >> 4, first & 0x0F, body


class _Cursor:
    """Sequential reader over a packet body; every overrun is a malformed packet."""

    def __init__(self, data: bytes, what: str) -> None:
        self.data, self.pos, self.what = data, 0, what

    def remaining(self) -> int:
        return len(self.data) - self.pos

    def take(self, n: int) -> bytes:
        if self.remaining() < n:
            raise MalformedPacket(f"{self.what} truncated at byte {self.pos} (needs {n} more)")
        chunk = self.data[self.pos : self.pos + n]
        self.pos += n
        return chunk

    def u8(self) -> int:
        return self.take(1)[0]

    def u16(self) -> int:
        return struct.unpack(">H", self.take(2))[0]

    def binary(self) -> bytes:
        return self.take(self.u16())

    def string(self) -> str:
        """UTF-8 encoded string of §1.5.3: well-formed, no U+0000."""
        raw = self.binary()
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise MalformedPacket(f"{self.what}: invalid UTF-8 string (§1.5.3): {exc}") from None
        if "\x00" in text:
            raise MalformedPacket(f"{self.what}: string contains U+0000 (§1.5.3)")
        return text


def parse_connect(body: bytes) -> Connect:
    """Decode a CONNECT body (§3.1.2-3.1.3).

    Protocol name/level are returned as read so the caller can answer unknown levels with
    CONNACK 0x01 (or, for MQTT 5, reason 0x84). Flag rules checked: reserved bit 0 is zero
    (§3.1.2-3), will QoS/retain are zero without the will flag (§3.1.2-11, -13), will QoS
    is not 3 (§3.1.2-14), no password without user name (§3.1.2-22).
    """
    cur = _Cursor(body, "CONNECT")
    name = cur.string()
    level = cur.u8()
    if name not in ("MQTT", "MQIsdp"):
        raise MalformedPacket(f"CONNECT protocol name {name!r} is not 'MQTT' (§3.1.2.1)")
    if level == 5:
        # MQTT 5: flags and keep-alive follow, then properties; the caller refuses it.
        return Connect(name, level, True, 0, "")
    flags = cur.u8()
    keepalive = cur.u16()
    if flags & 0x01:
        raise MalformedPacket("CONNECT reserved flag bit 0 is set (§3.1.2-3)")
    will_flag = bool(flags & 0x04)
    will_qos = (flags >> 3) & 0x03
    will_retain = bool(flags & 0x20)
    if not will_flag and (will_qos or will_retain):
        raise MalformedPacket("CONNECT will QoS/retain set without the will flag (§3.1.2-11)")
    if will_qos == 3:
        raise MalformedPacket("CONNECT will QoS is 3 (§3.1.2-14)")
    has_password, has_username = bool(flags & 0x40), bool(flags & 0x80)
    if has_password and not has_username:
        raise MalformedPacket("CONNECT password flag set without user name flag (§3.1.2-22)")
    client_id = cur.string()
    will = None
    if will_flag:
        will_topic = cur.string()
        will = Message(will_topic, cur.binary(), will_qos, will_retain)
    username = cur.string() if has_username else None
    password = cur.binary() if has_password else None
    if cur.remaining():
        raise MalformedPacket(f"CONNECT has {cur.remaining()} unexpected trailing bytes")
    return Connect(name, level, bool(flags & 0x02), keepalive, client_id, will, username, password)


def parse_publish(flags: int, body: bytes) -> Publish:
    """Decode a PUBLISH (§3.3): QoS from the fixed header, packet id only for QoS > 0."""
    qos = (flags >> 1) & 0x03
    if qos == 3:
        raise MalformedPacket("PUBLISH with QoS 3 (§3.3.1-4)")
    dup = bool(flags & 0x08)
    if qos == 0 and dup:
        raise MalformedPacket("PUBLISH QoS 0 with DUP set (§3.3.1-2)")
    cur = _Cursor(body, "PUBLISH")
    topic = cur.string()
    packet_id = cur.u16() if qos else None
    if packet_id == 0:
        raise MalformedPacket("PUBLISH packet identifier 0 (§2.3.1-1)")
    payload = cur.take(cur.remaining())
    return Publish(Message(topic, payload, qos, bool(flags & 0x01)), packet_id, dup)


def parse_packet_id(name: str, body: bytes) -> int:
    """Decode the two-byte body of PUBACK/PUBREC/PUBREL/PUBCOMP (§3.4-3.7)."""
    if len(body) != 2:
        raise MalformedPacket(f"{name} remaining length {len(body)}, must be 2")
    return struct.unpack(">H", body)[0]


def parse_subscribe(body: bytes) -> Subscribe:
    """Decode SUBSCRIBE (§3.8): at least one filter (§3.8.3-3), QoS byte 0..2 (§3.8.3-4)."""
    cur = _Cursor(body, "SUBSCRIBE")
    sub = Subscribe(cur.u16())
    while cur.remaining():
        topic_filter = cur.string()
        options = cur.u8()
        if options & 0xFC or options & 0x03 == 3:
            raise MalformedPacket(f"SUBSCRIBE requested QoS byte 0x{options:02x} (§3.8.3-4)")
        sub.topics.append((topic_filter, options))
    if not sub.topics:
        raise MalformedPacket("SUBSCRIBE without any topic filter (§3.8.3-3)")
    return sub


def parse_unsubscribe(body: bytes) -> Unsubscribe:
    """Decode UNSUBSCRIBE (§3.10): at least one filter (§3.10.3-2)."""
    cur = _Cursor(body, "UNSUBSCRIBE")
    unsub = Unsubscribe(cur.u16())
    while cur.remaining():
        unsub.topics.append(cur.string())
    if not unsub.topics:
        raise MalformedPacket("UNSUBSCRIBE without any topic filter (§3.10.3-2)")
    return unsub


# Fixed-header flags each client packet type must carry (§2.2.2); PUBLISH is free.
REQUIRED_FLAGS = {
    CONNECT: 0,
    PUBACK: 0,
    PUBREC: 0,
    PUBREL: 2,
    PUBCOMP: 0,
    SUBSCRIBE: 2,
    UNSUBSCRIBE: 2,
    PINGREQ: 0,
    DISCONNECT: 0,
}


def _packet(packet_type: int, flags: int, body: bytes) -> bytes:
    return bytes([(packet_type << 4) | flags]) + encode_remaining_length(len(body)) + body


def _string(text: str) -> bytes:
    raw = text.encode("utf-8")
    return struct.pack(">H", len(raw)) + raw


def connack(session_present: bool, return_code: int) -> bytes:
    """CONNACK (§3.2): acknowledge flags byte then return code."""
    return _packet(CONNACK, 0, bytes([1 if session_present else 0, return_code]))


def connack_v5_refusal(reason_code: int = CONNACK_V5_UNSUPPORTED_PROTOCOL) -> bytes:
    """MQTT 5 CONNACK (MQTT 5.0 §3.2) with a reason code and an empty property list."""
    return _packet(CONNACK, 0, bytes([0, reason_code, 0]))


def publish(message: Message, packet_id: int | None = None, dup: bool = False) -> bytes:
    """PUBLISH (§3.3) with the given QoS, retain and DUP flags."""
    flags = (0x08 if dup else 0) | (message.qos << 1) | (0x01 if message.retain else 0)
    body = _string(message.topic)
    if message.qos:
        if packet_id is None:
            raise ValueError("a QoS > 0 PUBLISH needs a packet identifier")
        body += struct.pack(">H", packet_id)
    return _packet(PUBLISH, flags, body + message.payload)


def ack(packet_type: int, packet_id: int) -> bytes:
    """PUBACK, PUBREC, PUBREL (flags 0b0010, §3.6.1), PUBCOMP or UNSUBACK."""
    flags = 2 if packet_type == PUBREL else 0
    return _packet(packet_type, flags, struct.pack(">H", packet_id))


def suback(packet_id: int, return_codes: list[int]) -> bytes:
    """SUBACK (§3.9): one granted QoS or 0x80 per requested filter, in order."""
    return _packet(SUBACK, 0, struct.pack(">H", packet_id) + bytes(return_codes))


def pingresp() -> bytes:
    """PINGRESP (§3.13)."""
    return _packet(PINGRESP, 0, b"")
