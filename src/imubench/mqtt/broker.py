"""A small in-process MQTT 3.1.1 broker on asyncio, for ``mqtt.broker = "embedded"`` and tests.

Protocol: OASIS MQTT Version 3.1.1 (Plus Errata 01); "§" below cites its sections. MQTT 3.1
(``MQIsdp``, level 3) clients are accepted too; MQTT 5 clients get an MQTT 5 CONNACK with
reason code 0x84 "Unsupported Protocol Version" (MQTT 5.0 §3.2.2.2) and are disconnected.

Scope: CONNECT/CONNACK with clean and persistent sessions (persistent sessions keep their
subscriptions and queue QoS 1/2 messages while offline, in memory only), client id rules
(§3.1.3.1), optional user name/password check, keep-alive with the 1.5x grace (§3.1.2.10),
session takeover (§3.1.4-2), PUBLISH QoS 0/1/2 both ways, SUBSCRIBE/UNSUBSCRIBE with ``+``
and ``#`` (``$``-topics not matched by a leading wildcard, §4.7.2), PINGREQ, DISCONNECT,
retained messages (an empty retained payload clears, §3.3.1.3), last will on abnormal
disconnect, keep-alive expiry or protocol error (§3.1.2.5). Not provided: TLS listeners,
WebSockets, bridges, ``$SYS`` topics, persistence to disk, MQTT 5 features.

Security: listens on loopback unless authentication is required (``users`` given and no
anonymous access): ``0.0.0.0`` or another non-loopback address is refused otherwise.
``publish_rights`` maps a user name to the topic filters it may publish to; a user without
an entry, and an anonymous client when users are configured, may only subscribe. A PUBLISH
outside the rights is acknowledged as QoS requires (MQTT 3.1.1 has no refusal code; mosquitto
does the same) but not delivered nor retained, and counted (``BrokerStats.denied``). A session
is taken over only by a client of the same user name.

Back-pressure: each client has its own sender task and a bounded queue (``max_queued``
messages and ``max_queued_bytes`` bytes). When a subscriber reads too slowly its queue
drops the oldest messages and counts them (``client_stats(client_id).dropped``); the broker
and the other clients are not slowed down. A client that does not read its control replies
(CONNACK, PUBACK, SUBACK, ...) only stalls its own connection.
"""

from __future__ import annotations

import argparse
import asyncio
import concurrent.futures
import contextlib
import errno
import hmac
import itertools
import logging
import signal
import threading
import uuid
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from imubench.mqtt import packets as pk
from imubench.mqtt.errors import MalformedPacket, MqttError
from imubench.mqtt.topics import is_valid_topic_filter, is_valid_topic_name, topic_matches
from imubench.netaddr import is_loopback

log = logging.getLogger(__name__)

PORT_SEARCH_SPAN = 100
"""How many consecutive ports ``find_free_port`` tries, starting at the requested one."""


@dataclass(frozen=True)
class ClientStats:
    """Counters of one client session."""

    client_id: str
    connected: bool
    subscriptions: int
    queued: int
    inflight: int
    received: int
    sent: int
    dropped: int


@dataclass(frozen=True)
class BrokerStats:
    """Broker-wide counters."""

    clients_connected: int
    sessions: int
    retained: int
    received: int
    sent: int
    dropped: int
    malformed: int
    denied: int
    retained_bytes: int
    retained_dropped: int


class _Session:
    """State that outlives a connection when clean session is 0 (§3.1.2.4)."""

    def __init__(self, client_id: str, clean: bool, max_queued: int, max_bytes: int) -> None:
        self.client_id = client_id
        self.username: str | None = None
        self.clean = clean
        self.subscriptions: dict[str, int] = {}
        self.queue: deque[pk.Message] = deque()
        self.queued_bytes = 0
        self.max_queued = max_queued
        self.max_bytes = max_bytes
        self.dropped = 0
        self.received = 0
        self.sent = 0
        # Outgoing QoS > 0 in flight: packet id -> (message, awaited ack: PUBACK/PUBREC/PUBCOMP)
        self.inflight: dict[int, tuple[pk.Message, int]] = {}
        self.incoming_qos2: set[int] = set()
        self.connection: _Connection | None = None
        self.wake = asyncio.Event()
        self._ids = itertools.cycle(range(1, 65536))

    def granted_qos(self, topic: str) -> int | None:
        """Highest QoS among this session's filters matching ``topic``, None if none match."""
        best = None
        for topic_filter, qos in self.subscriptions.items():
            if topic_matches(topic_filter, topic) and (best is None or qos > best):
                best = qos
        return best

    def enqueue(self, message: pk.Message) -> int:
        """Queue ``message``; drop the oldest beyond the bounds. Return how many were dropped."""
        self.queue.append(message)
        self.queued_bytes += len(message.payload) + len(message.topic)
        dropped = 0
        while len(self.queue) > self.max_queued or (
            self.queued_bytes > self.max_bytes and len(self.queue) > 1
        ):
            old = self.queue.popleft()
            self.queued_bytes -= len(old.payload) + len(old.topic)
            dropped += 1
        self.dropped += dropped
        self.wake.set()
        return dropped

    def pop(self) -> pk.Message:
        message = self.queue.popleft()
        self.queued_bytes -= len(message.payload) + len(message.topic)
        return message

    def next_packet_id(self) -> int:
        for _ in range(65535):
            packet_id = next(self._ids)
            if packet_id not in self.inflight:
                return packet_id
        raise MqttError(f"client {self.client_id!r}: all 65535 packet identifiers in flight")


class _Connection:
    """One network connection after a successful CONNECT."""

    def __init__(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, peer: str
    ) -> None:
        self.reader = reader
        self.writer = writer
        self.peer = peer
        self.session: _Session | None = None
        self.will: pk.Message | None = None
        self.taken_over = False
        self.sender: asyncio.Task[None] | None = None


class EmbeddedBroker:
    """An asyncio MQTT 3.1.1 broker listening on ``host:port``.

    ``port`` 0 lets the OS choose; with ``find_free_port`` a taken port is replaced by the
    next free one among the following ``PORT_SEARCH_SPAN`` ports. ``users`` maps user
    names to passwords; when given, CONNECTs with a wrong password get return code 0x04 and
    anonymous ones 0x05 unless ``allow_anonymous``. ``max_queued`` / ``max_queued_bytes``
    bound each client's outgoing queue (oldest dropped first), ``max_inflight`` bounds its
    unacknowledged QoS 1/2 messages, ``max_packet_size`` bounds incoming packets (bytes),
    ``max_retained`` the number of retained topics and ``max_retained_bytes`` their payload
    and topic bytes (beyond either, the oldest retained message is dropped and counted),
    ``connect_timeout_s`` the wait for the first packet (CONNECT) of a new connection.
    ``publish_rights`` (user name -> topic filters): see the module docstring.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 1883,
        *,
        find_free_port: bool = True,
        users: Mapping[str, str] | None = None,
        allow_anonymous: bool | None = None,
        max_queued: int = 1000,
        max_queued_bytes: int = 16 * 1024 * 1024,
        max_inflight: int = 20,
        max_packet_size: int = 1024 * 1024,
        connect_timeout_s: float = 10.0,
        max_retained: int = 10_000,
        max_retained_bytes: int = 16 * 1024 * 1024,
        publish_rights: Mapping[str, Sequence[str]] | None = None,
    ) -> None:
        if not 0 <= port <= 65535:
            raise MqttError(f"embedded broker port {port} is outside 0..65535; pick another")
        if max_queued < 1 or max_inflight < 1:
            raise MqttError("embedded broker max_queued and max_inflight must be at least 1")
        self.host = host
        self.port = port
        self.find_free_port = find_free_port
        self._users = dict(users) if users is not None else None
        self._allow_anonymous = users is None if allow_anonymous is None else allow_anonymous
        if not is_loopback(host) and (self._users is None or self._allow_anonymous):
            raise MqttError(
                f"embedded broker refuses to listen on {host!r} without authentication: "
                "anyone on the network could read and publish; use 127.0.0.1, or configure "
                "mqtt.username and mqtt.password"
            )
        self._publish_rights: dict[str, tuple[str, ...]] = {}
        for user, filters in (publish_rights or {}).items():
            for topic_filter in filters:
                if not is_valid_topic_filter(topic_filter):
                    raise MqttError(
                        f"embedded broker publish rights of {user!r}: {topic_filter!r} is not "
                        "a valid topic filter"
                    )
            self._publish_rights[user] = tuple(filters)
        self._denied = 0
        self.max_retained_bytes = max_retained_bytes
        self._retained_bytes = 0
        self._retained_dropped = 0
        self.max_queued = max_queued
        self.max_queued_bytes = max_queued_bytes
        self.max_inflight = max_inflight
        self.max_packet_size = max_packet_size
        self.connect_timeout_s = connect_timeout_s
        self.max_retained = max_retained
        self._server: asyncio.Server | None = None
        self._sessions: dict[str, _Session] = {}
        self._retained: dict[str, pk.Message] = {}
        self._handlers: set[asyncio.Task[None]] = set()
        self._received = 0
        self._sent = 0
        self._dropped = 0
        self._malformed = 0
        self.address: tuple[str, int] | None = None
        self._thread: threading.Thread | None = None
        self._thread_loop: asyncio.AbstractEventLoop | None = None

    # ------------------------------------------------------------------ lifecycle

    async def start(self) -> tuple[str, int]:
        """Start listening; return the actual ``(host, port)``."""
        if self._server is not None:
            raise MqttError("embedded broker already started; call stop() first")
        span = PORT_SEARCH_SPAN if self.find_free_port and self.port != 0 else 1
        last_error: OSError | None = None
        for port in range(self.port, min(self.port + span, 65536)):
            try:
                self._server = await asyncio.start_server(self._on_client, self.host, port)
                break
            except OSError as exc:
                last_error = exc
                if exc.errno != errno.EADDRINUSE:
                    break
        if self._server is None:
            tried = f"port {self.port}" if span == 1 else f"ports {self.port}..{port}"
            hint = (
                "pass find_free_port=True or another port"
                if not self.find_free_port
                else "free a port or choose another"
            )
            raise MqttError(
                f"embedded MQTT broker cannot listen on {self.host} {tried}: {last_error}; {hint}"
            )
        sockname = self._server.sockets[0].getsockname()
        self.address = (sockname[0], sockname[1])
        log.info("embedded MQTT broker listening on mqtt://%s:%d", *self.address)
        return self.address

    async def stop(self) -> None:
        """Close the listener and every connection (no wills are published)."""
        server, self._server = self._server, None
        if server is None:
            return
        server.close()
        for task in list(self._handlers):
            task.cancel()
        await asyncio.gather(*self._handlers, return_exceptions=True)
        await server.wait_closed()
        self._sessions.clear()
        log.info("embedded MQTT broker on %s:%s stopped", *(self.address or ("?", "?")))

    async def __aenter__(self) -> EmbeddedBroker:
        await self.start()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.stop()

    def start_in_thread(self, timeout_s: float = 10.0) -> tuple[str, int]:
        """Run the broker on its own event loop in a daemon thread; return its address."""
        if self._thread is not None:
            raise MqttError("embedded broker thread already running; call stop_thread() first")
        ready: concurrent.futures.Future[tuple[str, int]] = concurrent.futures.Future()

        def run() -> None:
            loop = asyncio.new_event_loop()
            self._thread_loop = loop
            try:
                ready.set_result(loop.run_until_complete(self.start()))
            except BaseException as exc:
                ready.set_exception(exc)
                loop.close()
                return
            try:
                loop.run_forever()
            finally:
                loop.run_until_complete(self.stop())
                loop.close()

        self._thread = threading.Thread(target=run, name="imubench-mqtt-broker", daemon=True)
        self._thread.start()
        try:
            return ready.result(timeout=timeout_s)
        except BaseException:
            self._thread.join(timeout_s)
            self._thread = None
            raise

    def stop_thread(self, timeout_s: float = 10.0) -> None:
        """Stop a broker started with ``start_in_thread`` and join its thread."""
        thread, loop = self._thread, self._thread_loop
        if thread is None or loop is None:
            return
        if loop.is_running():
            future = asyncio.run_coroutine_threadsafe(self.stop(), loop)
            with contextlib.suppress(concurrent.futures.TimeoutError):
                future.result(timeout_s)
            loop.call_soon_threadsafe(loop.stop)
        thread.join(timeout_s)
        self._thread = None
        self._thread_loop = None

    # ------------------------------------------------------------------ statistics

    def stats(self) -> BrokerStats:
        """Broker-wide counters (safe to read from another thread, values may be a bit old)."""
        sessions = list(self._sessions.values())
        return BrokerStats(
            clients_connected=sum(1 for s in sessions if s.connection is not None),
            sessions=len(sessions),
            retained=len(self._retained),
            received=self._received,
            sent=self._sent,
            dropped=self._dropped,
            malformed=self._malformed,
            denied=self._denied,
            retained_bytes=self._retained_bytes,
            retained_dropped=self._retained_dropped,
        )

    def client_stats(self, client_id: str) -> ClientStats | None:
        """Counters of one session, None when the broker holds no session for ``client_id``."""
        s = self._sessions.get(client_id)
        if s is None:
            return None
        return ClientStats(
            client_id=s.client_id,
            connected=s.connection is not None,
            subscriptions=len(s.subscriptions),
            queued=len(s.queue),
            inflight=len(s.inflight),
            received=s.received,
            sent=s.sent,
            dropped=s.dropped,
        )

    # ------------------------------------------------------------------ routing

    def _route(self, message: pk.Message) -> None:
        """Deliver ``message`` to every matching session and update the retained store."""
        if message.retain:
            old = self._retained.pop(message.topic, None)  # §3.3.1-10/11 (empty: cleared)
            if old is not None:
                self._retained_bytes -= len(old.payload) + len(old.topic)
            if message.payload:
                self._retained[message.topic] = message  # newest last
                self._retained_bytes += len(message.payload) + len(message.topic)
                dropped = 0
                while len(self._retained) > self.max_retained or (
                    self._retained_bytes > self.max_retained_bytes and len(self._retained) > 1
                ):
                    oldest = self._retained.pop(next(iter(self._retained)))
                    self._retained_bytes -= len(oldest.payload) + len(oldest.topic)
                    dropped += 1
                if dropped:
                    self._retained_dropped += dropped
                    if self._retained_dropped & (self._retained_dropped - 1) == 0:
                        log.warning(
                            "retained store full (%d topics / %d bytes): dropped the oldest, "
                            "%d dropped so far",
                            self.max_retained,
                            self.max_retained_bytes,
                            self._retained_dropped,
                        )
        for session in self._sessions.values():
            granted = session.granted_qos(message.topic)
            if granted is None:
                continue
            qos = min(granted, message.qos)
            if session.connection is None and qos == 0:
                continue  # offline persistent session: only QoS 1/2 are queued (§3.1.2.4)
            # §3.3.1-9: RETAIN is 0 when forwarding to established subscriptions.
            self._enqueue(session, pk.Message(message.topic, message.payload, qos, False))

    def _enqueue(self, session: _Session, message: pk.Message) -> None:
        dropped = session.enqueue(message)
        if dropped:
            self._dropped += dropped
            if (
                session.dropped == dropped
                or session.dropped // 1000 != (session.dropped - dropped) // 1000
            ):
                log.warning(
                    "MQTT client %r reads too slowly: %d message(s) dropped so far "
                    "(queue bound %d messages / %d bytes)",
                    session.client_id,
                    session.dropped,
                    session.max_queued,
                    session.max_bytes,
                )

    # ------------------------------------------------------------------ connections

    async def _on_client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._handlers.add(task)
        peername = writer.get_extra_info("peername")
        peer = f"{peername[0]}:{peername[1]}" if peername else "?"
        conn = _Connection(reader, writer, peer)
        graceful = False
        try:
            graceful = await self._serve(conn)
        except MalformedPacket as exc:
            self._malformed += 1
            who = conn.session.client_id if conn.session else "(before CONNECT)"
            log.warning(
                "MQTT client %r from %s sent a malformed packet: %s; disconnecting", who, peer, exc
            )
        except TimeoutError:
            who = conn.session.client_id if conn.session else "(before CONNECT)"
            log.info(
                "MQTT client %r from %s timed out (keep-alive or CONNECT); disconnecting", who, peer
            )
        except (asyncio.IncompleteReadError, ConnectionError, OSError) as exc:
            if conn.session is not None and not conn.taken_over:
                log.info(
                    "MQTT client %r from %s lost its connection: %s",
                    conn.session.client_id,
                    peer,
                    type(exc).__name__,
                )
        except asyncio.CancelledError:
            graceful = True  # broker shutdown: nobody is left to receive the will
        finally:
            self._handlers.discard(task)
            self._finish(conn, graceful)

    def _finish(self, conn: _Connection, graceful: bool) -> None:
        if conn.sender is not None:
            conn.sender.cancel()
        conn.writer.close()
        session = conn.session
        if session is None:
            return
        if session.connection is conn:
            session.connection = None
            if not graceful and conn.will is not None and self._server is not None:
                log.info(
                    "publishing the will of MQTT client %r on %r",
                    session.client_id,
                    conn.will.topic,
                )
                self._route(conn.will)
            if session.clean and self._sessions.get(session.client_id) is session:
                del self._sessions[session.client_id]

    async def _send(self, conn: _Connection, data: bytes) -> None:
        conn.writer.write(data)
        await conn.writer.drain()

    async def _serve(self, conn: _Connection) -> bool:
        """Run one connection; True when it ended with DISCONNECT (no will)."""
        packet_type, flags, body = await asyncio.wait_for(
            pk.read_packet(conn.reader, self.max_packet_size), self.connect_timeout_s
        )
        if packet_type != pk.CONNECT:
            name = pk.PACKET_NAMES.get(packet_type, f"type {packet_type}")
            raise MalformedPacket(f"first packet is {name}, not CONNECT (§3.1.0-1)")
        if flags:
            raise MalformedPacket(f"CONNECT fixed-header flags 0x{flags:x} are not 0 (§2.2.2)")
        connect = pk.parse_connect(body)
        if not await self._accept(conn, connect):
            return True
        session = conn.session
        assert session is not None
        timeout = connect.keepalive_s * 1.5 if connect.keepalive_s else None  # §3.1.2-24
        while True:
            packet_type, flags, body = await asyncio.wait_for(
                pk.read_packet(conn.reader, self.max_packet_size), timeout
            )
            if conn.taken_over:
                return True
            if packet_type != pk.PUBLISH and pk.REQUIRED_FLAGS.get(packet_type) != flags:
                name = pk.PACKET_NAMES.get(packet_type, f"reserved type {packet_type}")
                if packet_type not in pk.REQUIRED_FLAGS:
                    raise MalformedPacket(f"{name} is not a packet a client may send")
                raise MalformedPacket(f"{name} fixed-header flags 0x{flags:x} are invalid (§2.2.2)")
            if packet_type == pk.DISCONNECT:
                log.debug("MQTT client %r disconnected", session.client_id)
                return True
            await self._dispatch(conn, session, packet_type, flags, body)

    async def _accept(self, conn: _Connection, connect: pk.Connect) -> bool:
        """Apply protocol, client id and credential rules; send CONNACK. True if accepted."""
        if connect.protocol_level == 5:
            log.info("refusing MQTT 5 client from %s (this broker speaks 3.1.1)", conn.peer)
            await self._send(conn, pk.connack_v5_refusal())
            return False
        expected = {"MQTT": 4, "MQIsdp": 3}[connect.protocol_name]
        if connect.protocol_level != expected:
            log.info(
                "refusing %s level %d from %s",
                connect.protocol_name,
                connect.protocol_level,
                conn.peer,
            )
            await self._send(conn, pk.connack(False, pk.CONNACK_BAD_PROTOCOL))
            return False
        if connect.will is not None and not is_valid_topic_name(connect.will.topic):
            raise MalformedPacket(
                f"CONNECT will topic {connect.will.topic!r} is not a valid topic name (§3.1.3.2)"
            )
        client_id = connect.client_id
        if not client_id:
            if not connect.clean_session:  # §3.1.3-8
                log.info("refusing empty client id with clean session 0 from %s", conn.peer)
                await self._send(conn, pk.connack(False, pk.CONNACK_ID_REJECTED))
                return False
            client_id = f"auto-{uuid.uuid4().hex}"  # §3.1.3-6
        code = self._check_credentials(connect)
        if code != pk.CONNACK_ACCEPTED:
            log.info(
                "refusing MQTT client %r from %s: %s",
                client_id,
                conn.peer,
                "bad user name or password"
                if code == pk.CONNACK_BAD_CREDENTIALS
                else "not authorized",
            )
            await self._send(conn, pk.connack(False, code))
            return False
        old = self._sessions.get(client_id)
        if old is not None and self._users is not None and old.username != connect.username:
            log.warning(
                "refusing MQTT client %r from %s: its session belongs to another user",
                client_id,
                conn.peer,
            )
            await self._send(conn, pk.connack(False, pk.CONNACK_ID_REJECTED))
            return False
        if old is not None and old.connection is not None:  # §3.1.4-2 session takeover
            log.info(
                "MQTT client %r reconnected from %s: closing its previous connection",
                client_id,
                conn.peer,
            )
            previous = old.connection
            previous.taken_over = True
            old.connection = None
            if previous.sender is not None:
                previous.sender.cancel()
            previous.writer.close()
        if connect.clean_session or old is None:
            session = _Session(
                client_id, connect.clean_session, self.max_queued, self.max_queued_bytes
            )
            self._sessions[client_id] = session
            present = False
        else:
            session = old
            present = True
        session.clean = connect.clean_session
        session.username = connect.username
        session.connection = conn
        conn.session = session
        conn.will = connect.will
        await self._send(conn, pk.connack(present, pk.CONNACK_ACCEPTED))
        log.debug(
            "MQTT client %r connected from %s (keep-alive %d s, clean %s)",
            client_id,
            conn.peer,
            connect.keepalive_s,
            connect.clean_session,
        )
        conn.sender = asyncio.create_task(self._sender(conn, session))
        return True

    def _may_publish(self, session: _Session, topic: str) -> bool:
        """Publish rights: everything when no users are configured, else only the
        ``publish_rights`` filters of the session's user."""
        if self._users is None:
            return True
        if session.username is None:
            return False
        return any(topic_matches(f, topic) for f in self._publish_rights.get(session.username, ()))

    def _check_credentials(self, connect: pk.Connect) -> int:
        if self._users is None:
            return pk.CONNACK_ACCEPTED
        if connect.username is None:
            return pk.CONNACK_ACCEPTED if self._allow_anonymous else pk.CONNACK_NOT_AUTHORIZED
        expected = self._users.get(connect.username)
        given = connect.password or b""
        if expected is None or not hmac.compare_digest(expected.encode("utf-8"), given):
            return pk.CONNACK_BAD_CREDENTIALS
        return pk.CONNACK_ACCEPTED

    async def _dispatch(
        self, conn: _Connection, session: _Session, packet_type: int, flags: int, body: bytes
    ) -> None:
        if packet_type == pk.PUBLISH:
            publish = pk.parse_publish(flags, body)
            message = publish.message
            if not is_valid_topic_name(message.topic):
                raise MalformedPacket(
                    f"PUBLISH topic {message.topic!r} is not a valid topic "
                    "name (wildcards or empty, §3.3.2-2)"
                )
            session.received += 1
            self._received += 1
            if not self._may_publish(session, message.topic):
                self._denied += 1
                if self._denied & (self._denied - 1) == 0:  # log at 1, 2, 4, 8, ...
                    log.warning(
                        "MQTT client %r (user %r) may not publish to %r: dropped, %d denied "
                        "so far",
                        session.client_id,
                        session.username,
                        message.topic,
                        self._denied,
                    )
                if message.qos == 1:
                    await self._send(conn, pk.ack(pk.PUBACK, publish.packet_id or 0))
                elif message.qos == 2:
                    await self._send(conn, pk.ack(pk.PUBREC, publish.packet_id or 0))
            elif message.qos == 0:
                self._route(message)
            elif message.qos == 1:
                self._route(message)
                await self._send(conn, pk.ack(pk.PUBACK, publish.packet_id or 0))
            else:
                packet_id = publish.packet_id or 0
                if packet_id not in session.incoming_qos2:  # §4.3.3 method B: deliver once
                    session.incoming_qos2.add(packet_id)
                    self._route(message)
                await self._send(conn, pk.ack(pk.PUBREC, packet_id))
        elif packet_type == pk.PUBREL:
            packet_id = pk.parse_packet_id("PUBREL", body)
            session.incoming_qos2.discard(packet_id)
            await self._send(conn, pk.ack(pk.PUBCOMP, packet_id))
        elif packet_type in (pk.PUBACK, pk.PUBREC, pk.PUBCOMP):
            name = pk.PACKET_NAMES[packet_type]
            packet_id = pk.parse_packet_id(name, body)
            entry = session.inflight.get(packet_id)
            if entry is None or entry[1] != packet_type:
                log.debug(
                    "MQTT client %r sent unexpected %s for id %d",
                    session.client_id,
                    name,
                    packet_id,
                )
                return
            if packet_type == pk.PUBREC:
                session.inflight[packet_id] = (entry[0], pk.PUBCOMP)
                await self._send(conn, pk.ack(pk.PUBREL, packet_id))
            else:
                del session.inflight[packet_id]
                session.wake.set()
        elif packet_type == pk.SUBSCRIBE:
            await self._subscribe(conn, session, pk.parse_subscribe(body))
        elif packet_type == pk.UNSUBSCRIBE:
            unsub = pk.parse_unsubscribe(body)
            for topic_filter in unsub.topics:
                session.subscriptions.pop(topic_filter, None)
            await self._send(conn, pk.ack(pk.UNSUBACK, unsub.packet_id))
        elif packet_type == pk.PINGREQ:
            await self._send(conn, pk.pingresp())
        elif packet_type == pk.CONNECT:
            raise MalformedPacket("second CONNECT on one connection (§3.1.0-2)")

    async def _subscribe(self, conn: _Connection, session: _Session, sub: pk.Subscribe) -> None:
        codes: list[int] = []
        granted: list[tuple[str, int]] = []
        for topic_filter, qos in sub.topics:
            if is_valid_topic_filter(topic_filter):
                session.subscriptions[topic_filter] = qos
                granted.append((topic_filter, qos))
                codes.append(qos)
            else:
                log.info(
                    "MQTT client %r: refusing invalid topic filter %r",
                    session.client_id,
                    topic_filter,
                )
                codes.append(pk.SUBACK_FAILURE)
        await self._send(conn, pk.suback(sub.packet_id, codes))
        for message in list(self._retained.values()):  # §3.3.1-6: retained on subscribe
            qos_list = [q for f, q in granted if topic_matches(f, message.topic)]
            if qos_list:
                qos = min(max(qos_list), message.qos)
                self._enqueue(session, pk.Message(message.topic, message.payload, qos, True))

    async def _sender(self, conn: _Connection, session: _Session) -> None:
        """Write queued messages to one client; only this task waits on a slow reader."""
        try:
            for packet_id, (message, awaited) in list(session.inflight.items()):  # §4.4
                if awaited == pk.PUBCOMP:
                    await self._send(conn, pk.ack(pk.PUBREL, packet_id))
                else:
                    await self._send(conn, pk.publish(message, packet_id, dup=True))
            while True:
                while session.queue and len(session.inflight) < self.max_inflight:
                    message = session.pop()
                    new_id: int | None = None
                    if message.qos:
                        new_id = session.next_packet_id()
                        awaited = pk.PUBACK if message.qos == 1 else pk.PUBREC
                        session.inflight[new_id] = (message, awaited)
                    conn.writer.write(pk.publish(message, new_id))
                    session.sent += 1
                    self._sent += 1
                    await conn.writer.drain()
                session.wake.clear()
                await session.wake.wait()
        except (ConnectionError, OSError) as exc:
            log.debug("MQTT client %r: send failed: %s", session.client_id, exc)
            conn.writer.close()


def main(argv: list[str] | None = None) -> int:
    """``python -m imubench.mqtt.broker --port N``: run the embedded broker until Ctrl-C."""
    parser = argparse.ArgumentParser(
        prog="python -m imubench.mqtt.broker",
        description="imubench's embedded MQTT 3.1.1 broker (for tests and quick starts)",
    )
    parser.add_argument("--host", default="127.0.0.1", help="address to listen on")
    parser.add_argument("--port", type=int, default=1883, help="TCP port (0: any free port)")
    parser.add_argument(
        "--exact-port",
        action="store_true",
        help="fail instead of using the next free port when --port is taken",
    )
    parser.add_argument(
        "--user",
        action="append",
        default=[],
        metavar="NAME:PASSWORD",
        help="accepted credentials (repeatable); anonymous clients are then "
        "refused unless --allow-anonymous",
    )
    parser.add_argument(
        "--publish",
        action="append",
        default=[],
        metavar="NAME:FILTER",
        help="topic filter user NAME may publish to (repeatable, e.g. bench:imubench/#); "
        "with --user and no --publish for a user, that user may only subscribe",
    )
    parser.add_argument("--allow-anonymous", action="store_true")
    parser.add_argument(
        "--max-queued",
        type=int,
        default=1000,
        help="per-client queue bound in messages (oldest dropped first)",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log every connection")
    args = parser.parse_args(argv)
    users: dict[str, str] | None = None
    for entry in args.user:
        name, sep, password = entry.partition(":")
        if not sep or not name:
            parser.error(f"--user {entry!r}: expected NAME:PASSWORD")
        users = users or {}
        users[name] = password
    rights: dict[str, list[str]] = {}
    for entry in args.publish:
        name, sep, topic_filter = entry.partition(":")
        if not sep or not name or not topic_filter or name not in (users or {}):
            parser.error(f"--publish {entry!r}: expected NAME:FILTER for a --user NAME")
        rights.setdefault(name, []).append(topic_filter)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    try:
        broker = EmbeddedBroker(
            args.host,
            args.port,
            find_free_port=not args.exact_port,
            users=users,
            publish_rights=rights or None,
            allow_anonymous=args.allow_anonymous or None,
            max_queued=args.max_queued,
        )
    except MqttError as exc:  # one line, in this command's words (not the daemon's keys)
        parser.error(str(exc).replace("mqtt.username and mqtt.password", "--user NAME:PASSWORD"))

    async def serve() -> None:
        host, port = await broker.start()
        stop = asyncio.Event()
        with contextlib.suppress(NotImplementedError):
            # SIGINT too: a shell starts background jobs with SIGINT ignored, and
            # asyncio.run then leaves it ignored; installed before the address is printed
            for signum in (signal.SIGINT, signal.SIGTERM):
                asyncio.get_running_loop().add_signal_handler(signum, stop.set)
        print(f"imubench embedded MQTT broker on mqtt://{host}:{port} (Ctrl-C to stop)", flush=True)
        try:
            await stop.wait()
        finally:
            await broker.stop()

    try:
        asyncio.run(serve())
    except MqttError as exc:
        print(f"error: {exc}")
        return 1
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
