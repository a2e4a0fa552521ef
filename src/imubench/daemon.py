"""``imubench run``: the acquisition pipeline, published over MQTT, shown on a terminal.

Threads and tasks:

* the :class:`~imubench.pipeline.Pipeline` (:mod:`imubench.pipeline`): an acquisition
  thread reads the source into the ring buffer; the recorder
  (:class:`~imubench.recorder.Recorder`) and the Allan engine
  (:class:`~imubench.allan_consumer.AllanConsumer`) each read it in their own thread.
  Nothing heavy runs on the event loop: the engine's kernels are compiled (or loaded
  from the numba cache) in a worker thread before the source starts, and snapshots are
  computed by the engine's thread on request.
* asyncio tasks: the publisher (a JSON snapshot every ``mqtt.publish_interval_s`` on a
  fixed cadence: a slot missed while the machine was busy is skipped, never sent late in
  a burst) and the live table (with the broker address and the exact ``mosquitto_sub``
  command on screen).

The retained status says ``online`` within a second of start (``phase``: ``starting``
while kernels load, then ``acquiring``), and carries the recording state (``recording``,
or ``not recording: disk full ...`` until a new segment opens).

SIGINT/SIGTERM (or ``run.duration_s``, or the end of a finite source) stop the source;
the consumers drain the ring; the recording is closed; the engine state is saved when
configured; a final snapshot and the retained ``offline`` status are published.
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
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np

from imubench.batch import CHANNELS, UNITS
from imubench.calibration import Calibration, recording_header
from imubench.config import Config
from imubench.errors import ImubenchError
from imubench.pipeline import Consumer, Pipeline
from imubench.recorder import Recorder
from imubench.service import ServiceNotifier
from imubench.sources.base import SourceInfo
from imubench.sources.registry import open_source

if TYPE_CHECKING:  # imported in run(), after the status is online (numba takes a while)
    from imubench.allan_consumer import AllanConsumer, Snapshot
    from imubench.stats.streaming import StreamingAllan

log = logging.getLogger("imubench.daemon")

STOP_GRACE_S = 1.5
"""Longest wait for the pipeline to drain after a stop request, s."""
SNAPSHOT_LEAD = 0.25
"""A snapshot is asked for this share of the publish interval before it is sent."""


def _utc_stamp() -> str:
    return dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ")


def per_channel(snap: Snapshot) -> list[Mapping[str, Any]]:
    """A six-channel engine's snapshot: one mapping (statistic -> result) per channel."""
    if not isinstance(snap, list):
        raise TypeError("a six-channel engine returns one snapshot per channel")
    return snap


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
        self.engine_consumer: AllanConsumer | None = None
        self.recorder: Recorder | None = None
        self.pipeline: Pipeline | None = None
        self.published = 0
        self.skipped_slots = 0
        self.phase = "starting"
        self._publisher: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self.calibration: Calibration | None = None
        self.service = ServiceNotifier()
        """sd_notify to systemd (a no-op outside a ``Type=notify`` unit)."""

    # -- helpers --------------------------------------------------------------------
    def say(self, text: str) -> None:
        print(text, file=self.out, flush=True)

    @property
    def engine(self) -> StreamingAllan | None:
        return None if self.engine_consumer is None else self.engine_consumer.engine

    def _recording_path(self) -> Path:
        c = self.cfg
        return Path(c.log.path.format(station=c.mqtt.station, sensor=c.mqtt.sensor,
                                      start=_utc_stamp()))

    def _make_engine(self, info: SourceInfo, use_raw: bool) -> StreamingAllan:
        from imubench.stats.streaming import StreamingAllan

        a = self.cfg.allan
        scale = None
        if use_raw:
            assert info.gyro_sensitivity_dps is not None
            assert info.accel_sensitivity_g is not None
            g, acc = info.gyro_sensitivity_dps, info.accel_sensitivity_g
            scale = [g, g, g, acc, acc, acc]
        if a.state_path and Path(a.state_path).exists():
            try:
                eng = StreamingAllan.load_state(Path(a.state_path).read_bytes())
                if abs(eng.rate_hz - info.odr_hz) < 1e-9 and list(eng.stats) == list(a.stats):
                    self.say(f"resumed Allan state from {a.state_path} "
                             f"({eng.n_samples} samples)")
                    return eng
                self.say(f"ignoring {a.state_path}: it was made with other settings")
            except (ImubenchError, OSError, ValueError, KeyError) as exc:
                self.say(f"ignoring {a.state_path}: {exc}")
        return StreamingAllan(info.odr_hz, taus=a.tau_spec, stats=list(a.stats),
                              max_tau_s=a.max_tau_s, memory=a.memory, scale=scale)

    def health(self) -> dict[str, Any]:
        """Acquisition health for the snapshot payload: source telemetry, what each
        consumer received and lost (by reason), recording state and size."""
        p = self.pipeline
        if p is None:
            return {}
        tel = p.source.telemetry()
        out: dict[str, Any] = {
            "phase": self.phase,
            "produced": p.produced,
            "source": {k: v for k, v in tel.as_dict().items()},
            "consumers": {
                name: {"delivered": a.delivered, "lost": a.lost,
                       "lost_by_reason": dict(a.lost_by_reason)}
                for name, a in p.accounts().items()
            },
            "lag": p.lag(),
            "temperature_c": (None if self.engine_consumer is None
                              else self.engine_consumer.temperature_c),
            "snapshots_skipped": self.skipped_slots,
        }
        if self.recorder is not None:
            segs = self.recorder.segments
            out["recording"] = {
                "state": self.recorder.state,
                "path": str(segs[-1]) if segs else None,
                "segments": len(segs),
                "bytes": sum(s.stat().st_size for s in segs if s.exists()),
                "not_recorded": self.recorder.not_recorded,
            }
        return out

    def snapshot_payload(self, snap: Snapshot | None) -> dict[str, Any]:
        """The ``allan`` MQTT payload (docs/mqtt.md): the first configured statistic in
        ``statistic``/``channels`` and every configured one under ``statistics``."""
        stats = list(self.cfg.allan.stats)
        per_stat: dict[str, dict[str, Any]] = {s: {} for s in stats}
        if snap is not None:
            for ch, res in zip(CHANNELS, per_channel(snap), strict=True):
                for s in stats:
                    r = res[s]
                    per_stat[s][ch] = {
                        "tau_s": r.tau_s, "dev": r.dev, "n": r.n, "ci_low": r.ci_low,
                        "ci_high": r.ci_high, "alpha": r.alpha, "edf": r.edf,
                        "units": UNITS[ch],
                    }
        info = self.pipeline.info if self.pipeline is not None else None
        engine_account = (self.pipeline.accounts().get("engine")
                          if self.pipeline is not None else None)
        return {
            "time": dt.datetime.now(dt.UTC).isoformat(timespec="milliseconds"),
            "station": self.cfg.mqtt.station, "sensor": self.cfg.mqtt.sensor,
            "chip": info.chip if info else None, "odr_hz": info.odr_hz if info else None,
            "samples": self.engine.n_samples if self.engine is not None else 0,
            "lost_samples": engine_account.lost if engine_account is not None else 0,
            "statistic": stats[0], "memory": self.cfg.allan.memory,
            "channels": per_stat[stats[0]],
            "statistics": per_stat,
            "health": self.health(),
        }

    async def _snapshot(self) -> Snapshot | None:
        ec = self.engine_consumer
        if ec is None or not ec.n_samples:
            return None
        return await asyncio.wrap_future(ec.request_snapshot())

    # -- tasks --------------------------------------------------------------------------
    async def _publish_loop(self, publisher: Any) -> None:
        """A snapshot every interval on a fixed grid. The engine's thread computes it a
        little ahead of each tick (``SNAPSHOT_LEAD``) and the loop sends it on the tick,
        so the cadence does not depend on how long a snapshot takes; a tick missed while
        the machine was busy is skipped (``snapshots_skipped``), never sent late in a
        burst."""
        interval = self.cfg.mqtt.publish_interval_s
        lead = SNAPSHOT_LEAD * interval
        next_t = time.monotonic() + interval
        while not self.stop_requested.is_set():
            if await self._sleep_until(next_t - lead):
                return
            snap = await self._snapshot()
            if await self._sleep_until(next_t):
                return
            now = time.monotonic()
            late = int((now - next_t) // interval)
            if late > 0:
                self.skipped_slots += late
                next_t += late * interval
            next_t += interval
            if snap is None:
                continue
            await publisher.publish_allan(self.snapshot_payload(snap))
            self.published += 1

    async def _sleep_until(self, t: float) -> bool:
        """Sleep until monotonic time ``t``; True if a stop was requested meanwhile."""
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self.stop_requested.wait(), max(0.0, t - time.monotonic()))
        return self.stop_requested.is_set()

    async def _display_loop(self) -> None:
        interval = self.cfg.display.interval_s
        while not self.stop_requested.is_set():
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.stop_requested.wait(), interval)
            snap = await self._snapshot()
            self.out.write(self.live_table(snap))
            self.out.flush()

    def watch_command(self) -> str:
        """The exact command that watches this daemon's topics."""
        if self.broker_address is None:
            return ""
        host, port = self.broker_address
        topic = f"imubench/{self.cfg.mqtt.station}/{self.cfg.mqtt.sensor}/#"
        cmd = f"mosquitto_sub -h {host} -p {port} -t '{topic}' -v"
        if self.cfg.mqtt.username:
            cmd += f" -u {self.cfg.mqtt.username} -P '...'"
        return cmd

    def live_table(self, snap: Snapshot | None) -> str:
        """A compact terminal table: deviation per channel at about one tau per decade,
        under the broker address, the watch command and the acquisition counters."""
        stat = next(iter(self.cfg.allan.stats))
        p = self.pipeline
        head = [f"\x1b[H\x1b[2Jimubench run: {self.phase}"]
        if self.broker_address is not None:
            head.append(f"MQTT mqtt://{self.broker_address[0]}:{self.broker_address[1]}   "
                        f"watch: {self.watch_command()}")
        if p is not None:
            tel = p.source.telemetry()
            acc = p.accounts().get("engine")
            lost = acc.lost if acc is not None else 0
            head.append(f"{p.info.chip} {p.info.odr_hz:g} Hz  samples "
                        f"{self.engine.n_samples if self.engine is not None else 0}  lost "
                        f"{lost}  gaps {tel.gaps}  recording "
                        f"{self.recorder.state if self.recorder is not None else 'off'}")
        if snap is None:
            return "\n".join(head) + "\n"
        first = per_channel(snap)[0][stat]
        if not len(first):
            return "\n".join(head) + "\n"
        decades = sorted({int(np.floor(np.log10(t))) for t in first.tau_s})
        cols = [int(np.argmin(np.abs(np.log10(first.tau_s) - d))) for d in decades]
        lines = [*head, f"{stat:>6} " + "".join(f"{first.tau_s[i]:>11.3g}s" for i in cols)]
        for ch, res in zip(CHANNELS, per_channel(snap), strict=True):
            r = res[stat]
            vals = "".join(f"{r.dev[i]:>12.4g}" if i < len(r) else " " * 12 for i in cols)
            lines.append(f"{ch:>2} {UNITS[ch]:>3} {vals}")
        return "\n".join(lines) + "\n"

    def _on_recorder_state(self, state: str) -> None:
        """From the recorder's thread: raise the recording state on the status."""
        if state.startswith("not recording"):
            log.error("recording: %s", state)
        loop = self._loop
        if loop is not None and self._publisher is not None:
            loop.call_soon_threadsafe(
                lambda: asyncio.ensure_future(self._publish_status())
            )

    async def _publish_status(self) -> None:
        if self._publisher is None:
            return
        detail: dict[str, Any] = {"phase": self.phase}
        if self.pipeline is not None:
            info = self.pipeline.info
            detail.update(chip=info.chip, odr_hz=info.odr_hz, source=info.uri)
        if self.recorder is not None:
            detail["recording"] = self.recorder.state
        await self._publisher.publish_status(detail)

    # -- main ------------------------------------------------------------------------------
    async def run(self) -> int:
        cfg = self.cfg
        self._loop = asyncio.get_running_loop()
        self.calibration = (None if cfg.calibration.file is None
                            else Calibration.load(cfg.calibration.file))
        if cfg.log.enabled:
            self.recorder = Recorder(
                self._recording_path(),
                {"config": cfg.public_dump(), "station": cfg.mqtt.station,
                 "sensor": cfg.mqtt.sensor,
                 "calibration": recording_header(self.calibration)},
                fsync_interval_s=cfg.log.fsync_interval_s, on_state=self._on_recorder_state,
            )

        broker = None
        from imubench.mqtt.publisher import MqttPublisher, parse_broker_url
        from imubench.mqtt.topics import allan_topic, base_topic

        if cfg.mqtt.broker == "embedded":
            from imubench.mqtt.broker import EmbeddedBroker

            # With mqtt.username/password the embedded broker requires them, and only this
            # daemon's user may publish, only under its own imubench/<station>/<sensor>/.
            users = None if cfg.mqtt.username is None or cfg.mqtt.password is None else {
                cfg.mqtt.username: cfg.mqtt.password.get_secret_value()}
            broker = EmbeddedBroker(
                "127.0.0.1", cfg.mqtt.port, users=users,
                publish_rights=None if cfg.mqtt.username is None else {
                    cfg.mqtt.username: [f"{base_topic(cfg.mqtt.station, cfg.mqtt.sensor)}/#"]},
            )
            host, port = await broker.start()
            self.say(f"embedded MQTT broker listening on mqtt://{host}:{port}")
            tls = False
        else:
            addr = parse_broker_url(cfg.mqtt.broker)
            host, port, tls = addr.host, addr.port, addr.tls
        self.broker_address = (host, port)
        publisher = MqttPublisher(
            host, port, cfg.mqtt.station, cfg.mqtt.sensor, username=cfg.mqtt.username,
            password=None if cfg.mqtt.password is None else cfg.mqtt.password.get_secret_value(),
            tls=tls, tls_ca=cfg.mqtt.tls_ca, tls_cert=cfg.mqtt.tls_cert,
            tls_key=cfg.mqtt.tls_key, tls_insecure=cfg.mqtt.tls_insecure, qos=cfg.mqtt.qos,
            keepalive_s=cfg.mqtt.keepalive_s, backlog_snapshots=cfg.mqtt.backlog_snapshots,
            status_detail={"phase": self.phase, "source": cfg.source.uri},
        )
        self._publisher = publisher
        self.say(f"publishing {', '.join(cfg.allan.stats)} snapshots to "
                 f"{allan_topic(cfg.mqtt.station, cfg.mqtt.sensor)}")
        self.say(f"watch them with: {self.watch_command()}")
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError):
                loop.add_signal_handler(sig, self.stop_requested.set)
        show = cfg.display.live_table == "on" or (
            cfg.display.live_table == "auto" and self.out.isatty()
        )
        await publisher.__aenter__()  # starts its connect/publish/reconnect task
        view = None
        error: BaseException | None = None
        tasks: list[asyncio.Task[None]] = []
        try:
            view = await self._start_view(f"{'mqtts' if tls else 'mqtt'}://{host}:{port}")
            started = await self._start_pipeline()
            pipeline = self.pipeline
            if started:
                assert pipeline is not None
                self.phase = "acquiring"
                await self._publish_status()
                info = pipeline.info
                self.service.ready(f"acquiring {info.chip} at {info.odr_hz:g} Hz from "
                                   f"{info.uri}")
                if self.recorder is not None:
                    self.recording_path = self.recorder.path
                    self.say(f"recording to {self.recorder.path}")
                tasks.append(asyncio.create_task(self._publish_loop(publisher)))
                if show:
                    tasks.append(asyncio.create_task(self._display_loop()))
                await self._wait_end(pipeline)
        except BaseException as exc:
            error = exc
        finally:
            self.stop_requested.set()
            self.service.stopping("stopping: draining the pipeline")
            pipeline = self.pipeline
            if pipeline is not None:
                pipeline.stop()
                drained = await asyncio.to_thread(pipeline.join, STOP_GRACE_S)
                if not drained:
                    log.warning("pipeline still draining after %.1f s; stopping anyway",
                                STOP_GRACE_S)
            for t in tasks:
                t.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            self.phase = "stopped"
            if view is not None:
                await view.stop()
            await self._finish(publisher, broker)
        if pipeline is not None:
            error = error or pipeline.error or next(
                iter(pipeline.consumer_errors().values()), None)
        if error is not None:
            raise error
        if pipeline is None:
            self.say("stopped before the acquisition started")
            return 0
        acc = pipeline.accounts()
        rec = acc.get("recorder")
        eng = acc.get("engine")
        self.say(
            f"stopped after {pipeline.produced} samples produced; engine "
            f"{eng.delivered if eng else 0} delivered, {eng.lost if eng else 0} lost"
            + (f"; recording {rec.delivered - self.recorder.not_recorded} written, "
               f"{rec.lost + self.recorder.not_recorded} lost"
               if rec is not None and self.recorder is not None else "")
        )
        return 0

    def _build_pipeline(self) -> Pipeline:
        """The source, the recorder and the Allan engine (imports the simulator, scipy and
        numba: run it off the event loop, before the stream starts)."""
        from imubench.allan_consumer import AllanConsumer

        source = open_source(self.cfg.source.uri)
        info = source.info
        self.say(f"source {info.uri}: {info.chip} at {info.odr_hz:g} Hz")

        self.engine_consumer = AllanConsumer(self._make_engine)
        consumers: list[Consumer] = [self.engine_consumer]
        if self.recorder is not None:
            consumers.insert(0, self.recorder)
        cal = self.calibration
        return Pipeline(source, consumers, capacity_s=self.cfg.buffer.capacity_s,
                        duration_s=self.cfg.run.duration_s,
                        transform=None if cal is None else cal.apply)

    async def _start_pipeline(self) -> bool:
        """Build and prepare the pipeline (import and compile the kernels, open the
        recording) in a worker thread while the loop stays responsive, then start it;
        False when a stop came first."""
        done = threading.Event()
        failure: list[BaseException] = []

        def prepare() -> None:
            try:
                self.pipeline = self._build_pipeline()
                self.pipeline.prepare()
            except BaseException as exc:
                failure.append(exc)
            finally:
                done.set()

        worker = threading.Thread(target=prepare, name="imubench-prepare", daemon=True)
        t0 = time.monotonic()
        worker.start()
        warned = False
        while not done.is_set():
            if self.stop_requested.is_set():
                return False
            if self.service.watchdog_due():  # compiling is progress too
                self.service.watchdog()
            if not warned and time.monotonic() - t0 > 3.0:
                self.say("compiling the statistics kernels (first start on this machine; "
                         "`python3 dev.py setup` does it ahead)")
                warned = True
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.stop_requested.wait(), 0.05)
        if failure:
            raise failure[0]
        if self.stop_requested.is_set() or self.pipeline is None:
            return False
        self.pipeline.start()
        return True

    async def _start_view(self, broker_url: str) -> Any:
        """The live view (``[web] enabled``), subscribed to this daemon's broker."""
        web = self.cfg.web
        if not web.enabled:
            return None
        from imubench.web import LiveView, ViewOptions

        mqtt = self.cfg.mqtt
        view = LiveView(ViewOptions(
            broker=broker_url, listen=web.listen, user=web.user,
            password=None if web.password is None else web.password.get_secret_value(),
            mqtt_username=mqtt.username,
            mqtt_password=None if mqtt.password is None else mqtt.password.get_secret_value(),
            tls_ca=mqtt.tls_ca,
        ))
        host, port = await view.start()
        self.say(f"live view on http://{host}:{port}/")
        return view

    async def _wait_end(self, pipeline: Pipeline) -> None:
        """Until the stream ends, a stop, or an error. The systemd watchdog is fed only
        while the acquisition thread is alive and the event loop turns, so a hung
        acquisition or loop gets the service restarted."""
        while not self.stop_requested.is_set() and not pipeline.done:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.stop_requested.wait(), 0.1)
            if pipeline.error is not None or pipeline.consumer_errors():
                return
            if pipeline.running and self.service.watchdog_due():
                self.service.watchdog()

    async def _finish(self, publisher: Any, broker: Any) -> None:
        cfg = self.cfg
        ec = self.engine_consumer
        if ec is not None and ec.n_samples and ec.engine is not None:
            with contextlib.suppress(Exception):
                snap = await asyncio.wait_for(self._snapshot(), 1.0)
                await publisher.publish_allan(self.snapshot_payload(snap))
            if cfg.allan.state_path:
                path = Path(cfg.allan.state_path)
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = path.with_suffix(path.suffix + ".tmp")
                tmp.write_bytes(ec.engine.save_state())
                tmp.replace(path)
        await publisher.close(timeout_s=1.0)
        if broker is not None:
            await broker.stop()
        if self.recorder is not None and self.recorder.segments:
            self.say(f"recording closed: {', '.join(map(str, self.recorder.segments))} "
                     f"({self.recorder.samples} samples, {self.recorder.gap_records} gaps)")


def run_daemon(config: Config, config_path: str | None = None) -> int:
    return asyncio.run(Daemon(config, config_path).run())
