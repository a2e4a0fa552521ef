"""SensorTile sources: ``sensortile://`` (a real kit, any pyserial URL) and ``sensortile-sim://``.

``sensortile:///dev/serial/by-id/usb-STMicroelectronics_...-if00?mode=binary`` opens a kit
running the DataLogExtended firmware (``mode=binary``, default) or the ASCII DataLog
(``mode=ascii``). Prefer the by-id symlink: after an unplug the link reconnects by
reopening the same name (:mod:`lsm6ds.sensortile.link`).

``sensortile-sim://?mode=binary|ascii&seed=0&clock=virtual|wall&model=PATH&corrupt_rate=0&
drop_rate=0&split_rate=0&unplug_every_s=&replug_after_s=0.5&duration_s=`` starts a simulated
kit (:class:`lsm6ds_sim.sensortile_fw.SensorTileFirmware`) on a pty and reads it through
the very same serial code.

Batches: the sample index counts the firmware's *frames* (binary: RTC stamp / frame
period; ascii: TimeStamp ms / record period), so a frame lost on the line is a hole
(``lost_samples``, ``gaps``) and a damaged one is also counted in ``bad_frames``. Values
are the firmware's int32 mg / mdps divided by 1000 (g, dps); ``raw`` is None because the
firmware sends scaled integers, not the chip's counts. ``t_s`` is the firmware RTC time
since the first frame (10 ms resolution; 12-hour wrap unwrapped); the host receive time
is not kept; ``info.config["firmware_t0_s"]``
is the firmware stamp of index 0 (RTC seconds modulo 12 h, or DataLog ms / 1000). On a
wall-clock link the host
clock also guards the RTC (a reset RTC after a kit reboot re-anchors the index on the
host clock). A frame whose new-data flag is 0 repeats the previous value (the firmware
samples on its own timer): such frames are delivered as they are (the kit's own output).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from lsm6ds.sensortile import commands as cmds
from lsm6ds.sensortile.datalog_ascii import DATA_PERIOD_MS, DataLogRecord
from lsm6ds.sensortile.link import (
    LinkConfig,
    LinkInterruptedError,
    Received,
    SensorTileError,
    SensorTileLink,
)
from lsm6ds.sensortile.stream import FLAG_TEMP, RtcTimeline, StreamFrame

from imubench.batch import Batch, Gap
from imubench.errors import SourceError
from imubench.sources.base import Source, SourceInfo
from imubench.sources.registry import (
    Backend,
    Param,
    SourceURI,
    check_model_param,
    register_backend,
)

DEFAULT_MASK = int(
    cmds.SensorMask.ACCELEROMETER | cmds.SensorMask.GYROSCOPE | cmds.SensorMask.TEMPERATURE
)
"""Sensors enabled by the source: accel, gyro, temperature (0x32)."""


class _AsciiTimeline:
    """Index from the DataLog ``TimeStamp`` (ms since boot, uint32): round(delta / period)."""

    def __init__(self, period_ms: float, host_check_s: float | None) -> None:
        self.period_ms = period_ms
        self.host_check_s = host_check_s
        self._last_ms: int | None = None
        self._last_host: float | None = None
        self._elapsed_ms = 0
        self.last_index = -1
        self.reanchors = 0

    def accept(self, ts_ms: int, host_s: float | None) -> int | None:
        if self._last_ms is None:
            self._last_ms, self._last_host, self.last_index = ts_ms, host_s, 0
            return 0
        delta = (ts_ms - self._last_ms) % (1 << 32)
        if self.host_check_s is not None and host_s is not None and self._last_host is not None:
            host_ms = (host_s - self._last_host) * 1000.0
            if abs(delta - host_ms) > self.host_check_s * 1000.0 + 0.1 * abs(host_ms):
                delta = max(round(host_ms), 1)  # the kit rebooted: TimeStamp restarted
                self.reanchors += 1
        if delta == 0 or delta > (1 << 31):
            return None
        index = round((self._elapsed_ms + delta) / self.period_ms)
        if index <= self.last_index:
            return None
        self._elapsed_ms += delta
        self._last_ms, self._last_host, self.last_index = ts_ms, host_s, index
        return index

    @property
    def elapsed_s(self) -> float:
        return self._elapsed_ms / 1000.0


class SensorTileSource(Source):
    """Batches from a SensorTile link (real or simulated).

    Args:
        uri: the URI text (recorded in :attr:`info`).
        url: the pyserial URL of the port.
        mode: ``binary`` or ``ascii``.
        period_s: nominal frame period of the firmware (binary 0.01, ascii 0.02).
        mask: sensors-enabled mask sent with START_DATA_STREAMING (binary).
        duration_s: stop after this much firmware time (None: endless).
        host_check_s: guard the firmware clock with the host clock (wall-clock links).
        link_config: link tunables (timeouts, backoff).
        firmware: a simulated firmware owned by this source (started on open, stopped on close).
        max_batch: most samples per batch.
    """

    def __init__(
        self,
        uri: str,
        url: str,
        *,
        mode: str = "binary",
        period_s: float | None = None,
        mask: int = DEFAULT_MASK,
        duration_s: float | None = None,
        host_check_s: float | None = 2.0,
        link_config: LinkConfig | None = None,
        firmware: Any | None = None,
        max_batch: int = 256,
        chip: str = "lsm6dsm",
        realtime: bool = True,
    ) -> None:
        super().__init__()
        if period_s is None:
            period_s = 0.01 if mode == "binary" else DATA_PERIOD_MS / 1000.0
        if period_s <= 0:
            raise SourceError(f"source URI {uri!r}: frame period {period_s} s must be > 0")
        self.url = url
        self.mode = mode
        self.period_s = period_s
        self.mask = mask
        self.duration_s = duration_s
        self.host_check_s = host_check_s
        self.firmware = firmware
        self.max_batch = max_batch
        self.link = SensorTileLink(url, mode, link_config)
        self.link.interrupted = self._interrupt  # a stop ends a reconnection at once
        self.info = SourceInfo(
            uri=uri,
            chip=chip,
            odr_hz=1.0 / period_s,
            realtime=realtime,
            config={"url": url, "mode": mode, "mask": mask, "period_s": period_s},
        )
        self._timeline: RtcTimeline | _AsciiTimeline | None = None
        self._last_index = -1
        self._last_frame_host_s = 0.0
        """Host time (``time.monotonic``) the newest delivered frame arrived, s."""
        self._tail: Gap | None = None
        """The frames lost before the end of a finite stream, still to be declared."""
        self._clock_t0 = 0.0
        """The kit's clock at the start (see :meth:`_past_end`), s."""
        self._host_t0 = 0.0
        self._done = False
        self._link_bad_seen = 0
        self.presentation: str | None = None

    # -- hooks ----------------------------------------------------------------------
    @property
    def elapsed_s(self) -> float:
        """Kit seconds (RTC) of the newest frame read since the stream started."""
        return 0.0 if self._timeline is None else self._timeline.elapsed_s

    def _open(self) -> None:
        if self.firmware is not None:
            self.firmware.start()
        try:
            self.link.open()
            if self.mode == "binary":
                self._identify()
            self.link.start_streaming(self.mask)
        except SensorTileError as exc:
            self._shutdown()
            raise SourceError(f"{self.info.uri}: {exc}") from exc
        self._host_t0 = self._last_frame_host_s = time.monotonic()
        self._clock_t0 = (self.firmware.clock.now() if self.firmware is not None
                          else self._host_t0)
        if self.mode == "binary":
            self._timeline = RtcTimeline(self.period_s * 100.0, self.host_check_s)
        else:
            self._timeline = _AsciiTimeline(self.period_s * 1000.0, self.host_check_s)
        self._last_index = -1
        self._done = False

    def _identify(self) -> None:
        """Presentation string, firmware id, full scales (stored in ``info.config``)."""
        self.presentation = self.link.presentation()
        fw_id = self.link.check_mode()
        if fw_id != cmds.DATALOG_EXT_MODE:
            raise SensorTileError(
                f"firmware id {fw_id} is not DataLogExtended ({cmds.DATALOG_EXT_MODE}); "
                "use mode=ascii for the DataLog application"
            )
        self.info.config["presentation"] = self.presentation
        try:
            fs_g = self.link.command(cmds.get_fs_request(cmds.SensorType.ACCELEROMETER))
            fs_dps = self.link.command(cmds.get_fs_request(cmds.SensorType.GYROSCOPE))
        except SensorTileError:
            return  # optional: older firmware may NACK sensor commands
        self.info.fs_g = float(int.from_bytes(fs_g.payload[2:6], "little"))
        self.info.fs_dps = float(int.from_bytes(fs_dps.payload[2:6], "little"))

    def _close(self) -> None:
        self._shutdown()

    def _shutdown(self) -> None:
        self.link.close()
        if self.firmware is not None:
            self.firmware.stop()

    def _read(self) -> Batch | None:
        if self._done:
            tail, self._tail = self._tail, None
            return None if tail is None else Batch.empty(with_raw=False, gaps=(tail,))
        while not self._interrupt.is_set():
            try:
                received = self.link.read_stream(self.max_batch, timeout_s=0.2)
            except LinkInterruptedError:
                break
            except SensorTileError as exc:
                raise SourceError(f"{self.info.uri}: {exc}") from exc
            self._sync_counters()
            batch = self._to_batch(received)
            self._sync_counters()
            if batch is not None:
                return batch
            if self._done:
                return None
            if self._past_end():
                return self._ended_without_frames()
        return self._stopped_in_outage()

    def _past_end(self) -> bool:
        """A finite stream's end has passed on the kit's clock (the simulated firmware's;
        the host's for a real kit) by more than a stall while no frame got through: a
        kit whose every frame was damaged never reached its end (0 lost, for ever)."""
        if self.duration_s is None:
            return False
        clock = self.firmware.clock.now() if self.firmware is not None else time.monotonic()
        margin = max(1.0, self.link.config.stall_timeout_s)
        return clock - self._clock_t0 > self.duration_s + margin

    def _ended_without_frames(self) -> Batch | None:
        """The end of a finite stream reached by the clock: the frames from the newest
        delivered to the end are lost."""
        self._done = True
        tail = self._lost_before_end(self._last_index, self._end_index)
        return None if tail is None else Batch.empty(with_raw=False, gaps=(tail,))

    @property
    def _end_index(self) -> int:
        """The first index past a finite stream's ``duration_s`` (0 when endless)."""
        return math.ceil(self.duration_s / self.period_s - 1e-9) if self.duration_s else 0

    @staticmethod
    def _lost_before_end(last: int, end: int) -> Gap | None:
        """The frames after index ``last`` up to ``end`` (exclusive), lost, or None."""
        return Gap(end, end - last - 1, "frames lost on the serial link") if end > last + 1 \
            else None

    def _lost_at_failure(self) -> Batch | None:
        """The frames lost in the outage that ended in a failure (the kit not back within
        ``reconnect_timeout_s``), counted as at a stop during it however short it was."""
        return self._stopped_in_outage(failed=True)

    def _stopped_in_outage(self, *, failed: bool = False) -> Batch | None:
        """At a stop: the frames the kit made since the newest one arrived, lost, when no
        frame came for longer than an outage allows (an unplug, a silent link), or at a
        failure (``failed``) whatever the time; None otherwise. A stop during an unplug
        reported 0 lost for the seconds it lasted. Counted from the host clock at the frame
        period, on a real-time link only (a virtual-clock simulator's firmware time is
        not the host's)."""
        self._done = True
        if not self.info.realtime:
            return None
        quiet = 0.0 if failed else max(1.0, self.link.config.stall_timeout_s)
        since = time.monotonic() - self._last_frame_host_s
        if since <= quiet:
            return None
        made = self._last_index + int(since / self.period_s)
        if made <= self._last_index:
            return None
        reason = "serial link down" if not self.link.is_open else "no frames from the kit"
        return Batch.empty(with_raw=False, gaps=(
            Gap(made + 1, made - self._last_index, reason),))

    # -- conversion -----------------------------------------------------------------
    def _sync_counters(self) -> None:
        lc = self.link.counters
        self.counters["bus_bytes"] = lc["bytes"]
        self.counters["io_errors"] = lc["io_errors"]
        self.counters["retries"] = lc["retries"]
        self.counters["reconnects"] = lc["reconnects"]
        new_bad = lc["bad_frames"] - self._link_bad_seen
        self._link_bad_seen = lc["bad_frames"]
        self.counters["bad_frames"] += new_bad

    def _to_batch(self, received: list[Received]) -> Batch | None:
        assert self._timeline is not None
        idx: list[int] = []
        t_s: list[float] = []
        vals: list[tuple[float, ...]] = []
        temps: list[float] = []
        tail: Gap | None = None
        received_at = self._last_frame_host_s
        for r in received:
            item = r.item
            if isinstance(item, StreamFrame):
                index = self._timeline.accept(item.rtc_cs, r.host_s)
                temp = item.temperature_c if self.mask & cmds.SensorMask.TEMPERATURE else np.nan
                if self.mask & cmds.SensorMask.TEMPERATURE and not item.flags & FLAG_TEMP:
                    temp = np.nan
            else:
                assert isinstance(item, DataLogRecord)
                index = self._timeline.accept(item.timestamp_ms, r.host_s)
                temp = np.nan  # the DataLog temperature is the HTS221's, not the IMU's
            if index is None:  # duplicate or implausible stamp
                self.counters["bad_frames"] += 1
                continue
            if index == 0:
                stamp_s = (
                    item.rtc_cs / 100.0
                    if isinstance(item, StreamFrame)
                    else item.timestamp_ms / 1000.0
                )
                self.info.config["firmware_t0_s"] = stamp_s
                self.info.config["host_t0_s"] = r.host_s
            elapsed = self._timeline.elapsed_s
            if self.duration_s is not None and elapsed >= self.duration_s - 1e-9:
                self._done = True
                # the frames between the newest delivered and the end never arrived
                tail = self._lost_before_end(idx[-1] if idx else self._last_index,
                                             min(index, self._end_index))
                break
            g, a = item.gyro_mdps, item.accel_mg
            received_at = r.host_s
            idx.append(index)
            t_s.append(elapsed)
            vals.append(
                (
                    g[0] / 1000.0,
                    g[1] / 1000.0,
                    g[2] / 1000.0,
                    a[0] / 1000.0,
                    a[1] / 1000.0,
                    a[2] / 1000.0,
                )
            )
            temps.append(float(temp))
        if not idx:
            return None if tail is None else Batch.empty(with_raw=False, gaps=(tail,))
        index_arr = np.asarray(idx, dtype=np.int64)
        # the first accepted frame has index 0, so with _last_index = -1 the step is 0
        holes = np.diff(np.concatenate([[self._last_index], index_arr])) - 1
        gaps = tuple(
            Gap(int(index_arr[k]), int(holes[k]), "frames lost on the serial link")
            for k in np.nonzero(holes > 0)[0]
        )
        self._tail = tail  # after the samples: in a batch of its own, read next
        self._last_index = int(index_arr[-1])
        self._last_frame_host_s = received_at
        return Batch(
            index=index_arr,
            t_s=np.asarray(t_s, dtype=np.float64),
            values=np.asarray(vals, dtype=np.float64).reshape(-1, 6),
            temp_c=np.asarray(temps, dtype=np.float64),
            raw=None,
            gaps=gaps,
        )


COMMON_PARAMS: tuple[Param, ...] = (
    Param("mode", str, "binary", "binary (DataLogExtended) or ascii (DataLog)",
          ("binary", "ascii")),
    Param("duration_s", float, None, "stop after this much firmware time, s"),
    Param("period_ms", float, None, "frame period, ms (binary 10, ascii 20)"),
    Param("reconnect_timeout_s", float, None, "give up re-opening an unplugged port after, s"),
    Param("backoff_max_s", float, None, "longest wait between re-open attempts, s"),
    Param("mask", int, DEFAULT_MASK, "sensors enabled (bit mask, binary mode)"),
)
SIM_PARAMS: tuple[Param, ...] = (
    *COMMON_PARAMS,
    Param("seed", int, 0, "random seed of the noise and the faults"),
    Param("clock", str, "virtual", "virtual (as fast as read) or wall (real time)",
          ("virtual", "wall")),
    Param("model", str, None, "noise model TOML file"),
    Param("corrupt_rate", float, 0.0, "probability a byte is corrupted"),
    Param("drop_rate", float, 0.0, "probability a byte vanishes"),
    Param("split_rate", float, 0.0, "probability a write is split"),
    Param("unplug_every_s", float, None, "unplug the kit this often, s"),
    Param("replug_after_s", float, 0.5, "and plug it back after, s"),
    Param("max_unplugs", int, None, "unplug at most this many times"),
    Param("crystal_ppm", float, 0.0, "oscillator frequency error, ppm"),
)


@dataclass(frozen=True)
class SensorTileOptions:
    mode: str
    period_ms: float
    values: dict[str, Any]


def _options(uri: SourceURI, params: tuple[Param, ...]) -> SensorTileOptions:
    v = uri.values(params)
    mode = v["mode"]
    period_ms = v["period_ms"] or (10.0 if mode == "binary" else float(DATA_PERIOD_MS))
    if period_ms <= 0:
        raise SourceError(f"source URI {uri.text!r}: period_ms={period_ms:g} must be > 0")
    for name in ("duration_s", "reconnect_timeout_s", "backoff_max_s"):
        if v[name] is not None and v[name] <= 0:
            raise SourceError(f"source URI {uri.text!r}: {name}={v[name]} must be > 0")
    return SensorTileOptions(mode, period_ms, v)


def _link_config(v: dict[str, Any]) -> LinkConfig:
    cfg = LinkConfig()
    if v["reconnect_timeout_s"] is not None:
        cfg.reconnect_timeout_s = v["reconnect_timeout_s"]
    if v["backoff_max_s"] is not None:
        cfg.backoff_max_s = v["backoff_max_s"]
    return cfg


def sensortile_options(uri: SourceURI) -> SensorTileOptions:
    opts = _options(uri, COMMON_PARAMS)
    if not uri.target:
        raise SourceError(
            f"source URI {uri.text!r} names no port; e.g. sensortile:///dev/ttyACM0 or "
            "sensortile:///dev/serial/by-id/usb-STMicroelectronics_...-if00"
        )
    return opts


def open_sensortile(uri: SourceURI, opts: SensorTileOptions) -> SensorTileSource:
    """``sensortile://<pyserial url or device>?mode=binary|ascii&period_ms=&mask=&duration_s=``."""
    v = opts.values
    return SensorTileSource(
        uri.text,
        uri.target,
        mode=opts.mode,
        period_s=opts.period_ms / 1000.0,
        mask=v["mask"],
        duration_s=v["duration_s"],
        host_check_s=2.0,
        link_config=_link_config(v),
    )


def sensortile_sim_options(uri: SourceURI) -> SensorTileOptions:
    opts = _options(uri, SIM_PARAMS)
    if opts.mode == "binary" and (opts.period_ms < 10 or opts.period_ms % 10):
        raise SourceError(
            f"source URI {uri.text!r}: period_ms={opts.period_ms:g} must be a multiple of "
            "10 ms in binary mode (the RTC stamps frames in hundredths of a second)"
        )
    v = opts.values
    check_model_param(uri, v["model"])
    _serial_faults(uri, v)
    return opts


def _serial_faults(uri: SourceURI, v: dict[str, Any]) -> Any:
    from lsm6ds_sim.sensortile_fw import SerialFaults

    try:
        return SerialFaults(
            corrupt_rate=v["corrupt_rate"], drop_rate=v["drop_rate"],
            split_rate=v["split_rate"], unplug_every_s=v["unplug_every_s"],
            replug_after_s=v["replug_after_s"], max_unplugs=v["max_unplugs"],
        )
    except ValueError as exc:
        raise SourceError(f"source URI {uri.text!r}: {exc}") from exc


def open_sensortile_sim(uri: SourceURI, opts: SensorTileOptions) -> SensorTileSource:
    """The simulated SensorTile firmware on a pty, read through the real serial code."""
    from lsm6ds_sim.clock import SimClock
    from lsm6ds_sim.model import load_model
    from lsm6ds_sim.sensortile_chip import simulated_lsm6dsm
    from lsm6ds_sim.sensortile_fw import SensorTileFirmware

    v = opts.values
    clock = SimClock(v["clock"])
    model = load_model(v["model"]) if v["model"] else None
    chip = simulated_lsm6dsm(clock, v["seed"], model, crystal_ppm=v["crystal_ppm"])
    firmware = SensorTileFirmware(
        opts.mode,
        chip,
        clock,
        seed=v["seed"],
        faults=_serial_faults(uri, v),
        period_cs=round(opts.period_ms / 10) if opts.mode == "binary" else 1,
        period_ms=round(opts.period_ms),
    )
    return SensorTileSource(
        uri.text,
        firmware.url,
        mode=opts.mode,
        period_s=opts.period_ms / 1000.0,
        mask=v["mask"],
        duration_s=v["duration_s"],
        host_check_s=2.0 if v["clock"] == "wall" else None,
        link_config=_link_config(v),
        firmware=firmware,
        realtime=v["clock"] == "wall",
    )


register_backend(Backend("sensortile", COMMON_PARAMS, sensortile_options, open_sensortile,
                         "a SensorTile running DataLogExtended or DataLog"))
register_backend(Backend("sensortile-sim", SIM_PARAMS, sensortile_sim_options,
                         open_sensortile_sim, "the simulated SensorTile firmware on a pty"))
