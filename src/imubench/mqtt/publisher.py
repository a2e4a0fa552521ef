"""Publish Allan snapshots and a retained status over MQTT with aiomqtt 2.x.

Topics (see ``docs/mqtt.md``): ``imubench/<station>/<sensor>/allan`` carries one JSON
snapshot per call of ``publish_allan`` (not retained); ``imubench/<station>/<sensor>/status``
is retained: JSON ``{"state": "online", ...}`` after each (re)connection, the plain string
``offline`` after a clean stop, and the same ``offline`` as last will (set at CONNECT, so the
broker publishes it when the process dies or the link times out).

The caller is never blocked for long: ``publish_allan`` numbers the snapshot (``seq``,
0, 1, 2, ... per sensor), encodes and queues it. A background loop (``run``) connects,
publishes, and reconnects with capped exponential backoff with jitter (each wait drawn
uniformly from [backoff/2, backoff], "equal jitter", AWS Architecture Blog, "Exponential
Backoff and Jitter", 2015). A snapshot leaves the backlog only once the broker acknowledged
it (PUBACK for QoS 1, PUBCOMP for QoS 2; QoS 0 only once handed to the socket), so a
snapshot in flight when the link dies is sent again after reconnection. While disconnected
or while the broker does not answer, at most ``backlog_snapshots`` per sensor wait; the
oldest are dropped, counted in ``dropped_snapshots`` (per sensor in its retained status)
and logged. A hung broker (process stopped, link black-holed) is detected when an
acknowledgement does not come within ``ack_timeout_s`` or by paho's keep-alive (no PINGRESP
within ``keepalive_s``).
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime as dt
import json
import logging
import math
import os
import random
import socket
import ssl
import time
import uuid
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit

import aiomqtt

from imubench.mqtt.errors import MqttError
from imubench.mqtt.topics import allan_topic, node_status_topic, status_topic

log = logging.getLogger(__name__)

OFFLINE_PAYLOAD = b"offline"
"""Retained status after a clean stop, and the last will: plain text, not JSON."""


@dataclass(frozen=True)
class BrokerAddress:
    """Where an external broker lives, parsed from ``mqtt://host:port`` or ``mqtts://...``."""

    host: str
    port: int
    tls: bool


def parse_broker_url(url: str, option: str = "mqtt.broker") -> BrokerAddress:
    """Parse ``mqtt://host[:port]`` (default port 1883) or ``mqtts://host[:port]`` (8883, TLS).

    Raises ``MqttError`` naming ``option`` (the setting or flag that gave it), the URL and
    the accepted forms (``embedded`` only where the daemon's configuration is read).
    """
    if option != "mqtt.broker" and url == "embedded":
        raise MqttError(f"{option} 'embedded': give the URL of the broker to listen to (a "
                        "daemon with its embedded broker prints it, e.g. "
                        "mqtt://127.0.0.1:1884)")
    forms = ("use mqtt://HOST[:PORT] or mqtts://HOST[:PORT] (TLS)"
             + (", or 'embedded'" if option == "mqtt.broker" else ""))
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError as exc:
        raise MqttError(f"{option} {url!r} is not a valid URL ({exc}); {forms}") from None
    if parts.scheme not in ("mqtt", "mqtts"):
        raise MqttError(f"{option} {url!r} has scheme {parts.scheme!r}; {forms}")
    if not parts.hostname:
        raise MqttError(f"{option} {url!r} has no host name; {forms}")
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        raise MqttError(f"{option} {url!r} has a path or query, not allowed; {forms}")
    tls = parts.scheme == "mqtts"
    return BrokerAddress(parts.hostname, port or (8883 if tls else 1883), tls)


def make_tls_context(
    ca: str | os.PathLike[str] | None,
    cert: str | os.PathLike[str] | None = None,
    key: str | os.PathLike[str] | None = None,
    insecure: bool = False,
) -> ssl.SSLContext:
    """Client TLS context: the server's certificate verified against ``ca`` (PEM; the system
    store when None), with its host name checked unless ``insecure`` (the chain is still
    verified), and ``cert``/``key`` (PEM) presented as the client certificate when given.

    Raises ``MqttError`` naming the file that cannot be used.
    """
    try:
        context = ssl.create_default_context(cafile=ca)
    except (OSError, ssl.SSLError, ValueError) as exc:
        raise MqttError(f"mqtt.tls_ca {ca}: not a readable PEM CA certificate ({exc})") from None
    if insecure:
        context.check_hostname = False
    if cert is not None:
        try:
            context.load_cert_chain(cert, key)
        except (OSError, ssl.SSLError, ValueError) as exc:
            raise MqttError(
                f"mqtt.tls_cert {cert} / mqtt.tls_key {key}: not a matching PEM certificate "
                f"and private key ({exc})"
            ) from None
    return context


def _jsonable(value: Any, path: str) -> Any:
    """Convert numpy arrays/scalars to lists/numbers and non-finite floats to None."""
    if value is None or isinstance(value, str | bool | int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v, f"{path}.{k}") for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v, f"{path}[{i}]") for i, v in enumerate(value)]
    tolist = getattr(value, "tolist", None)  # numpy arrays and numpy scalars
    if callable(tolist):
        return _jsonable(tolist(), path)
    if isinstance(value, dt.datetime):
        return value.isoformat()
    raise MqttError(
        f"MQTT payload key {path} holds a {type(value).__name__}, which has no JSON form; "
        "use numbers, strings, lists, dicts or numpy arrays"
    )


def encode_json(payload: Mapping[str, Any]) -> bytes:
    """UTF-8 JSON of ``payload``; numpy values become plain numbers, NaN/inf become null."""
    return json.dumps(_jsonable(payload, "payload"), separators=(",", ":")).encode("utf-8")


class MqttPublisher:
    """Publishes the Allan snapshots and status of one sensor, or of several sensors over
    one connection, to an MQTT broker.

    With one sensor (``sensor`` a name) the connection's last will is that sensor's
    retained status. With several (``sensor`` a sequence of names, ``node`` the daemon's
    name) the will is the node's status (:func:`~imubench.mqtt.topics.node_status_topic`)
    and each sensor's status names the node, so a subscriber knows that the sensors of a
    node that died are offline (:class:`imubench.fleet.inventory.Inventory` does).

    Use as ``async with MqttPublisher(...) as pub: await pub.publish_allan(d)``, or start
    ``await pub.run()`` as a task and call ``await pub.close()`` to stop. ``qos`` applies to
    the snapshots; status messages always use QoS 1 and retain. ``keepalive_s`` is the MQTT
    keep-alive (the broker declares the link dead after 1.5x it and publishes the will).
    ``reconnect_min_s``/``reconnect_max_s`` bound the exponential reconnection backoff.
    """

    def __init__(
        self,
        host: str,
        port: int,
        station: str,
        sensor: str | Sequence[str],
        *,
        node: str | None = None,
        username: str | None = None,
        password: str | None = None,
        tls: bool = False,
        tls_ca: str | os.PathLike[str] | None = None,
        tls_cert: str | os.PathLike[str] | None = None,
        tls_key: str | os.PathLike[str] | None = None,
        tls_insecure: bool = False,
        keepalive_s: int = 30,
        client_id: str | None = None,
        qos: int = 1,
        backlog_snapshots: int = 120,
        reconnect_min_s: float = 0.5,
        reconnect_max_s: float = 5.0,
        timeout_s: float = 10.0,
        ack_timeout_s: float | None = None,
        status_detail: Mapping[str, Any] | None = None,
        max_payload_bytes: int | None = None,
    ) -> None:
        if qos not in (0, 1, 2):
            raise MqttError(f"mqtt qos {qos!r} is invalid; use 0, 1 or 2")
        if backlog_snapshots < 1:
            raise MqttError(f"backlog_snapshots {backlog_snapshots} must be at least 1")
        if (tls_cert is None) != (tls_key is None):
            raise MqttError("mqtt tls_cert and tls_key go together: give both or neither")
        if not 0 < reconnect_min_s <= reconnect_max_s:
            raise MqttError(
                f"reconnect backoff {reconnect_min_s}..{reconnect_max_s} s is invalid; "
                "need 0 < reconnect_min_s <= reconnect_max_s"
            )
        if not 0 <= keepalive_s <= 65535:
            raise MqttError(f"mqtt keepalive_s {keepalive_s} is outside 0..65535")
        sensors = [sensor] if isinstance(sensor, str) else list(sensor)
        if not sensors or len(set(sensors)) != len(sensors):
            raise MqttError(f"sensor names {sensors!r}: need at least one, each once")
        if len(sensors) > 1 and node is None:
            raise MqttError("several sensors over one connection need a node name")
        self.host = host
        self.port = port
        self.station = station
        self.sensors = sensors
        self.sensor = sensors[0]
        self.node = node if len(sensors) > 1 else None
        self.allan_topics = {s: allan_topic(station, s) for s in sensors}  # validates names
        self.status_topics = {s: status_topic(station, s) for s in sensors}
        self.allan_topic = self.allan_topics[self.sensor]
        self.status_topic = self.status_topics[self.sensor]
        self.will_topic = (self.status_topic if self.node is None
                           else node_status_topic(station, self.node))
        self.qos = qos
        self.keepalive_s = keepalive_s
        self.client_id = client_id or (
            f"imubench-{station}-{self.node or self.sensor}-{uuid.uuid4().hex[:8]}")
        self._username = username
        self._password = password
        self._tls_context = (
            make_tls_context(tls_ca, tls_cert, tls_key, tls_insecure) if tls else None
        )
        self._reconnect_min_s = reconnect_min_s
        self._reconnect_max_s = reconnect_max_s
        self._timeout_s = timeout_s
        self._ack_timeout_s = float(keepalive_s) if ack_timeout_s is None else ack_timeout_s
        self._buffer: deque[tuple[str, bytes]] = deque()  # (sensor, JSON)
        self._in_flight: tuple[str, bytes] | None = None
        """The snapshot being published (it may already be at the broker): a full backlog
        drops the next oldest instead, or it would be counted dropped and received."""
        self._buffer_max = backlog_snapshots * len(sensors)
        self._seq = dict.fromkeys(sensors, 0)
        self.dropped_by_sensor = dict.fromkeys(sensors, 0)
        self._drops_logged = 0
        self._status_detail: dict[str, dict[str, Any]] = {
            s: dict(status_detail or {}) for s in sensors}
        self._status_dirty: set[str] = set(sensors)
        self._node_dirty = True
        self._since = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
        self._wake = asyncio.Event()
        self._closing = asyncio.Event()
        self._connected = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self.dropped_snapshots = 0
        self._last_ack: float | None = None
        """Monotonic time of the last snapshot the broker acknowledged."""
        self.max_payload_bytes = max_payload_bytes
        """Snapshots larger than this (the broker's packet limit less the topic and the
        header) are not sent: the broker would close the connection on each attempt."""
        self.oversize_snapshots = 0
        self._oversize_logged = 0
        self.published_snapshots = 0
        self.connections = 0
        self.last_error: str | None = None

    # ------------------------------------------------------------------ public API

    @property
    def connected(self) -> bool:
        """True while a connection to the broker is up."""
        return self._connected.is_set()

    @property
    def buffered_snapshots(self) -> int:
        """Snapshots waiting to be published."""
        return len(self._buffer)

    async def publish_allan(self, payload: Mapping[str, Any], sensor: str | None = None
                            ) -> None:
        """Queue one Allan snapshot of ``sensor`` (default: the first) for its allan
        topic; returns at once.

        ``payload`` gets ``seq`` (the sensor's snapshot number, from 0) and is encoded as
        JSON now (numpy arrays allowed, NaN becomes null). When ``backlog_snapshots`` per
        sensor are already waiting, the oldest is dropped and counted.
        """
        name = sensor or self.sensor
        data = encode_json({**payload, "seq": self._seq[name]})
        self._seq[name] += 1
        if self.max_payload_bytes is not None and len(data) > self.max_payload_bytes:
            # the broker would drop the connection on every attempt: nothing would pass
            self.oversize_snapshots += 1
            self._drop(name)
            if self.oversize_snapshots >= 2 * self._oversize_logged:  # 1, 2, 4, 8, ...
                self._oversize_logged = self.oversize_snapshots
                log.error("%s: snapshot of %d bytes exceeds the broker's packet limit (%d "
                          "bytes for the payload): not sent (%d so far); publish fewer "
                          "statistics or taus (allan.stats, allan.taus), or use a broker "
                          "of your own (mqtt.broker)", name, len(data),
                          self.max_payload_bytes, self.oversize_snapshots)
            return
        self._buffer.append((name, data))
        self._trim_backlog()
        self._wake.set()

    @property
    def produced_snapshots(self) -> int:
        """Snapshots handed to ``publish_allan`` so far, all sensors."""
        return sum(self._seq.values())

    def _drop(self, name: str) -> None:
        """Count one snapshot of sensor ``name`` not sent (its retained status says so)."""
        self.dropped_by_sensor[name] += 1
        self.dropped_snapshots += 1
        self._status_dirty.add(name)

    def _trim_backlog(self) -> None:
        dropped = 0
        while len(self._buffer) > self._buffer_max:
            if self._in_flight is not None and self._buffer[0] is self._in_flight:
                head = self._buffer.popleft()
                name, _ = self._buffer.popleft()
                self._buffer.appendleft(head)
            else:
                name, _ = self._buffer.popleft()
            self._drop(name)
            dropped += 1
        if dropped and self.dropped_snapshots >= 2 * self._drops_logged:  # 1, 2, 4, 8, ...
            self._drops_logged = self.dropped_snapshots
            log.warning(
                "MQTT backlog full (%d snapshots): dropped the oldest, %d dropped so far",
                self._buffer_max,
                self.dropped_snapshots,
            )

    async def publish_status(self, detail: Mapping[str, Any] | None = None,
                             sensor: str | None = None) -> None:
        """Update the retained ``online`` status of ``sensor`` (default: the first) with
        ``detail`` merged in; returns at once.

        Statuses are republished after every reconnection, so subscribers always find them.
        """
        name = sensor or self.sensor
        if detail:
            self._status_detail[name].update(detail)
        self._status_dirty.add(name)
        self._wake.set()

    def _identity(self) -> dict[str, Any]:
        return {"client_id": self.client_id, "host": socket.gethostname(),
                "pid": os.getpid(), "since": self._since}

    def status_payload(self, sensor: str | None = None) -> bytes:
        """The JSON of a sensor's retained online status (``state``, identity, ``node``
        when several sensors share the connection, ``since``, detail)."""
        name = sensor or self.sensor
        status = {"state": "online", "station": self.station, "sensor": name,
                  **({} if self.node is None else {"node": self.node}),
                  **self._identity(), "dropped_snapshots": self.dropped_by_sensor[name],
                  **self._status_detail[name]}
        return encode_json(status)

    def node_payload(self) -> bytes:
        """The JSON of the node's retained online status (several sensors only)."""
        return encode_json({"state": "online", "station": self.station, "node": self.node,
                            "sensors": self.sensors, **self._identity()})

    async def _publish_offline(self, client: aiomqtt.Client, qos: int,
                               timeout: float | None) -> None:
        """Retained ``offline`` on every sensor's status (and the node's)."""
        topics = list(self.status_topics.values())
        if self.node is not None:
            topics.append(self.will_topic)
        for topic in topics:
            await client.publish(topic, OFFLINE_PAYLOAD, qos=qos, retain=True,
                                 timeout=timeout)

    async def wait_connected(self, timeout_s: float) -> bool:
        """Wait until connected (True) or ``timeout_s`` passed (False)."""
        try:
            await asyncio.wait_for(self._connected.wait(), timeout_s)
        except TimeoutError:
            return False
        return True

    async def __aenter__(self) -> MqttPublisher:
        self._task = asyncio.create_task(self.run(), name=f"mqtt-publisher-{self.client_id}")
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    async def close(self, timeout_s: float = 5.0) -> None:
        """Publish retained ``offline`` (if connected), disconnect, and stop ``run``."""
        self._closing.set()
        self._wake.set()
        task, self._task = self._task, None
        if task is None:
            return
        try:
            await asyncio.wait_for(asyncio.shield(task), timeout_s)
        except TimeoutError:
            log.warning(
                "MQTT publisher %s did not stop within %.1f s; cancelling it",
                self.client_id,
                timeout_s,
            )
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    async def run(self) -> None:
        """Connect, publish, reconnect with capped exponential backoff until ``close``."""
        if self._task is None:
            self._task = asyncio.current_task()  # so that close() waits for this loop
        backoff = self._reconnect_min_s
        failures = 0
        down_since: float | None = None  # the last acknowledged snapshot before an outage
        while not self._closing.is_set():
            try:
                async with self._client() as client:
                    self.connections += 1
                    failures = 0
                    backoff = self._reconnect_min_s
                    self._status_dirty = set(self.sensors)
                    self._node_dirty = True
                    self._connected.set()
                    if down_since is None:
                        log.info("MQTT publisher %s connected to %s:%d", self.client_id,
                                 self.host, self.port)
                    else:  # the warning that it was unavailable gets its answer
                        log.warning(
                            "MQTT broker %s:%d back after %.0f s; %d snapshots waiting, %d "
                            "dropped so far", self.host, self.port,
                            time.monotonic() - down_since, len(self._buffer),
                            self.dropped_snapshots)
                        down_since = None
                    try:
                        await self._pump(client)
                    except asyncio.CancelledError:
                        # Cancelled instead of closed: still leave a truthful status behind.
                        with contextlib.suppress(Exception):
                            await self._publish_offline(client, 0, None)
                        raise
                    # Clean stop: the broker will not publish the will after DISCONNECT.
                    await self._publish_offline(client, 1, self._timeout_s)
                    return
            except aiomqtt.MqttError as exc:
                self.last_error = str(exc)
                failures += 1
                if down_since is None:  # from the last snapshot the broker took: a hung
                    # broker is noticed only a keep-alive later ("back after 0 s" after 55 s)
                    down_since = (self._last_ack if self._last_ack is not None
                                  else time.monotonic())
                wait_s = random.uniform(backoff / 2, backoff)
                level = logging.WARNING if failures == 1 else logging.DEBUG
                log.log(
                    level,
                    "MQTT broker %s:%d unavailable (%s); retrying in %.1f s, %d snapshots "
                    "waiting",
                    self.host,
                    self.port,
                    exc,
                    wait_s,
                    len(self._buffer),
                )
            finally:
                self._connected.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._closing.wait(), wait_s)
            backoff = min(backoff * 2, self._reconnect_max_s)

    # ------------------------------------------------------------------ internals

    def _client(self) -> aiomqtt.Client:
        return aiomqtt.Client(
            self.host,
            self.port,
            username=self._username,
            password=self._password,
            identifier=self.client_id,
            will=aiomqtt.Will(self.will_topic, OFFLINE_PAYLOAD, qos=1, retain=True),
            clean_session=True,
            keepalive=self.keepalive_s,
            timeout=self._timeout_s,
            tls_context=self._tls_context,
        )

    async def _pump(self, client: aiomqtt.Client) -> None:
        """Publish status and buffered snapshots until closing; raise MqttError on loss."""
        watcher = asyncio.create_task(self._watch(client))
        try:
            while True:
                if self._status_dirty:
                    dirty, self._status_dirty = self._status_dirty, set()
                    if self.node is not None and self._node_dirty:
                        self._node_dirty = False
                        await client.publish(self.will_topic, self.node_payload(), qos=1,
                                             retain=True, timeout=self._timeout_s)
                    for name in self.sensors:
                        if name in dirty:
                            await client.publish(
                                self.status_topics[name],
                                self.status_payload(name),
                                qos=1,
                                retain=True,
                                timeout=self._timeout_s,
                            )
                while self._buffer:
                    # Leaves the backlog only once acknowledged: a snapshot whose PUBACK
                    # never came is sent again after reconnection.
                    head = self._buffer[0]
                    self._in_flight = head
                    try:
                        await client.publish(self.allan_topics[head[0]], head[1],
                                             qos=self.qos, timeout=self._ack_timeout_s)
                    finally:
                        self._in_flight = None
                    if self._buffer and self._buffer[0] is head:  # not trimmed meanwhile
                        self._buffer.popleft()
                    self.published_snapshots += 1
                    self._last_ack = time.monotonic()
                    if self._status_dirty:
                        break  # a drop happened meanwhile: tell the status first
                if self._status_dirty:
                    continue
                if self._closing.is_set():
                    return
                self._wake.clear()
                waiter = asyncio.create_task(self._wake.wait())
                await asyncio.wait((waiter, watcher), return_when=asyncio.FIRST_COMPLETED)
                waiter.cancel()
                if watcher.done():
                    watcher.result()  # raises the disconnection
                    raise aiomqtt.MqttError("connection lost")
        finally:
            watcher.cancel()
            with contextlib.suppress(asyncio.CancelledError, aiomqtt.MqttError):
                await watcher

    @staticmethod
    async def _watch(client: aiomqtt.Client) -> None:
        """Return or raise when the connection drops (no subscriptions: no messages come)."""
        async for _ in client.messages:
            pass
