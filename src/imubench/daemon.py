"""``imubench run``: acquisition -> ring buffer -> recording + streaming Allan -> MQTT.

Threads and tasks:

* an acquisition thread reads the source and writes the ring buffer (a source may block:
  a wall-clock simulator, a serial port, an I2C FIFO poll);
* asyncio tasks, each with its own ring reader: the recorder (every sample, crash-safe
  file), the Allan engine (:class:`~imubench.stats.streaming.StreamingAllan`), the
  publisher (a JSON snapshot every ``mqtt.publish_interval_s``) and the live table.

SIGINT/SIGTERM (or ``run.duration_s``) stop the source, drain the ring into the
recording and the engine, close the recording, save the engine state when configured,
publish the retained ``offline`` status and stop the embedded broker.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime as dt
import logging
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from imubench.batch import CHANNELS, UNITS, Batch
from imubench.config import Config
from imubench.errors import ImubenchError
from imubench.recording import STORAGE_FLOAT, STORAGE_RAW, open_writer
from imubench.ringbuffer import RingBuffer, RingReader
from imubench.sources.base import Source
from imubench.sources.registry import open_source
from imubench.stats.streaming import StreamingAllan

log = logging.getLogger("imubench.daemon")


def _utc_stamp() -> str:
    return dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ")


class Acquisition(threading.Thread):
    """Reads the source until stopped or exhausted, writing every batch to the ring."""

    def __init__(self, source: Source, ring: RingBuffer, duration_s: float | None) -> None:
        super().__init__(name="imubench-acquisition", daemon=True)
        self.source = source
        self.ring = ring
        self.stop_event = threading.Event()
        self.max_samples = (
            None if duration_s is None else round(duration_s * source.info.odr_hz)
        )
        self.error: BaseException | None = None
        self.samples = 0

    def run(self) -> None:
        try:
            while not self.stop_event.is_set():
                batch = self.source.read()
                if batch is None:
                    break
                if self.max_samples is not None:
                    room = self.max_samples - self.samples
                    if room <= 0:
                        break
                    if len(batch) > room:
                        batch = _head(batch, room)
                self.ring.write(batch)
                self.samples += len(batch)
        except BaseException as exc:  # reported by the daemon, never swallowed
            self.error = exc
        finally:
            with contextlib.suppress(Exception):
                self.source.close()
            self.ring.close()


def _head(batch: Batch, n: int) -> Batch:
    return Batch(batch.index[:n], batch.t_s[:n], batch.values[:n], batch.temp_c[:n],
                 None if batch.raw is None else batch.raw[:n], batch.lost_before)


def _dense(batch: Batch, last_index: int | None, use_raw: bool) -> tuple[np.ndarray, np.ndarray]:
    """Samples on the full index grid (holes as gap rows) and the gap mask."""
    start = int(batch.index[0]) if last_index is None else last_index + 1
    span = int(batch.index[-1]) - start + 1
    src = batch.raw if use_raw else batch.values
    assert src is not None
    if span == len(batch):
        data = src
        mask = np.isnan(batch.values)
    else:
        data = np.zeros((span, 6), src.dtype) if use_raw else np.full((span, 6), np.nan)
        mask = np.ones((span, 6), bool)
        pos = batch.index - start
        data[pos] = src
        mask[pos] = np.isnan(batch.values)
    return data, mask


class Daemon:
    """The whole ``imubench run`` service for one sensor."""

    def __init__(self, config: Config, config_path: str | None = None,
                 out: TextIO | None = None) -> None:
        self.cfg = config
        self.config_path = config_path
        self.out = out or sys.stdout
        self.stop_requested = asyncio.Event()
        self.recording_path: Path | None = None
        self.broker_address: tuple[str, int] | None = None
        self.engine: StreamingAllan | None = None
        self.published = 0

    # -- helpers --------------------------------------------------------------------
    def say(self, text: str) -> None:
        print(text, file=self.out, flush=True)

    def _recording_path(self) -> Path:
        c = self.cfg
        return Path(c.log.path.format(station=c.mqtt.station, sensor=c.mqtt.sensor,
                                      start=_utc_stamp()))

    def _make_engine(self, source: Source, use_raw: bool) -> StreamingAllan:
        a = self.cfg.allan
        info = source.info
        scale = None
        if use_raw:
            g, acc = info.gyro_sensitivity_dps, info.accel_sensitivity_g
            scale = [g, g, g, acc, acc, acc]
        if a.state_path and Path(a.state_path).exists():
            try:
                eng = StreamingAllan.load_state(Path(a.state_path).read_bytes())
                if abs(eng.rate_hz - info.odr_hz) < 1e-9 and list(eng.stats) == [
                    s for s in a.stats
                ]:
                    self.say(f"resumed Allan state from {a.state_path} "
                             f"({eng.n_samples} samples)")
                    return eng
                self.say(f"ignoring {a.state_path}: it was made with other settings")
            except (ImubenchError, OSError, ValueError, KeyError) as exc:
                self.say(f"ignoring {a.state_path}: {exc}")
        taus: Any = a.taus
        if taus not in ("octave", "decade", "all"):
            taus = int(taus) if taus.isdigit() else [float(t) for t in taus.split(",")]
        return StreamingAllan(info.odr_hz, taus=taus, stats=a.stats, max_tau_s=a.max_tau_s,
                              memory=a.memory, scale=scale)

    def snapshot_payload(self, source: Source, acq: Acquisition) -> dict[str, Any]:
        """The ``allan`` MQTT payload (docs/mqtt.md): the first configured statistic in
        ``statistic``/``channels`` and every configured one under ``statistics``."""
        eng = self.engine
        stats = list(self.cfg.allan.stats)
        per_stat: dict[str, dict[str, Any]] = {s: {} for s in stats}
        if eng is not None and eng.n_samples:
            snap = eng.snapshot()
            for ch, res in zip(CHANNELS, snap, strict=True):  # type: ignore[arg-type]
                for s in stats:
                    r = res[s]
                    per_stat[s][ch] = {
                        "tau_s": r.tau_s, "dev": r.dev, "n": r.n, "ci_low": r.ci_low,
                        "ci_high": r.ci_high, "alpha": r.alpha, "edf": r.edf,
                        "units": UNITS[ch],
                    }
        return {
            "time": dt.datetime.now(dt.UTC).isoformat(timespec="milliseconds"),
            "station": self.cfg.mqtt.station, "sensor": self.cfg.mqtt.sensor,
            "chip": source.info.chip, "odr_hz": source.info.odr_hz,
            "samples": 0 if eng is None else eng.n_samples,
            "lost_samples": int(source.counters.get("lost_samples", 0)),
            "statistic": stats[0], "memory": self.cfg.allan.memory,
            "channels": per_stat[stats[0]],
            "statistics": per_stat,
        }

    # -- tasks --------------------------------------------------------------------------
    async def _consume(self, reader: RingReader, source: Source) -> None:
        """Recorder + engine: every sample goes to the file and the Allan engine."""
        writer = None
        last_index: int | None = None
        use_raw: bool | None = None
        try:
            while True:
                has = await reader.wait_async(0.2)
                res = reader.read(1 << 16)
                if res.missed:
                    log.error("consumer fell %d samples behind the ring buffer", res.missed)
                if res.batch is None:
                    if not has and reader.ring.closed:
                        return
                    continue
                batch = res.batch
                if use_raw is None:
                    use_raw = (batch.raw is not None
                               and source.info.gyro_sensitivity_dps is not None
                               and source.info.accel_sensitivity_g is not None)
                    self.engine = self._make_engine(source, use_raw)
                    if self.cfg.log.enabled:
                        writer = self._open_writer(source, use_raw)
                if res.missed and last_index is not None and writer is not None:
                    writer.write_gap(int(batch.index[0]), int(batch.index[0]) - last_index - 1,
                                     "ring buffer overrun")
                if writer is not None:
                    writer.write(batch)
                data, mask = _dense(batch, last_index, bool(use_raw))
                assert self.engine is not None
                self.engine.update(data, gaps=mask)
                last_index = int(batch.index[-1])
        finally:
            if writer is not None:
                writer.close()
                self.say(f"recording closed: {self.recording_path} ({writer.samples} samples, "
                         f"{writer.gaps} gaps)")

    def _open_writer(self, source: Source, use_raw: bool) -> Any:
        info = source.info
        path = self._recording_path()
        meta = {
            "chip": info.chip, "odr_hz": info.odr_hz, "fs_dps": info.fs_dps, "fs_g": info.fs_g,
            "gyro_sensitivity_dps": info.gyro_sensitivity_dps,
            "accel_sensitivity_g": info.accel_sensitivity_g,
            "source_uri": info.uri, "source_config": info.config,
            "config": self.cfg.model_dump(mode="json"),
            "station": self.cfg.mqtt.station, "sensor": self.cfg.mqtt.sensor,
            "storage": STORAGE_RAW if use_raw else STORAGE_FLOAT,
        }
        writer = open_writer(path, meta, fsync_interval_s=self.cfg.log.fsync_interval_s)
        self.recording_path = path
        self.say(f"recording to {path}")
        return writer

    async def _publish_loop(self, publisher: Any, source: Source, acq: Acquisition) -> None:
        interval = self.cfg.mqtt.publish_interval_s
        next_t = time.monotonic() + interval
        while not self.stop_requested.is_set():
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.stop_requested.wait(),
                                       max(0.0, next_t - time.monotonic()))
            next_t += interval
            if self.engine is None or not self.engine.n_samples:
                continue
            payload = self.snapshot_payload(source, acq)
            await publisher.publish_allan(payload)
            self.published += 1

    async def _display_loop(self, source: Source) -> None:
        interval = self.cfg.display.interval_s
        while not self.stop_requested.is_set():
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.stop_requested.wait(), interval)
            if self.engine is not None and self.engine.n_samples:
                self.out.write(live_table(self.engine, self.cfg.allan.stats[0], source))
                self.out.flush()

    # -- main ------------------------------------------------------------------------------
    async def run(self) -> int:
        cfg = self.cfg
        source = open_source(cfg.source.uri)
        source.open()
        info = source.info
        self.say(f"source {info.uri}: {info.chip} at {info.odr_hz:g} Hz")
        ring = RingBuffer(max(1024, round(cfg.buffer.capacity_s * info.odr_hz)))
        consumer_reader = ring.reader("recorder+engine")
        acq = Acquisition(source, ring, cfg.run.duration_s)

        broker = None
        from imubench.mqtt.publisher import MqttPublisher, parse_broker_url

        if cfg.mqtt.broker == "embedded":
            from imubench.mqtt.broker import EmbeddedBroker

            broker = EmbeddedBroker("127.0.0.1", cfg.mqtt.port)
            host, port = await broker.start()
            self.say(f"embedded MQTT broker listening on mqtt://{host}:{port}")
            tls = False
        else:
            addr = parse_broker_url(cfg.mqtt.broker)
            host, port, tls = addr.host, addr.port, addr.tls
        self.broker_address = (host, port)
        publisher = MqttPublisher(
            host, port, cfg.mqtt.station, cfg.mqtt.sensor, username=cfg.mqtt.username,
            password=cfg.mqtt.password, tls=tls, tls_ca=cfg.mqtt.tls_ca, qos=cfg.mqtt.qos,
            keepalive_s=cfg.mqtt.keepalive_s,
            status_detail={"chip": info.chip, "odr_hz": info.odr_hz, "source": info.uri},
        )
        from imubench.mqtt.topics import allan_topic

        self.say(f"publishing {', '.join(cfg.allan.stats)} snapshots to "
                 f"{allan_topic(cfg.mqtt.station, cfg.mqtt.sensor)}")
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError):
                loop.add_signal_handler(sig, self.stop_requested.set)
        show = cfg.display.live_table == "on" or (
            cfg.display.live_table == "auto" and self.out.isatty()
        )
        await publisher.__aenter__()  # starts its connect/publish/reconnect task
        acq.start()
        consumer = asyncio.create_task(self._consume(consumer_reader, source), name="consumer")
        tasks = [asyncio.create_task(self._publish_loop(publisher, source, acq))]
        if show:
            tasks.append(asyncio.create_task(self._display_loop(source)))
        acq_done = asyncio.create_task(asyncio.to_thread(acq.join))
        stop_wait = asyncio.create_task(self.stop_requested.wait())
        await asyncio.wait({acq_done, stop_wait, consumer}, return_when=asyncio.FIRST_COMPLETED)
        # -- shutdown: stop the source, drain, close, publish offline ---------------------
        acq.stop_event.set()
        with contextlib.suppress(Exception):
            source.close()
        self.stop_requested.set()
        await asyncio.to_thread(acq.join, 5.0)
        ring.close()
        await consumer
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        stop_wait.cancel()
        if self.engine is not None and self.engine.n_samples:
            await publisher.publish_allan(self.snapshot_payload(source, acq))
            if cfg.allan.state_path:
                path = Path(cfg.allan.state_path)
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = path.with_suffix(path.suffix + ".tmp")
                tmp.write_bytes(self.engine.save_state())
                tmp.replace(path)
        await publisher.close(timeout_s=1.0)
        if broker is not None:
            await broker.stop()
        if acq.error is not None:
            raise acq.error
        self.say(f"stopped after {acq.samples} samples; lost "
                 f"{source.counters.get('lost_samples', 0)}")
        return 0


def live_table(engine: StreamingAllan, stat: str, source: Source) -> str:
    """A compact terminal table: deviation per channel at about one tau per decade."""
    snap = engine.snapshot()
    first = snap[0][stat]  # type: ignore[index]
    if not len(first):
        return ""
    decades = sorted({int(np.floor(np.log10(t))) for t in first.tau_s})
    cols = [int(np.argmin(np.abs(np.log10(first.tau_s) - d))) for d in decades]
    head = f"{stat:>6} " + "".join(f"{first.tau_s[i]:>11.3g}s" for i in cols)
    lines = [f"\x1b[H\x1b[2J{source.info.chip} {source.info.odr_hz:g} Hz  "
             f"samples {engine.n_samples}  lost {source.counters.get('lost_samples', 0)}",
             head]
    for ch, res in zip(CHANNELS, snap, strict=True):  # type: ignore[arg-type]
        r = res[stat]
        vals = "".join(f"{r.dev[i]:>12.4g}" if i < len(r) else " " * 12 for i in cols)
        lines.append(f"{ch:>2} {UNITS[ch]:>3} {vals}")
    return "\n".join(lines) + "\n"


def run_daemon(config: Config, config_path: str | None = None) -> int:
    return asyncio.run(Daemon(config, config_path).run())
