"""A simulated SensorTile (STEVAL-STLKT01V1) firmware served on a pty.

The firmware runs in a thread, owns the master side of a pty from :func:`os.openpty`, and
publishes the slave under a *stable symlink* that it re-points at every replug, the way
udev maintains ``/dev/serial/by-id/usb-STMicroelectronics_...``. A host opens the symlink
with :func:`serial.serial_for_url` exactly like a real kit.

Two firmwares (``lsm6ds-registers.md`` §14):

* ``binary``: DataLogExtended / Unicleo TMsg protocol (§14.A). Answers PING, READ_PRES_STRING,
  CHECK_MODE_SUPPORT, START/STOP_DATA_STREAMING, SET_DATE_TIME and the SENSOR sub-commands
  GET_NAME, READ/WRITE_REGISTER, GET_FS, GET_ODR; anything else gets a NACK. While
  streaming, a 56-byte stream frame is sent on every tick of the firmware's own timer
  (``period_cs`` hundredths of a second). The chip is sampled on that timer, not on its
  data-ready line, so against the chip's ODR samples repeat (flag bit 0) or are skipped,
  as on the real kit.
* ``ascii``: the STSW-STLKT01 DataLog five-line records (§14.B), every ``period_ms``,
  streamed from the moment the port exists; takes no commands.

Clock: ``virtual`` runs the timer as fast as the host reads (pty back-pressure; time does
not move while nobody listens to the binary stream), ``wall`` paces it with real time and
drops frames the host does not read in time (USB CDC busy), like the real kit.

Faults (host-visible, on the firmware's output bytes): ``corrupt_rate`` (a byte XOR a
random non-zero value), ``drop_rate`` (a byte vanishes), ``split_rate`` (the write is
split after a byte, the rest follows in a later write); ``unplug_every_s`` of simulated
time after the host starts the binary stream (after plug-in in ``ascii`` mode, which
streams from then) the USB cable is pulled: pty and symlink vanish, streaming stops, the
firmware keeps running on its battery (RTC and timer continue); ``replug_after_s`` later a new pty
appears behind the same symlink. Test hooks are prefixed ``sim_``.
"""

from __future__ import annotations

import contextlib
import os
import select
import struct
import tempfile
import threading
import time
import tty
from dataclasses import dataclass, field

import numpy as np
from lsm6ds.sensortile import commands as cmds
from lsm6ds.sensortile.datalog_ascii import DataLogRecord
from lsm6ds.sensortile.stream import (
    FLAG_ACC,
    FLAG_GYRO,
    FLAG_MAG,
    FLAG_TEMP,
    RTC_WRAP_CS,
    StreamFrame,
)
from lsm6ds.sensortile.tmsg import FrameDecoder, encode_frame

from lsm6ds_sim.clock import SimClock
from lsm6ds_sim.sensortile_chip import ChipPort, simulated_lsm6dsm

BY_ID_NAME = "usb-STMicroelectronics_STLKT01V1_0123456789AB-if00"
"""Name of the stable symlink (like udev's /dev/serial/by-id entry)."""

MAG_FIELD_MGAUSS = (220, -45, -410)
"""Constant magnetic field reported when the magnetometer is enabled (mgauss)."""


@dataclass
class SerialFaults:
    """Per-byte fault rates on the firmware -> host direction, and cable events (sim seconds)."""

    corrupt_rate: float = 0.0
    drop_rate: float = 0.0
    split_rate: float = 0.0
    unplug_every_s: float | None = None
    replug_after_s: float = 0.5
    max_unplugs: int | None = None

    def __post_init__(self) -> None:
        for name in ("corrupt_rate", "drop_rate", "split_rate"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"SerialFaults.{name}={v} must be within [0, 1]")
        if self.unplug_every_s is not None and self.unplug_every_s <= 0:
            raise ValueError(f"SerialFaults.unplug_every_s={self.unplug_every_s} must be > 0")


@dataclass
class SentFrame:
    """What the firmware produced on one timer tick (the test oracle)."""

    tick: int
    rtc_cs: int
    gyro_mdps: tuple[int, int, int]
    accel_mg: tuple[int, int, int]
    temp_c: float
    flags: int
    sent: bool
    wire: bytes = b""
    damaged: bool = False
    """A fault corrupted or dropped at least one byte of this frame on the wire."""


@dataclass
class FirmwareStats:
    ticks: int = 0
    frames_sent: int = 0
    frames_unsent: int = 0
    frames_busy: int = 0
    bytes_sent: int = 0
    bytes_corrupted: int = 0
    bytes_dropped: int = 0
    writes_split: int = 0
    unplugs: int = 0
    replugs: int = 0
    commands: int = 0
    bad_commands: int = 0
    log: list[SentFrame] = field(default_factory=list)


class SensorTileFirmware:
    """The simulated kit. ``start()`` plugs it in and runs the firmware thread; ``stop()`` ends it.

    Args:
        mode: ``binary`` (DataLogExtended) or ``ascii`` (DataLog).
        chip: where the IMU outputs come from; default :func:`simulated_lsm6dsm` on the clock.
        clock: the simulated clock (default: a new virtual one).
        seed: seeds the fault generator (and the stand-in chip).
        period_cs: binary stream tick in hundredths of a second (RTC resolution).
        period_ms: ascii record period, ms.
        link_dir: directory of the stable symlink (default: a fresh temp dir).
        rtc_start_cs: RTC value at boot (hundredths since 00:00:00, 12-hour clock).
        keep_log: keep every :class:`SentFrame` in ``sim_stats.log`` (tests).
    """

    def __init__(
        self,
        mode: str = "binary",
        chip: ChipPort | None = None,
        clock: SimClock | None = None,
        *,
        seed: int = 0,
        faults: SerialFaults | None = None,
        period_cs: int = 1,
        period_ms: int = 20,
        link_dir: str | None = None,
        rtc_start_cs: int = 0,
        keep_log: bool = False,
        presentation: str = cmds.PRESENTATION_STRING,
    ) -> None:
        if mode not in ("binary", "ascii"):
            raise ValueError(f"SensorTileFirmware: mode {mode!r} is not binary|ascii")
        if period_cs < 1 or period_ms < 1:
            raise ValueError("SensorTileFirmware: period_cs and period_ms must be >= 1")
        self.mode = mode
        self.clock = clock if clock is not None else SimClock("virtual")
        self.chip: ChipPort = chip if chip is not None else simulated_lsm6dsm(self.clock, seed)
        self.faults = faults or SerialFaults()
        self.period_s = period_cs / 100.0 if mode == "binary" else period_ms / 1000.0
        self.period_cs = period_cs
        self.period_ms = period_ms
        self.rtc_start_cs = rtc_start_cs
        self.keep_log = keep_log
        self.presentation = presentation
        self._rng = np.random.default_rng([seed, 0x5E7])
        self._own_dir = link_dir is None
        self.link_dir = link_dir or tempfile.mkdtemp(prefix="imubench-sensortile-")
        self.link_path = os.path.join(self.link_dir, BY_ID_NAME)
        self.sim_stats = FirmwareStats()
        self._master: int | None = None
        self._slave: int | None = None
        self._decoder = FrameDecoder()
        self._streaming: int | None = None  # mask
        self._host = cmds.HOST_ADDR
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._tick = 0
        self._pull_timer_from_s = 0.0
        self._unplugged_at_s: float | None = None
        self._stale = {"acc": (0, 0, 0), "gyro": (0, 0, 0), "temp": 0.0}
        self._regs = {0x0F: 0x6A, 0x10: 0x40, 0x11: 0x40, 0x12: 0x44}
        self.error: BaseException | None = None
        self._last_damaged = False

    # -- lifecycle ---------------------------------------------------------------
    @property
    def url(self) -> str:
        """What a host passes to ``serial_for_url`` (the stable symlink)."""
        return self.link_path

    @property
    def sim_plugged(self) -> bool:
        return self._master is not None

    @property
    def sim_streaming(self) -> bool:
        return self._streaming is not None

    def start(self) -> SensorTileFirmware:
        if self._thread is not None:
            return self
        self._stop.clear()
        self._plug()
        self._thread = threading.Thread(target=self._run, name="sensortile-fw", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self._unplug(count=False)
        if self._own_dir:
            with contextlib.suppress(OSError):
                os.rmdir(self.link_dir)

    def __enter__(self) -> SensorTileFirmware:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def sim_unplug(self) -> None:
        """Pull the cable now (the firmware thread replugs after ``replug_after_s``)."""
        with self._lock:
            self._unplug()

    # -- pty and symlink -----------------------------------------------------------
    def _plug(self) -> None:
        os.makedirs(self.link_dir, exist_ok=True)
        master, slave = os.openpty()
        tty.setraw(slave)
        tty.setraw(master)
        os.set_blocking(master, False)
        tmp = self.link_path + ".new"
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        os.symlink(os.ttyname(slave), tmp)
        os.replace(tmp, self.link_path)  # atomic re-point, like udev
        self._master, self._slave = master, slave
        self._decoder.reset()
        self._pull_timer_from_s = self.clock.now()
        self._unplugged_at_s = None

    def _unplug(self, count: bool = True) -> None:
        if self._master is None:
            return
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.link_path)
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)  # type: ignore[arg-type]
        self._master = self._slave = None
        self._streaming = None  # the USB host went away: streaming state is lost
        if count:
            self.sim_stats.unplugs += 1
        self._unplugged_at_s = self.clock.now()

    # -- main loop ------------------------------------------------------------------
    def _run(self) -> None:
        try:
            self._loop()
        except BaseException as exc:  # surfaced to tests through .error
            self.error = exc
            raise

    def _loop(self) -> None:
        clock = self.clock
        virtual = clock.mode == "virtual"
        next_tick_s = clock.now()
        while not self._stop.is_set():
            with self._lock:
                self._cable_events()
                active = self._master is not None and (
                    self.mode == "ascii" or self._streaming is not None
                )
            if virtual:
                if self._master is not None:  # unplugged: the timer runs on, unheard
                    self._serve_commands(0.0 if active else 0.02)
                    if not active:
                        continue  # nobody listens: virtual time stands still
                next_tick_s += self.period_s
                # the bus model may already have moved time on (I2C transfers)
                lag = next_tick_s - clock.now()
                if lag > 0:
                    clock.advance(lag)
            else:
                wait = next_tick_s - clock.now()
                self._serve_commands(max(wait, 0.0))
                if clock.now() < next_tick_s:
                    continue
                next_tick_s += self.period_s
            with self._lock:
                self._on_tick(block=virtual)

    def _cable_events(self) -> None:
        f = self.faults
        now = self.clock.now()
        if self._master is not None:
            if (
                f.unplug_every_s is not None
                and (self.mode == "ascii" or self._streaming is not None)
                and now - self._pull_timer_from_s >= f.unplug_every_s
                and (f.max_unplugs is None or self.sim_stats.unplugs < f.max_unplugs)
            ):
                self._unplug()
        elif self._unplugged_at_s is not None and now - self._unplugged_at_s >= f.replug_after_s:
            self._plug()
            self.sim_stats.replugs += 1

    # -- commands ---------------------------------------------------------------------
    def _serve_commands(self, timeout_s: float) -> None:
        master = self._master
        if master is None:
            if timeout_s > 0:
                time.sleep(min(timeout_s, 0.02))
            return
        try:
            ready, _, _ = select.select([master], [], [], timeout_s)
        except (OSError, ValueError):
            return
        if not ready:
            return
        with self._lock:
            if self._master is None:
                return
            try:
                data = os.read(self._master, 4096)
            except BlockingIOError:
                return
            except OSError:  # EIO: no host has the slave open; nothing to read
                data = b""
            if self.mode == "ascii" or not data:
                return
            for item in self._decoder.feed(data):
                if hasattr(item, "message"):
                    self._answer(item.message)
                else:
                    self.sim_stats.bad_commands += 1

    def _answer(self, msg: bytes) -> None:
        if msg[0] != cmds.DEV_ADDR:
            return  # not for us
        self.sim_stats.commands += 1
        cmd = msg[2]
        payload = msg[3:]
        reply: bytes | None
        if cmd == cmds.Cmd.PING and not payload:
            reply = cmds.reply_message(msg)
        elif cmd == cmds.Cmd.READ_PRES_STRING:
            reply = cmds.reply_message(msg, self.presentation.encode("ascii"))
        elif cmd == cmds.Cmd.CHECK_MODE_SUPPORT:
            reply = cmds.reply_message(msg, struct.pack("<i", cmds.DATALOG_EXT_MODE))
        elif cmd == cmds.Cmd.START_DATA_STREAMING and len(payload) == 4:
            self._host = msg[1]
            if self._streaming is None:  # the cable-pull timer counts streaming time: a
                # host slow to start (a loaded machine compiling) saw the kit vanish
                # before its first sample and had nothing to account for
                self._pull_timer_from_s = self.clock.now()
            self._streaming = struct.unpack("<I", payload)[0]
            reply = cmds.reply_message(msg)
        elif cmd == cmds.Cmd.STOP_DATA_STREAMING:
            self._streaming = None
            reply = cmds.reply_message(msg)
        elif cmd == cmds.Cmd.SET_DATE_TIME and len(payload) == 3:
            h, m, s = payload
            rtc_now = self._rtc_cs(self._tick)
            self.rtc_start_cs += ((h * 60 + m) * 60 + s) * 100 - rtc_now
            reply = cmds.reply_message(msg)
        elif cmd == cmds.Cmd.SENSOR and len(payload) >= 2:
            reply = self._sensor_command(msg)
        else:
            reply = None
        if reply is None:
            self.sim_stats.bad_commands += 1
            reply = cmds.nack_message(msg)
        self._send(encode_frame(reply), block=True, faults=False)

    def _sensor_command(self, msg: bytes) -> bytes | None:
        sub, sensor = msg[3], msg[4]
        args = msg[5:]
        if sensor not in (cmds.SensorType.ACCELEROMETER, cmds.SensorType.GYROSCOPE):
            return None
        if sub == cmds.SensorSub.GET_NAME:
            return cmds.reply_message(msg, b"LSM6DSM")
        if sub == cmds.SensorSub.READ_REGISTER and len(args) == 1:
            return cmds.reply_message(msg, bytes([args[0], self._regs.get(args[0], 0)]))
        if sub == cmds.SensorSub.WRITE_REGISTER and len(args) == 2:
            self._regs[args[0]] = args[1]
            return cmds.reply_message(msg, args)
        if sub == cmds.SensorSub.GET_FS:
            fs = 2 if sensor == cmds.SensorType.ACCELEROMETER else 250
            return cmds.reply_message(msg, struct.pack("<I", fs))
        if sub == cmds.SensorSub.GET_ODR:
            return cmds.reply_message(msg, struct.pack("<f", 104.0))
        return None

    # -- stream -------------------------------------------------------------------------
    def _rtc_cs(self, tick: int) -> int:
        elapsed = tick * self.period_cs if self.mode == "binary" else tick * self.period_ms // 10
        return (self.rtc_start_cs + elapsed) % RTC_WRAP_CS

    def _on_tick(self, block: bool) -> None:
        tick = self._tick
        self._tick += 1
        self.sim_stats.ticks += 1
        out = self.chip.read_outputs()
        rtc_cs = self._rtc_cs(tick)
        if self.mode == "ascii":
            wire = DataLogRecord(
                timestamp_ms=tick * self.period_ms,
                accel_mg=out.accel_mg,
                gyro_mdps=out.gyro_mdps,
                mag_mgauss=MAG_FIELD_MGAUSS,
                pressure_hpa=0.0,
                temperature_c=0.0,
                humidity_pct=0.0,
            ).format()
            flags = FLAG_ACC | FLAG_GYRO
            acc, gyro, temp = out.accel_mg, out.gyro_mdps, 0.0
        else:
            mask = self._streaming or 0
            flags = 0
            if mask & cmds.SensorMask.ACCELEROMETER:
                self._stale["acc"] = out.accel_mg
                flags |= FLAG_ACC if out.accel_new else 0
            if mask & cmds.SensorMask.GYROSCOPE:
                self._stale["gyro"] = out.gyro_mdps
                flags |= FLAG_GYRO if out.gyro_new else 0
            if mask & cmds.SensorMask.TEMPERATURE:
                self._stale["temp"] = float(np.float32(out.temp_c))
                flags |= FLAG_TEMP
            mag = MAG_FIELD_MGAUSS if mask & cmds.SensorMask.MAGNETOMETER else (0, 0, 0)
            flags |= FLAG_MAG if mask & cmds.SensorMask.MAGNETOMETER else 0
            acc = self._stale["acc"]  # type: ignore[assignment]
            gyro = self._stale["gyro"]  # type: ignore[assignment]
            temp = self._stale["temp"]  # type: ignore[assignment]
            h, rest = divmod(rtc_cs, 360000)
            m, rest = divmod(rest, 6000)
            s, cc = divmod(rest, 100)
            wire = encode_frame(
                StreamFrame(
                    host=self._host,
                    rtc=(h, m, s, cc),
                    pressure_hpa=0.0,
                    temperature_c=temp,
                    humidity_pct=0.0,
                    accel_mg=acc,
                    gyro_mdps=gyro,
                    mag_mgauss=mag,
                    flags=flags,
                ).pack()
            )
        sent = self._master is not None and (self.mode == "ascii" or self._streaming is not None)
        self._last_damaged = False
        if sent:
            sent = self._send(wire, block=block, faults=True)
            if sent:
                self.sim_stats.frames_sent += 1
            else:
                self.sim_stats.frames_busy += 1
        else:
            self.sim_stats.frames_unsent += 1
        if self.keep_log:
            self.sim_stats.log.append(
                SentFrame(tick, rtc_cs, gyro, acc, temp, flags, sent, wire, self._last_damaged)
            )

    def _apply_faults(self, wire: bytes) -> list[bytes]:
        f = self.faults
        data = np.frombuffer(wire, dtype=np.uint8).copy()
        n = len(data)
        k = 0
        if f.corrupt_rate > 0:
            hit = self._rng.random(n) < f.corrupt_rate
            k = int(hit.sum())
            if k:
                data[hit] ^= self._rng.integers(1, 256, k).astype(np.uint8)
                self.sim_stats.bytes_corrupted += k
        keep = np.ones(n, dtype=bool)
        if f.drop_rate > 0:
            keep = self._rng.random(n) >= f.drop_rate
            self.sim_stats.bytes_dropped += int(n - keep.sum())
        cuts: list[int] = []
        if f.split_rate > 0:
            cuts = list(np.nonzero(self._rng.random(n) < f.split_rate)[0] + 1)
            self.sim_stats.writes_split += len(cuts)
        self._last_damaged = bool(f.corrupt_rate > 0 and k) or bool(not keep.all())
        pieces = []
        prev = 0
        for cut in [*cuts, n]:
            seg = data[prev:cut][keep[prev:cut]]
            if len(seg):
                pieces.append(seg.tobytes())
            prev = cut
        return pieces

    def _send(self, wire: bytes, block: bool, faults: bool) -> bool:
        """Write ``wire`` to the pty master; in wall mode a full buffer drops the frame."""
        pieces = self._apply_faults(wire) if faults else [wire]
        return all(self._write(piece, block) for piece in pieces)

    def _write(self, data: bytes, block: bool) -> bool:
        view = memoryview(data)
        while view:
            master = self._master
            if master is None:
                return False
            try:
                n = os.write(master, view)
            except BlockingIOError:
                if not block:
                    return False
                self._lock.release()
                try:
                    if self._stop.is_set():
                        return False
                    with contextlib.suppress(OSError, ValueError):
                        select.select([], [master], [], 0.05)
                finally:
                    self._lock.acquire()
                continue
            except OSError:
                return False
            self.sim_stats.bytes_sent += n
            view = view[n:]
        return True
