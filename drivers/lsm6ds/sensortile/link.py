"""The host side of the SensorTile USB serial link: commands, stream, reconnection.

The port is opened with :func:`serial.serial_for_url`, so a real ``/dev/ttyACM0``, a
``/dev/serial/by-id/...`` symlink, a pty served by the simulated firmware
(``lsm6ds_sim.sensortile_fw``) and pyserial's ``loop://`` all go through the same code.

Reconnection: any :class:`serial.SerialException` / :class:`OSError` on read or write
(USB unplug: the CDC device disappears, reads fail with EIO) closes the port and retries
``serial_for_url(url)`` with exponential backoff (``backoff_initial_s`` doubling up to
``backoff_max_s``) until ``reconnect_timeout_s``. The URL should therefore be a *stable*
name that survives a replug — on Linux the udev symlink
``/dev/serial/by-id/usb-STMicroelectronics_...-if00``; the simulated firmware re-points
such a symlink at its new pty on every replug. After a reconnect in binary mode the
START_DATA_STREAMING command is sent again (the firmware forgets its streaming state when
the USB host goes away).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import serial

from lsm6ds.errors import LSM6DSError
from lsm6ds.sensortile import commands as cmds
from lsm6ds.sensortile.datalog_ascii import BadRecord, DataLogParser, DataLogRecord
from lsm6ds.sensortile.stream import StreamFrame, is_stream_message, parse_stream_message
from lsm6ds.sensortile.tmsg import BadFrame, Frame, FrameDecoder


class SensorTileError(LSM6DSError):
    """The SensorTile link failed (no port, no reply, reconnection gave up)."""


class LinkInterruptedError(SensorTileError):
    """A reconnection was given up because :attr:`SensorTileLink.interrupted` was set (the
    reader is stopping), not because the kit failed."""


LINK_COUNTERS: tuple[str, ...] = (
    "bytes",
    "frames",
    "bad_frames",
    "io_errors",
    "retries",
    "reconnects",
    "nacks",
    "other_frames",
)


@dataclass(frozen=True)
class Received:
    """A stream item with the host clock (``time.monotonic``) when its bytes arrived."""

    item: StreamFrame | DataLogRecord
    host_s: float


@dataclass
class LinkConfig:
    """Tunables of :class:`SensorTileLink` (seconds throughout)."""

    host_addr: int = cmds.HOST_ADDR
    read_timeout_s: float = 0.05
    reply_timeout_s: float = 0.5
    command_retries: int = 3
    backoff_initial_s: float = 0.02
    backoff_max_s: float = 1.0
    reconnect_timeout_s: float = 30.0
    stall_timeout_s: float = 2.0
    """Binary streaming: no valid frame for this long -> send START again (``retries``)."""
    baudrate: int = 921600
    serial_kwargs: dict[str, object] = field(default_factory=dict)


class SensorTileLink:
    """A SensorTile on a serial URL, in ``binary`` (DataLogExtended) or ``ascii`` (DataLog) mode.

    Counters (``self.counters``): bytes, frames (valid stream frames / records), bad_frames
    (damaged frames, records, or stream frames that fail the layout check), io_errors,
    retries (command re-sends, stall restarts), reconnects, nacks, other_frames.
    """

    def __init__(
        self,
        url: str,
        mode: str = "binary",
        config: LinkConfig | None = None,
        *,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        if mode not in ("binary", "ascii"):
            raise SensorTileError(f"SensorTileLink({url!r}): mode {mode!r} is not binary|ascii")
        self.url = url
        self.mode = mode
        self.config = config or LinkConfig()
        self.counters: dict[str, int] = dict.fromkeys(LINK_COUNTERS, 0)
        self._sleep = sleep
        self._port: serial.SerialBase | None = None
        self._decoder = FrameDecoder()
        self._parser = DataLogParser()
        self._pending: list[Received] = []
        self._replies: list[Frame] = []
        self._streaming_mask: int | None = None
        self._last_frame_s = 0.0
        self.interrupted = threading.Event()
        """Set it (from any thread) to give up a reconnection at once: a stop during an
        unplug waited out ``reconnect_timeout_s`` (30 s) and then failed."""
        self.on_reconnect: Callable[[], None] | None = None
        """Called after every successful reconnection (before the stream is restarted)."""

    # -- port ---------------------------------------------------------------------
    @property
    def is_open(self) -> bool:
        return self._port is not None

    def open(self) -> None:
        """Open the port (once; raises :class:`SensorTileError` if it cannot)."""
        if self._port is not None:
            return
        try:
            self._port = serial.serial_for_url(
                self.url,
                baudrate=self.config.baudrate,
                timeout=self.config.read_timeout_s,
                write_timeout=self.config.reply_timeout_s,
                **self.config.serial_kwargs,
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise SensorTileError(
                f"cannot open SensorTile port {self.url!r}: {exc}; check the cable, the "
                "device path (ls /dev/serial/by-id/) and permissions (dialout group)"
            ) from exc
        self._decoder.reset()
        self._parser.reset()

    def close(self) -> None:
        """Stop the stream if possible and close the port."""
        if self._port is None:
            return
        if self._streaming_mask is not None and self.mode == "binary":
            try:
                self._port.write(cmds.frame(cmds.stop_streaming_request(self.config.host_addr)))
                self._port.flush()
            except (serial.SerialException, OSError):
                pass
        self._streaming_mask = None
        self._drop_port()

    def _drop_port(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            with contextlib.suppress(serial.SerialException, OSError):
                port.close()

    def __enter__(self) -> SensorTileLink:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def reconnect(self) -> None:
        """Close and reopen the port with exponential backoff; restart the stream.

        Raises:
            SensorTileError: when the port did not come back within ``reconnect_timeout_s``.
        """
        self._drop_port()
        cfg = self.config
        delay = cfg.backoff_initial_s
        deadline = time.monotonic() + cfg.reconnect_timeout_s
        last_exc: Exception | None = None
        while True:
            self._sleep(delay)
            if self.interrupted.is_set():
                raise LinkInterruptedError(
                    f"SensorTile at {self.url!r}: stopped while reconnecting")
            try:
                self.open()
                break
            except SensorTileError as exc:
                last_exc = exc
            if time.monotonic() >= deadline:
                raise SensorTileError(
                    f"SensorTile at {self.url!r} did not come back within "
                    f"{cfg.reconnect_timeout_s} s after a disconnect ({last_exc}); "
                    "replug the kit or raise reconnect_timeout_s"
                )
            delay = min(delay * 2.0, cfg.backoff_max_s)
        self.counters["reconnects"] += 1
        self._pending.clear()
        self._replies.clear()
        if self.on_reconnect is not None:
            self.on_reconnect()
        if self._streaming_mask is not None and self.mode == "binary":
            mask, self._streaming_mask = self._streaming_mask, None
            self.start_streaming(mask)

    # -- raw I/O ------------------------------------------------------------------
    def _write(self, data: bytes) -> None:
        if self._port is None:
            self.open()
        assert self._port is not None
        try:
            self._port.write(data)
        except (serial.SerialException, OSError):
            self.counters["io_errors"] += 1
            self.reconnect()

    def _in_waiting(self) -> int:
        if self._port is None:
            return 0
        try:
            return int(self._port.in_waiting)
        except (serial.SerialException, OSError):
            return 0

    def _pump(self) -> int:
        """Read what the port has (waiting up to ``read_timeout_s``) and dispatch it."""
        if self._port is None:
            self.open()
        assert self._port is not None
        try:
            data = self._port.read(max(1, self._port.in_waiting))
        except (serial.SerialException, OSError):
            self.counters["io_errors"] += 1
            self.reconnect()
            return 0
        if not data:
            return 0
        now = time.monotonic()
        self.counters["bytes"] += len(data)
        if self.mode == "binary":
            for item in self._decoder.feed(data):
                self._dispatch_frame(item, now)
        else:
            for rec in self._parser.feed(data):
                if isinstance(rec, BadRecord):
                    self.counters["bad_frames"] += 1
                else:
                    self.counters["frames"] += 1
                    self._pending.append(Received(rec, now))
        return len(data)

    def _dispatch_frame(self, item: Frame | BadFrame, now: float) -> None:
        if isinstance(item, BadFrame):
            self.counters["bad_frames"] += 1
            return
        msg = item.message
        if is_stream_message(msg) and msg[0] == self.config.host_addr:
            try:
                frame = parse_stream_message(msg)
            except ValueError:
                self.counters["bad_frames"] += 1
                return
            self.counters["frames"] += 1
            self._last_frame_s = now
            self._pending.append(Received(frame, now))
        elif item.source == cmds.DEV_ADDR and item.dest == self.config.host_addr:
            if item.command == cmds.Cmd.NACK:
                self.counters["nacks"] += 1
            self._replies.append(item)
        else:
            self.counters["other_frames"] += 1

    # -- commands -----------------------------------------------------------------
    def command(self, message: bytes) -> Frame:
        """Send a logical request and wait for its reply (command + 0x80).

        Stream frames that arrive meanwhile are kept for :meth:`read_stream`. The request
        is re-sent up to ``command_retries`` times (a reply can be lost to line noise).

        Raises:
            SensorTileError: on NACK or when no reply came after all retries.
        """
        if self.mode != "binary":
            raise SensorTileError(
                f"SensorTile at {self.url!r} is in ascii (DataLog) mode: it takes no commands"
            )
        want = message[2] | cmds.REPLY_FLAG
        wire = cmds.frame(message)
        for attempt in range(self.config.command_retries + 1):
            if attempt:
                self.counters["retries"] += 1
            self._replies.clear()
            self._write(wire)
            deadline = time.monotonic() + self.config.reply_timeout_s
            while time.monotonic() < deadline:
                self._pump()
                for reply in self._replies:
                    if reply.command == want:
                        self._replies.clear()
                        return reply
                    if reply.command == cmds.Cmd.NACK:
                        raise SensorTileError(
                            f"SensorTile at {self.url!r} answered NACK to command "
                            f"0x{message[2]:02X} ({message.hex(' ')})"
                        )
                self._replies.clear()
        raise SensorTileError(
            f"no reply 0x{want:02X} from the SensorTile at {self.url!r} to command "
            f"0x{message[2]:02X} after {self.config.command_retries + 1} tries; is the "
            "DataLogExtended firmware running (not the ASCII DataLog)?"
        )

    def ping(self) -> None:
        self.command(cmds.ping_request(self.config.host_addr))

    def presentation(self) -> str:
        """The presentation string, e.g. ``MEMS shield demo,101,4.0.0,0.0.0,STLKT01V1``."""
        reply = self.command(cmds.presentation_request(self.config.host_addr))
        return reply.payload.decode("ascii", errors="replace")

    def check_mode(self) -> int:
        """Firmware id (101 = DataLogExtended)."""
        reply = self.command(cmds.check_mode_request(self.config.host_addr))
        if len(reply.payload) != 4:
            raise SensorTileError(
                f"check-mode reply from {self.url!r} has {len(reply.payload)} payload bytes, want 4"
            )
        return int.from_bytes(reply.payload, "little", signed=True)

    def start_streaming(self, mask: int = cmds.IMU_MASK) -> None:
        """START_DATA_STREAMING with ``mask``; remembered so a reconnect restarts it."""
        if self.mode == "ascii":
            self._streaming_mask = mask
            return
        self.command(cmds.start_streaming_request(mask, self.config.host_addr))
        self._streaming_mask = mask
        self._last_frame_s = time.monotonic()

    def stop_streaming(self) -> None:
        if self.mode == "binary":
            self.command(cmds.stop_streaming_request(self.config.host_addr))
        self._streaming_mask = None

    # -- stream -------------------------------------------------------------------
    def read_stream(self, max_items: int = 256, timeout_s: float = 0.2) -> list[Received]:
        """Stream frames (binary) or records (ascii) received so far, waiting up to ``timeout_s``.

        Returns as soon as at least one item is there (up to ``max_items``), or an empty
        list at the timeout. Disconnects are handled inside (reconnect, restart).
        """
        deadline = time.monotonic() + timeout_s
        while not self._pending:
            self._pump()
            if self._pending:
                break
            now = time.monotonic()
            if (
                self.mode == "binary"
                and self._streaming_mask is not None
                and now - self._last_frame_s > self.config.stall_timeout_s
            ):
                self.counters["retries"] += 1
                mask, self._streaming_mask = self._streaming_mask, None
                try:
                    self.start_streaming(mask)
                except SensorTileError:
                    self._streaming_mask = mask
                    self._last_frame_s = time.monotonic()
            if now >= deadline:
                break
        # drain what is already buffered without waiting
        while len(self._pending) < max_items and self._in_waiting():
            if self._pump() == 0:
                break
        out, self._pending = self._pending[:max_items], self._pending[max_items:]
        return out
