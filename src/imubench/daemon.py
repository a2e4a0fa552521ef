"""``imubench run``: the acquisition pipelines of one or several sensors, published over
MQTT, shown on a terminal.

Threads and tasks:

* per sensor (:class:`~imubench.sensorrun.SensorRun`) a
  :class:`~imubench.pipeline.Pipeline` (:mod:`imubench.pipeline`): an acquisition thread
  reads the source into the ring buffer; the recorder
  (:class:`~imubench.recorder.Recorder`) and the Allan engine
  (:class:`~imubench.allan_consumer.AllanConsumer`) each read it in their own thread.
  Nothing heavy runs on the event loop: the engines' kernels are compiled (or loaded
  from the numba cache) in a worker thread before the sources start, and snapshots are
  computed by each engine's thread on request.
* asyncio tasks: per sensor a publish loop (a JSON snapshot every
  ``mqtt.publish_interval_s`` on a fixed cadence: a slot missed while the machine was
  busy is skipped, never sent late in a burst), one publisher (one broker connection for
  all sensors; with several, the connection's last will is the node's status) and the
  live table (with the broker address and the exact ``mosquitto_sub`` command on
  screen).

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
import logging
import math
import os
import signal
import sys
import threading
import time
from typing import Any, TextIO

from imubench.config import Config
from imubench.errors import ImubenchError
from imubench.pipeline import NOT_PROCESSED
from imubench.sensorrun import SensorRun, utc_stamp
from imubench.service import ServiceNotifier

log = logging.getLogger("imubench.daemon")

STOP_GRACE_S = 1.5
"""Longest wait for the pipeline to drain after a stop request, s; a consumer still
behind then is cut short (:meth:`imubench.pipeline.Pipeline.cut_short`)."""
CUT_JOIN_S = 60.0
"""Longest wait, once cut short, for a consumer to finish the batch in hand, s."""
STATE_SAVE_S = 30.0
"""Longest wait for the engine state to be made and written, s."""
PACKET_HEADROOM_BYTES = 4096
"""Bytes of an MQTT PUBLISH packet besides its payload allowed for: fixed header, topic,
packet id (the topic is under 300 bytes)."""
PREPARE_JOIN_S = 1.0
"""Longest wait, after a stop request, for the sensor being prepared to finish, s."""
SNAPSHOT_LEAD = 0.25
"""A snapshot is asked for this share of the publish interval before it is sent."""
SNAPSHOT_DUTY = 0.25
"""Largest share of the engine thread's time that snapshots may take: the ticks after a
snapshot that cost ``c`` seconds are skipped until ``c / SNAPSHOT_DUTY`` has passed since
it was asked for (:func:`next_tick`)."""


def next_tick(next_t: float, interval: float, lead: float, asked_at: float, cost: float
              ) -> tuple[float, int]:
    """(the tick after ``next_t`` whose snapshot may be asked for, ticks skipped to reach
    it): the next one on the grid, or a later one so that snapshots take at most
    :data:`SNAPSHOT_DUTY` of the engine's thread. A snapshot is computed in that thread,
    between batches: at 6660 Hz with eight exact statistics one took 0.48 s, and at a
    0.2 s publish interval the engine did little else and lost two samples in three to
    its own overrun (an outside reviewer's daemon)."""
    t = next_t + interval
    free_at = asked_at + cost / SNAPSHOT_DUTY
    if t - lead >= free_at:
        return t, 0
    skip = math.ceil((free_at - (t - lead)) / interval)
    return t + skip * interval, skip



class Daemon:
    """The whole ``imubench run`` service: one or several sensors (``[[sensors]]``)."""

    def __init__(self, config: Config, config_path: str | None = None,
                 out: TextIO | None = None) -> None:
        self.cfg = config
        self.config_path = config_path
        self.out = out or sys.stdout
        self.stop_requested = asyncio.Event()
        self.broker_address: tuple[str, int] | None = None
        self.sensors: list[SensorRun] = []
        self.phase = "starting"
        self._publisher: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self.service = ServiceNotifier()
        """sd_notify to systemd (a no-op outside a ``Type=notify`` unit)."""
        self.abandoned: threading.Thread | None = None
        """The preparing thread, when a stop came and it did not finish in time."""
        self._state_saves: set[asyncio.Task[None]] = set()
        """Periodic engine-state saves in flight (awaited before the final one)."""

    # -- helpers --------------------------------------------------------------------
    def say(self, text: str) -> None:
        print(text, file=self.out, flush=True)

    @property
    def several(self) -> bool:
        return bool(self.cfg.sensors)

    def _set_phase(self, phase: str) -> None:
        self.phase = phase
        for unit in self.sensors:
            unit.phase = phase

    # -- tasks --------------------------------------------------------------------------
    async def _publish_loop(self, unit: SensorRun, publisher: Any) -> None:
        """A snapshot of ``unit`` every interval on a fixed grid. The engine's thread
        computes it a little ahead of each tick (``SNAPSHOT_LEAD``) and the loop sends it
        on the tick, so the cadence does not depend on how long a snapshot takes; a tick
        missed while the machine was busy, or skipped so that snapshots take at most
        ``SNAPSHOT_DUTY`` of the engine's time (:func:`next_tick`), is counted
        (``snapshots_skipped``), never sent late in a burst. The periodic state save runs
        beside the loop (one at a time), so a slow disk never delays a snapshot."""
        interval = self.cfg.mqtt.publish_interval_s
        lead = SNAPSHOT_LEAD * interval
        next_t = time.monotonic() + interval
        every = self.cfg.allan.state_every_s
        next_save = time.monotonic() + every
        saving: asyncio.Task[None] | None = None
        while not self.stop_requested.is_set():
            if await self._sleep_until(next_t - lead):
                return
            asked_at = time.monotonic()
            snap = await unit.snapshot()
            cost = time.monotonic() - asked_at
            if await self._sleep_until(next_t):
                return
            now = time.monotonic()
            late = int((now - next_t) // interval)
            if late > 0:
                unit.skipped_slots += late
                next_t += late * interval
            next_t, skipped = next_tick(next_t, interval, lead, asked_at, cost)
            unit.skipped_slots += skipped
            if snap is None:
                continue
            await publisher.publish_allan(self._payload(unit, snap), unit.name)
            for line in unit.fault_lines(now):
                log.warning("%s", line)
            if every > 0 and now >= next_save and (saving is None or saving.done()):
                next_save = now + every
                saving = asyncio.create_task(self._save_state(unit))
                self._state_saves.add(saving)
                saving.add_done_callback(self._state_saves.discard)

    @staticmethod
    async def _save_state(unit: SensorRun) -> None:
        """``unit``'s engine state to ``allan.state_path``, a failure logged, not raised
        (the acquisition goes on; the next save tries again)."""
        try:
            await asyncio.wait_for(unit.save_state(), STATE_SAVE_S)
        except (OSError, ImubenchError, TimeoutError) as exc:
            log.warning("%s: could not save the engine state: %s", unit.name,
                        str(exc) or "no answer from the engine in time")

    def _payload(self, unit: SensorRun, snap: Any) -> dict[str, Any]:
        """The snapshot payload with the broker link's health (``health.mqtt``); the
        publisher adds its sequence number (``seq``: 0, 1, ... per sensor and run, so a
        subscriber counts what it missed or got twice)."""
        payload = unit.snapshot_payload(snap)
        unit.published += 1  # the publisher adds ``seq``, counted per sensor
        pub = self._publisher
        payload["health"]["mqtt"] = {
            "connected": pub.connected, "connections": pub.connections,
            "published_snapshots": pub.published_snapshots,
            "dropped_snapshots": pub.dropped_snapshots,
            "oversize_snapshots": pub.oversize_snapshots,
            "backlog_snapshots": pub.buffered_snapshots,
        }
        return payload

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
            snaps = [await unit.snapshot() for unit in self.sensors]
            self.out.write(self.live_table(snaps))
            self.out.flush()

    def watch_command(self) -> str:
        """The exact command that watches this daemon's topics."""
        if self.broker_address is None:
            return ""
        host, port = self.broker_address
        who = "+" if self.several else self.cfg.mqtt.sensor
        topic = f"imubench/{self.cfg.mqtt.station}/{who}/#"
        cmd = f"mosquitto_sub -h {host} -p {port} -t '{topic}' -v"
        if self.cfg.mqtt.username:
            cmd += f" -u {self.cfg.mqtt.username} -P '...'"
        return cmd

    def live_table(self, snaps: list[Any]) -> str:
        """A compact terminal table: under the broker address, the watch command, per
        sensor its counters and deviation per channel at about one tau per decade."""
        lines = [f"\x1b[H\x1b[2Jimubench run: {self.phase}"]
        if self.broker_address is not None:
            lines.append(f"MQTT mqtt://{self.broker_address[0]}:{self.broker_address[1]}   "
                         f"watch: {self.watch_command()}")
        for unit, snap in zip(self.sensors, snaps, strict=True):
            lines.extend(unit.table(snap))
        return "\n".join(lines) + "\n"

    def _on_recorder_state(self, unit: SensorRun, state: str) -> None:
        """From a recorder's thread: raise the recording state on the sensor's status."""
        if state.startswith("not recording"):
            log.error("%s recording: %s", unit.name, state)
        loop = self._loop
        if loop is not None and self._publisher is not None:
            loop.call_soon_threadsafe(
                lambda: asyncio.ensure_future(self._publish_status(unit))
            )

    async def _publish_status(self, unit: SensorRun) -> None:
        if self._publisher is not None:
            await self._publisher.publish_status(unit.status_detail(), unit.name)

    # -- main ------------------------------------------------------------------------------
    async def run(self) -> int:
        cfg = self.cfg
        self._loop = asyncio.get_running_loop()
        start = utc_stamp()
        self.sensors = [SensorRun(cfg, spec, start=start, say=self.say,
                                  on_recorder_state=self._on_recorder_state)
                        for spec in cfg.sensor_specs()]

        broker = None
        from imubench.mqtt.publisher import MqttPublisher, parse_broker_url
        from imubench.mqtt.topics import allan_topic, base_topic, node_status_topic

        if cfg.mqtt.broker == "embedded":
            from imubench.mqtt.broker import EmbeddedBroker

            # With mqtt.username/password the embedded broker requires them, and only this
            # daemon's user may publish, only under its own imubench/<station>/<sensor>/
            # (and its node status).
            users = None if cfg.mqtt.username is None or cfg.mqtt.password is None else {
                cfg.mqtt.username: cfg.mqtt.password.get_secret_value()}
            own = [f"{base_topic(cfg.mqtt.station, unit.name)}/#" for unit in self.sensors]
            if self.several:
                own.append(node_status_topic(cfg.mqtt.station, cfg.mqtt.node_name))
            broker = EmbeddedBroker(
                "127.0.0.1", cfg.mqtt.port, users=users,
                publish_rights=None if cfg.mqtt.username is None else {cfg.mqtt.username: own},
            )
            host, port = await broker.start()
            self.say(f"embedded MQTT broker listening on mqtt://{host}:{port}")
            tls = False
        else:
            addr = parse_broker_url(cfg.mqtt.broker)
            host, port, tls = addr.host, addr.port, addr.tls
        self.broker_address = (host, port)
        names = [unit.name for unit in self.sensors]
        publisher = MqttPublisher(
            host, port, cfg.mqtt.station, names if self.several else names[0],
            node=cfg.mqtt.node_name if self.several else None,
            username=cfg.mqtt.username,
            password=None if cfg.mqtt.password is None else cfg.mqtt.password.get_secret_value(),
            tls=tls, tls_ca=cfg.mqtt.tls_ca, tls_cert=cfg.mqtt.tls_cert,
            tls_key=cfg.mqtt.tls_key, tls_insecure=cfg.mqtt.tls_insecure, qos=cfg.mqtt.qos,
            keepalive_s=cfg.mqtt.keepalive_s, backlog_snapshots=cfg.mqtt.backlog_snapshots,
            max_payload_bytes=(None if broker is None
                               else broker.max_packet_size - PACKET_HEADROOM_BYTES),
        )
        for unit in self.sensors:
            await publisher.publish_status(unit.status_detail(), unit.name)
        self._publisher = publisher
        for unit in self.sensors:
            self.say(f"publishing {', '.join(cfg.allan.stats)} snapshots to "
                     f"{allan_topic(cfg.mqtt.station, unit.name)}")
        if self.several:
            self.say(f"node status (the connection's last will): "
                     f"{node_status_topic(cfg.mqtt.station, cfg.mqtt.node_name)}")
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
        started = False
        try:
            view = await self._start_view(f"{'mqtts' if tls else 'mqtt'}://{host}:{port}")
            started = await self._start_pipelines()
            if started:
                self._set_phase("acquiring")
                for unit in self.sensors:
                    await self._publish_status(unit)
                self.service.ready("acquiring " + "; ".join(
                    f"{u.pipeline.info.chip} at {u.pipeline.info.odr_hz:g} Hz from "
                    f"{u.pipeline.info.uri}" for u in self.sensors if u.pipeline is not None))
                for unit in self.sensors:
                    if unit.recorder is not None:
                        unit.say(f"recording to {unit.recorder.path}")
                    tasks.append(asyncio.create_task(self._publish_loop(unit, publisher)))
                if show:
                    tasks.append(asyncio.create_task(self._display_loop()))
                await self._wait_end()
        except BaseException as exc:
            error = exc
        finally:
            self.stop_requested.set()
            self.service.stopping("stopping: draining the pipelines")
            pipelines = [u.pipeline for u in self.sensors if u.pipeline is not None]
            for pipeline in pipelines:
                pipeline.stop()
            deadline = time.monotonic() + STOP_GRACE_S
            for pipeline in pipelines:
                left = max(0.0, deadline - time.monotonic())
                if not await asyncio.to_thread(pipeline.join, left):
                    cut = pipeline.cut_short()
                    # a consumer with nothing left to take is not behind: the source's
                    # read has not returned (an outside reviewer's 11 s simulated bus
                    # stall read "engine cut short", then "engine 0 samples")
                    lagging = [n for n, lag in cut.items() if lag > 0]
                    log.warning("pipeline %s still draining %.1f s after the stop%s",
                                pipeline.info.uri, STOP_GRACE_S,
                                f": {', '.join(lagging)} cut short, what it has not taken "
                                f"is counted lost ({NOT_PROCESSED})" if lagging
                                else "; the source's read has not returned yet"
                                if pipeline.running else "; waiting for the recording")
                    if not await asyncio.to_thread(pipeline.join, CUT_JOIN_S):
                        log.error("pipeline %s: a consumer is still busy %.0f s after it was "
                                  "cut short; its account below is incomplete",
                                  pipeline.info.uri, CUT_JOIN_S)
                    else:  # the count, not the lag at the cut: an overrun part of that
                        # lag is counted as the overrun (an outside reviewer: "engine 6656
                        # samples" here, 4096 in the final account)
                        acc = pipeline.accounts()
                        counted = {n: acc[n].lost_by_reason.get(f"{NOT_PROCESSED}: {n}", 0)
                                   for n in cut}
                        if any(counted.values()):
                            log.warning("pipeline %s: counted lost (%s): %s",
                                        pipeline.info.uri, NOT_PROCESSED, ", ".join(
                                            f"{n} {k} samples" for n, k in counted.items()
                                            if k))
            for t in tasks:
                t.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            self._set_phase("stopped")
            if view is not None:
                await view.stop()
            await self._finish(publisher, broker)
        for unit in self.sensors:
            p = unit.pipeline
            if p is not None:
                error = error or p.error or next(iter(p.consumer_errors().values()), None)
        if started:  # the account of every sample, also when a source failed
            for unit in self.sensors:
                self.say(unit.summary())
        else:  # also when a source failed while it was set up: nothing was produced
            self.say("stopped before the acquisition started")
        if error is not None:
            raise error
        return 0

    async def _start_pipelines(self) -> bool:
        """Build and prepare every sensor's pipeline (import and compile the kernels,
        open the recordings) in a worker thread while the loop stays responsive, then
        start them; False when a stop came first."""
        done = threading.Event()
        cancel = threading.Event()
        failure: list[BaseException] = []

        def prepare() -> None:
            try:
                for unit in self.sensors:
                    if cancel.is_set():
                        break
                    unit.build()
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
                # let the sensor being built finish (a thread stopped inside native code,
                # e.g. a kernel compiling, aborts the interpreter at exit), bounded
                cancel.set()
                await asyncio.to_thread(worker.join, PREPARE_JOIN_S)
                if worker.is_alive():
                    self.abandoned = worker
                self._close_unstarted()
                return False
            if self.service.watchdog_due():  # compiling is progress too
                self.service.watchdog()
            if not warned and time.monotonic() - t0 > 3.0:
                self.say("still preparing the sources and the statistics kernels (a "
                         "simulated source computes its first noise blocks; the kernels "
                         "compile on a first start, `python3 dev.py setup` does that ahead)")
                warned = True
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.stop_requested.wait(), 0.05)
        if failure:
            self._close_unstarted()
            raise failure[0]
        if self.stop_requested.is_set():
            self._close_unstarted()
            return False
        for unit in self.sensors:
            assert unit.pipeline is not None
            unit.pipeline.start()
        return True

    def _close_unstarted(self) -> None:
        """Close what the sensors set up for a start that will not come (their
        recordings; also of a sensor whose set-up goes on in an abandoned thread: what
        that set-up had opened is closed)."""
        for unit in self.sensors:
            if unit.pipeline is not None:
                unit.pipeline.close_unstarted()

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

    async def _wait_end(self) -> None:
        """Until every stream ends, a stop, or an error in any pipeline. The systemd
        watchdog is fed only while every acquisition thread that has not finished is alive
        and the event loop turns, so a hung acquisition or loop gets the service
        restarted."""
        pipelines = [u.pipeline for u in self.sensors if u.pipeline is not None]
        while not self.stop_requested.is_set() and not all(p.done for p in pipelines):
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.stop_requested.wait(), 0.1)
            if any(p.error is not None or p.consumer_errors() for p in pipelines):
                return
            if (all(p.running or p.done for p in pipelines)
                    and self.service.watchdog_due()):
                self.service.watchdog()

    async def _finish(self, publisher: Any, broker: Any) -> None:
        await asyncio.gather(*self._state_saves, return_exceptions=True)
        for unit in self.sensors:
            ec = unit.engine_consumer
            if ec is None or not ec.n_samples or ec.engine is None:
                continue
            with contextlib.suppress(Exception):
                snap = await asyncio.wait_for(unit.snapshot(), 1.0)
                await publisher.publish_allan(self._payload(unit, snap), unit.name)
            await self._save_state(unit)
        await publisher.close(timeout_s=1.0)
        if broker is not None:
            await broker.stop()
        for unit in self.sensors:
            rec = unit.recorder
            if rec is not None and rec.segments:
                unit.say(f"recording closed: {', '.join(map(str, rec.segments))} "
                         f"({rec.samples} samples, {rec.gap_records} gaps)")


def run_daemon(config: Config, config_path: str | None = None) -> int:
    daemon = Daemon(config, config_path)
    code = asyncio.run(daemon.run())
    if daemon.abandoned is not None and daemon.abandoned.is_alive():
        # stopped while a source was still being prepared: end the process without the
        # interpreter's finalisation, which a thread inside native code can abort
        log.warning("stopped while a sensor was still being prepared; exiting without "
                    "waiting for it")
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code
