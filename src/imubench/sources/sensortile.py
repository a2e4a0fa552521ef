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
(``time.monotonic`` since open) is in ``meta["host_t_s"]``; ``info.config["firmware_t0_s"]``
is the firmware stamp of index 0 (RTC seconds modulo 12 h, or DataLog ms / 1000). On a
wall-clock link the host
clock also guards the RTC (a reset RTC after a kit reboot re-anchors the index on the
host clock). Per-sample new-data flags are in ``meta["fresh"]`` (bool (n, 2): accel, gyro);
a frame whose flag is 0 repeats the previous value (the firmware samples on its own timer).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from lsm6ds.sensortile import commands as cmds
from lsm6ds.sensortile.datalog_ascii import DATA_PERIOD_MS, DataLogRecord
from lsm6ds.sensortile.link import LinkConfig, Received, SensorTileError, SensorTileLink
from lsm6ds.sensortile.stream import FLAG_ACC, FLAG_GYRO, FLAG_TEMP, RtcTimeline, StreamFrame

from imubench.batch import Batch
from imubench.errors import SourceError
from imubench.sources.base import Source, SourceInfo
from imubench.sources.registry import SourceURI, register_source

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
        self.info = SourceInfo(
            uri=uri,
            chip=chip,
            odr_hz=1.0 / period_s,
            config={"url": url, "mode": mode, "mask": mask, "period_s": period_s},
        )
        self._timeline: RtcTimeline | _AsciiTimeline | None = None
        self._last_index = -1
        self._host_t0 = 0.0
        self._done = False
        self._link_bad_seen = 0
        self.presentation: str | None = None

    # -- hooks ----------------------------------------------------------------------
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
        self._host_t0 = time.monotonic()
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
            return None
        while True:
            try:
                received = self.link.read_stream(self.max_batch, timeout_s=0.2)
            except SensorTileError as exc:
                raise SourceError(f"{self.info.uri}: {exc}") from exc
            self._sync_counters()
            batch = self._to_batch(received)
            self._sync_counters()
            if batch is not None:
                return batch
            if self._done:
                return None

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
        host: list[float] = []
        vals: list[tuple[float, ...]] = []
        temps: list[float] = []
        fresh: list[tuple[bool, bool]] = []
        for r in received:
            item = r.item
            if isinstance(item, StreamFrame):
                index = self._timeline.accept(item.rtc_cs, r.host_s)
                temp = item.temperature_c if self.mask & cmds.SensorMask.TEMPERATURE else np.nan
                if self.mask & cmds.SensorMask.TEMPERATURE and not item.flags & FLAG_TEMP:
                    temp = np.nan
                flags = (bool(item.flags & FLAG_ACC), bool(item.flags & FLAG_GYRO))
            else:
                assert isinstance(item, DataLogRecord)
                index = self._timeline.accept(item.timestamp_ms, r.host_s)
                temp = np.nan  # the DataLog temperature is the HTS221's, not the IMU's
                flags = (True, True)
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
                break
            g, a = item.gyro_mdps, item.accel_mg
            idx.append(index)
            t_s.append(elapsed)
            host.append(r.host_s - self._host_t0)
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
            fresh.append(flags)
        if not idx:
            return None
        index_arr = np.asarray(idx, dtype=np.int64)
        # the first accepted frame has index 0, so with _last_index = -1 the step is 0
        holes = np.diff(np.concatenate([[self._last_index], index_arr])) - 1
        lost_before = int(holes[0])
        self.counters["lost_samples"] += int(holes.sum())
        self.counters["gaps"] += int((holes > 0).sum())
        self._last_index = int(index_arr[-1])
        return Batch(
            index=index_arr,
            t_s=np.asarray(t_s, dtype=np.float64),
            values=np.asarray(vals, dtype=np.float64).reshape(-1, 6),
            temp_c=np.asarray(temps, dtype=np.float64),
            raw=None,
            lost_before=lost_before,
            meta={"host_t_s": np.asarray(host), "fresh": np.asarray(fresh, dtype=bool)},
        )


def _link_config(uri: SourceURI) -> LinkConfig:
    cfg = LinkConfig()
    cfg.reconnect_timeout_s = uri.get_float("reconnect_timeout_s", cfg.reconnect_timeout_s)  # type: ignore[assignment]
    cfg.backoff_max_s = uri.get_float("backoff_max_s", cfg.backoff_max_s)  # type: ignore[assignment]
    return cfg


_COMMON = {"mode", "duration_s", "period_ms", "reconnect_timeout_s", "backoff_max_s", "mask"}


@register_source("sensortile")
def open_sensortile(uri: SourceURI) -> SensorTileSource:
    """``sensortile://<pyserial url or device>?mode=binary|ascii&period_ms=&mask=&duration_s=``."""
    uri.check_known(_COMMON)
    if not uri.target:
        raise SourceError(
            f"source URI {uri.text!r} names no port; e.g. sensortile:///dev/ttyACM0 or "
            "sensortile:///dev/serial/by-id/usb-STMicroelectronics_...-if00"
        )
    mode = uri.get_choice("mode", ("binary", "ascii"), "binary")
    period_ms = uri.get_float("period_ms", 10.0 if mode == "binary" else float(DATA_PERIOD_MS))
    assert period_ms is not None
    return SensorTileSource(
        uri.text,
        uri.target,
        mode=mode,
        period_s=period_ms / 1000.0,
        mask=uri.get_int("mask", DEFAULT_MASK),  # type: ignore[arg-type]
        duration_s=uri.get_float("duration_s"),
        host_check_s=2.0,
        link_config=_link_config(uri),
    )


@register_source("sensortile-sim")
def open_sensortile_sim(uri: SourceURI) -> SensorTileSource:
    """``sensortile-sim://?mode=&seed=&clock=&model=&corrupt_rate=&drop_rate=&split_rate=&
    unplug_every_s=&replug_after_s=&max_unplugs=&duration_s=&period_ms=``."""
    from lsm6ds_sim.sensortile_chip import simulated_lsm6dsm
    from lsm6ds_sim.sensortile_fw import SensorTileFirmware, SerialFaults, make_clock

    uri.check_known(
        _COMMON
        | {
            "seed",
            "clock",
            "model",
            "corrupt_rate",
            "drop_rate",
            "split_rate",
            "unplug_every_s",
            "replug_after_s",
            "max_unplugs",
            "crystal_ppm",
        }
    )
    mode = uri.get_choice("mode", ("binary", "ascii"), "binary")
    clock_mode = uri.get_choice("clock", ("virtual", "wall"), "virtual")
    seed = uri.get_int("seed", 0)
    assert seed is not None
    period_ms = uri.get_float("period_ms", 10.0 if mode == "binary" else float(DATA_PERIOD_MS))
    assert period_ms is not None
    if mode == "binary" and (period_ms < 10 or period_ms % 10):
        raise SourceError(
            f"source URI {uri.text!r}: period_ms={period_ms:g} must be a multiple of 10 ms "
            "in binary mode (the RTC stamps frames in hundredths of a second)"
        )
    model = None
    model_path = uri.get_str("model")
    if model_path:
        from lsm6ds_sim.model import load_model

        model = load_model(model_path)
    try:
        faults = SerialFaults(
            corrupt_rate=uri.get_float("corrupt_rate", 0.0),  # type: ignore[arg-type]
            drop_rate=uri.get_float("drop_rate", 0.0),  # type: ignore[arg-type]
            split_rate=uri.get_float("split_rate", 0.0),  # type: ignore[arg-type]
            unplug_every_s=uri.get_float("unplug_every_s"),
            replug_after_s=uri.get_float("replug_after_s", 0.5),  # type: ignore[arg-type]
            max_unplugs=uri.get_int("max_unplugs"),
        )
    except ValueError as exc:
        raise SourceError(f"source URI {uri.text!r}: {exc}") from exc
    clock = make_clock(clock_mode)
    chip = simulated_lsm6dsm(clock, seed, model, crystal_ppm=uri.get_float("crystal_ppm", 0.0))  # type: ignore[arg-type]
    firmware = SensorTileFirmware(
        mode,
        chip,
        clock,
        seed=seed,
        faults=faults,
        period_cs=round(period_ms / 10) if mode == "binary" else 1,
        period_ms=round(period_ms),
    )
    cfg = _link_config(uri)
    return SensorTileSource(
        uri.text,
        firmware.url,
        mode=mode,
        period_s=period_ms / 1000.0,
        mask=uri.get_int("mask", DEFAULT_MASK),  # type: ignore[arg-type]
        duration_s=uri.get_float("duration_s"),
        host_check_s=2.0 if clock_mode == "wall" else None,
        link_config=cfg,
        firmware=firmware,
    )
