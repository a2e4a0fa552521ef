"""TMsg framing of ST's DataLogExtended / Unicleo serial protocol (SensorTile STEVAL-STLKT01V1).

Reference: ``shared/reference/lsm6ds-registers.md`` §14.A (read in ST's ``serial_protocol.c``
of X-CUBE-MEMS1 and the SensorTile DataLogExtended firmware).

A *logical message* is ``dest, source, command, payload...``. On the wire:

1. a checksum byte is appended so that the 8-bit sum of every byte, checksum included,
   is zero: ``chk = (-sum(message)) mod 256``;
2. byte stuffing: ``0xF0 -> 0xF1 0xF2``, ``0xF1 -> 0xF1 0xF1``, every other byte copied;
3. a single ``0xF0`` terminates the frame. There is no start byte and no length field.

The decoder below is incremental (bytes may arrive in any split) and resynchronises on
the next ``0xF0`` after any damage: a corrupted frame is reported as a :class:`BadFrame`
and never leaks into the following one.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

FRAME_END = 0xF0
"""Terminates every frame."""
ESCAPE = 0xF1
"""Escape byte: ``F1 F2`` stands for ``F0`` and ``F1 F1`` for ``F1``."""
ESCAPED_END = 0xF2

MAX_MESSAGE_LEN = 1024
"""Longest logical message accepted (v12 firmware ``Msg_MaxLen``); longer runs are noise."""


def checksum(message: bytes) -> int:
    """The TMsg checksum byte: ``(-sum(message)) mod 256`` (sum of all bytes incl. it is 0)."""
    return (-sum(message)) & 0xFF


def stuff(data: bytes) -> bytes:
    """Byte stuffing: ``F0 -> F1 F2``, ``F1 -> F1 F1`` (no terminator added)."""
    return data.replace(b"\xf1", b"\xf1\xf1").replace(b"\xf0", b"\xf1\xf2")


def encode_frame(message: bytes) -> bytes:
    """Wire bytes of a logical message: message + checksum, stuffed, then ``0xF0``."""
    body = bytes(message) + bytes([checksum(message)])
    return stuff(body) + bytes([FRAME_END])


def unstuff(stuffed: bytes) -> bytes:
    """Undo byte stuffing of one frame body (terminator already removed).

    Raises:
        ValueError: on ``F1`` followed by anything but ``F1``/``F2`` or a trailing ``F1``.
    """
    out = bytearray()
    i = 0
    n = len(stuffed)
    while i < n:
        b = stuffed[i]
        if b == ESCAPE:
            if i + 1 >= n:
                raise ValueError(f"escape byte 0xF1 at the end of the frame (offset {i})")
            nxt = stuffed[i + 1]
            if nxt == ESCAPE:
                out.append(ESCAPE)
            elif nxt == ESCAPED_END:
                out.append(FRAME_END)
            else:
                raise ValueError(f"invalid escape sequence F1 {nxt:02X} at offset {i}")
            i += 2
        else:
            out.append(b)
            i += 1
    return bytes(out)


@dataclass(frozen=True)
class Frame:
    """A frame that passed the checksum: the logical message without its checksum byte."""

    message: bytes

    @property
    def dest(self) -> int:
        return self.message[0]

    @property
    def source(self) -> int:
        return self.message[1]

    @property
    def command(self) -> int:
        return self.message[2]

    @property
    def payload(self) -> bytes:
        return self.message[3:]


@dataclass(frozen=True)
class BadFrame:
    """Bytes up to a terminator that did not form a valid frame, and why."""

    reason: str
    wire: bytes


class FrameDecoder:
    """Incremental TMsg deframer: ``feed(bytes)`` yields :class:`Frame` / :class:`BadFrame`.

    State is the partial frame only (bounded by :data:`MAX_MESSAGE_LEN` stuffed bytes);
    a run longer than that is dropped as one bad frame and decoding restarts at the next
    terminator. Counters: ``frames``, ``bad_frames``, ``bytes``.
    """

    def __init__(self, max_len: int = MAX_MESSAGE_LEN) -> None:
        self._buf = bytearray()
        self._overlong = False
        self.max_len = max_len
        self.frames = 0
        self.bad_frames = 0
        self.bytes = 0

    def reset(self) -> None:
        """Forget any partial frame (after a reconnect)."""
        self._buf.clear()
        self._overlong = False

    @property
    def pending(self) -> int:
        """Bytes of the current, unterminated frame."""
        return len(self._buf)

    def feed(self, data: bytes) -> Iterator[Frame | BadFrame]:
        self.bytes += len(data)
        start = 0
        while True:
            end = data.find(FRAME_END, start)
            if end < 0:
                self._append(data[start:])
                return
            self._append(data[start:end])
            wire = bytes(self._buf)
            overlong = self._overlong
            self.reset()
            start = end + 1
            result = self._decode(wire, overlong)
            if isinstance(result, Frame):
                self.frames += 1
            else:
                self.bad_frames += 1
            yield result

    def _append(self, chunk: bytes) -> None:
        if self._overlong:
            return
        self._buf += chunk
        if len(self._buf) > 2 * self.max_len + 2:
            self._overlong = True
            self._buf.clear()

    @staticmethod
    def _decode(wire: bytes, overlong: bool) -> Frame | BadFrame:
        if overlong:
            return BadFrame("no frame terminator within the maximum message length", wire)
        if not wire:
            return BadFrame("empty frame", wire)
        try:
            body = unstuff(wire)
        except ValueError as exc:
            return BadFrame(str(exc), wire)
        if len(body) < 4:
            return BadFrame(f"frame of {len(body)} bytes is shorter than header + checksum", wire)
        if sum(body) & 0xFF:
            return BadFrame(f"checksum error (byte sum 0x{sum(body) & 0xFF:02X}, want 0)", wire)
        return Frame(body[:-1])
