"""The embedded MQTT broker, against real clients over TCP: aiomqtt (paho), mosquitto_sub /
mosquitto_pub subprocesses, and hand-written packet bytes taken from the MQTT 3.1.1 text."""

from __future__ import annotations

import asyncio
import logging
import shutil
import signal
import socket
import subprocess
import time
from collections.abc import Callable

import aiomqtt
import mqtt_fixtures
import pytest
from mqtt_fixtures import unique_prefix

from imubench.mqtt.broker import EmbeddedBroker
from imubench.mqtt.errors import MqttError

MOSQUITTO_SUB = shutil.which("mosquitto_sub")
MOSQUITTO_PUB = shutil.which("mosquitto_pub")
needs_mosquitto_clients = pytest.mark.skipif(
    MOSQUITTO_SUB is None or MOSQUITTO_PUB is None,
    reason="mosquitto_sub/mosquitto_pub not installed (apt-get install mosquitto-clients)",
)

BrokerFactory = Callable[..., EmbeddedBroker]
# Fixtures from tests/mqtt_fixtures.py (harmless once conftest imports them too).
embedded_broker = mqtt_fixtures.embedded_broker


# ---------------------------------------------------------------- raw MQTT 3.1.1 bytes


def _utf8(text: str) -> bytes:
    raw = text.encode()
    return len(raw).to_bytes(2, "big") + raw


def _frame(first_byte: int, body: bytes) -> bytes:
    assert len(body) < 128, "test packets stay below 128 bytes: one remaining-length byte"
    return bytes([first_byte, len(body)]) + body


def raw_connect_packet(
    client_id: str, keepalive_s: int = 60, clean: bool = True, will: tuple[str, bytes] | None = None
) -> bytes:
    """CONNECT as laid out in §3.1 (figure 3.1-3.3), written out by hand."""
    flags = 0x02 if clean else 0x00
    payload = _utf8(client_id)
    if will is not None:
        flags |= 0x04  # will flag, QoS 0, no retain
        payload += _utf8(will[0]) + len(will[1]).to_bytes(2, "big") + will[1]
    body = _utf8("MQTT") + bytes([0x04, flags]) + keepalive_s.to_bytes(2, "big") + payload
    return _frame(0x10, body)


def raw_client(port: int, packet: bytes) -> tuple[socket.socket, bytes]:
    """Open a socket, send ``packet`` (normally a CONNECT) and return the 4-byte reply."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=5)
    sock.sendall(packet)
    return sock, recv_exactly(sock, 4)


def recv_exactly(sock: socket.socket, n: int) -> bytes:
    data = b""
    while len(data) < n:
        chunk = sock.recv(n - len(data))
        if not chunk:
            break
        data += chunk
    return data


def closed_by_peer(sock: socket.socket, timeout_s: float = 5.0) -> bool:
    """True when the broker closes the connection within ``timeout_s`` (recv returns EOF)."""
    sock.settimeout(timeout_s)
    try:
        while True:
            if not sock.recv(4096):
                return True
    except (ConnectionResetError, BrokenPipeError):
        return True
    except TimeoutError:
        return False


CONNACK_OK = bytes.fromhex("20020000")


# ---------------------------------------------------------------- aiomqtt helpers


async def receive(client: aiomqtt.Client, n: int, timeout_s: float = 5.0) -> list[aiomqtt.Message]:
    messages: list[aiomqtt.Message] = []

    async def take() -> None:
        async for message in client.messages:
            messages.append(message)
            if len(messages) == n:
                return

    await asyncio.wait_for(take(), timeout_s)
    return messages


def run(coro_factory: Callable[[], object]) -> object:
    return asyncio.run(coro_factory())  # type: ignore[arg-type]


# ---------------------------------------------------------------- tests


def test_pubsub_wildcards_and_dollar_topics(embedded_broker: BrokerFactory) -> None:
    host, port = embedded_broker().address or ("", 0)
    p = unique_prefix("wild")

    async def scenario() -> None:
        async with (
            aiomqtt.Client(host, port) as plus,
            aiomqtt.Client(host, port) as hash_all,
            aiomqtt.Client(host, port) as dollar,
            aiomqtt.Client(host, port) as pub,
        ):
            await plus.subscribe(f"{p}/+/temp")
            await hash_all.subscribe("#")
            await dollar.subscribe("$test/#")
            await pub.publish(f"{p}/a/temp", b"1")
            await pub.publish(f"{p}/a/b/temp", b"2")
            await pub.publish("$test/x", b"3")
            await pub.publish(f"{p}/b/temp", b"4")
            got_plus = await receive(plus, 2)
            got_all = await receive(hash_all, 3)
            got_dollar = await receive(dollar, 1)
            assert [(str(m.topic), m.payload) for m in got_plus] == [
                (f"{p}/a/temp", b"1"),
                (f"{p}/b/temp", b"4"),
            ]
            # '#' sees every topic except the '$' one (§4.7.2)
            assert [m.payload for m in got_all] == [b"1", b"2", b"4"]
            assert [(str(m.topic), m.payload) for m in got_dollar] == [("$test/x", b"3")]

    run(scenario)


@needs_mosquitto_clients
def test_mosquitto_clients_pub_sub_and_retained(embedded_broker: BrokerFactory) -> None:
    broker = embedded_broker()
    host, port = broker.address or ("", 0)
    p = unique_prefix("cli")
    pub = [MOSQUITTO_PUB, "-h", host, "-p", str(port)]
    sub = [MOSQUITTO_SUB, "-h", host, "-p", str(port)]
    subprocess.run([*pub, "-t", f"{p}/kept", "-m", "retained-1", "-r"], check=True, timeout=5)
    # A late subscriber gets the retained message with the retain flag (%r).
    out = subprocess.run(
        [*sub, "-t", f"{p}/#", "-C", "1", "-F", "%r %t %p", "-W", "5"],
        capture_output=True,
        text=True,
        timeout=10,
        check=True,
    )
    assert out.stdout.strip() == f"1 {p}/kept retained-1"
    # Live pub/sub between two mosquitto processes, QoS 1 and 2; retain flag 0 on live delivery.
    with subprocess.Popen(
        [
            *sub,
            "-i",
            "cli-sub",
            "-t",
            f"{p}/live/+",
            "-q",
            "2",
            "-C",
            "2",
            "-F",
            "%r %q %t %p",
            "-W",
            "5",
        ],
        stdout=subprocess.PIPE,
        text=True,
    ) as proc:
        _wait_subscribed(broker, "cli-sub")
        subprocess.run([*pub, "-t", f"{p}/live/a", "-m", "q1", "-q", "1"], check=True, timeout=5)
        subprocess.run(
            [*pub, "-t", f"{p}/live/b", "-m", "q2", "-q", "2", "-r"], check=True, timeout=5
        )
        stdout, _ = proc.communicate(timeout=10)
    assert stdout.splitlines() == [f"0 1 {p}/live/a q1", f"0 2 {p}/live/b q2"]
    # An empty retained message clears the retained one (§3.3.1-10, -11).
    subprocess.run([*pub, "-t", f"{p}/kept", "-r", "-n"], check=True, timeout=5)
    subprocess.run([*pub, "-t", f"{p}/live/b", "-r", "-n"], check=True, timeout=5)
    out = subprocess.run(
        [*sub, "-t", f"{p}/#", "-C", "1", "-W", "1", "--retained-only"],
        capture_output=True,
        text=True,
        timeout=10,
    )
    assert out.stdout == ""


def _wait_subscribed(broker: EmbeddedBroker, client_id: str, timeout_s: float = 5.0) -> None:
    """Wait until the client ``client_id`` holds a subscription on ``broker``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        stats = broker.client_stats(client_id)
        if stats is not None and stats.subscriptions:
            return
        time.sleep(0.02)
    raise AssertionError(f"client {client_id!r} did not subscribe within {timeout_s} s")


def test_retained_with_aiomqtt_and_clearing(embedded_broker: BrokerFactory) -> None:
    host, port = embedded_broker().address or ("", 0)
    p = unique_prefix("ret")

    async def scenario() -> None:
        async with aiomqtt.Client(host, port) as pub:
            await pub.publish(f"{p}/a", b"old", retain=True)
            await pub.publish(f"{p}/a", b"new", qos=1, retain=True)  # replaces
            await pub.publish(f"{p}/b", b"gone", retain=True)
            await pub.publish(f"{p}/b", b"", retain=True)  # clears
        async with aiomqtt.Client(host, port) as sub:
            await sub.subscribe(f"{p}/#", qos=1)
            first = (await receive(sub, 1))[0]
            assert (str(first.topic), first.payload, first.retain, first.qos) == (
                f"{p}/a",
                b"new",
                True,
                1,
            )
            async with aiomqtt.Client(host, port) as pub:
                await pub.publish(f"{p}/marker", b"m")
            second = (await receive(sub, 1))[0]
            assert (str(second.topic), second.retain) == (f"{p}/marker", False)

    run(scenario)


def test_qos1_and_qos2_both_directions(embedded_broker: BrokerFactory) -> None:
    host, port = embedded_broker().address or ("", 0)
    p = unique_prefix("qos")

    async def scenario() -> None:
        async with (
            aiomqtt.Client(host, port) as sub2,
            aiomqtt.Client(host, port) as sub1,
            aiomqtt.Client(host, port) as pub,
        ):
            await sub2.subscribe(f"{p}/t", qos=2)
            await sub1.subscribe(f"{p}/t", qos=1)
            # aiomqtt returns only after PUBACK (QoS 1) or PUBCOMP (QoS 2) from the broker.
            await pub.publish(f"{p}/t", b"one", qos=1)
            await pub.publish(f"{p}/t", b"two", qos=2)
            await pub.publish(f"{p}/t", b"zero", qos=0)
            got2 = await receive(sub2, 3)
            got1 = await receive(sub1, 3)
            # delivered QoS = min(publish QoS, granted QoS) (§3.8.4). Order across QoS
            # levels is not guaranteed at the application: paho hands a QoS 2 message over
            # only when the broker's PUBREL arrives, so a later QoS 0 one may overtake it.
            assert sorted((m.payload, m.qos) for m in got2) == [
                (b"one", 1), (b"two", 2), (b"zero", 0)]
            assert sorted((m.payload, m.qos) for m in got1) == [
                (b"one", 1), (b"two", 1), (b"zero", 0)]

    run(scenario)


def test_qos2_packet_flow_and_duplicate_delivered_once(embedded_broker: BrokerFactory) -> None:
    host, port = embedded_broker().address or ("", 0)
    topic = unique_prefix("q2raw")

    async def scenario() -> list[bytes]:
        async with aiomqtt.Client(host, port) as sub:
            await sub.subscribe(topic, qos=2)
            sock, reply = raw_client(port, raw_connect_packet("raw-q2"))
            assert reply == CONNACK_OK
            publish = _frame(0x34, _utf8(topic) + b"\x00\x07" + b"payload")  # QoS 2, id 7
            sock.sendall(publish)
            assert recv_exactly(sock, 4) == bytes.fromhex("50020007")  # PUBREC id 7
            sock.sendall(bytes([0x3C]) + publish[1:])  # same id again with DUP (§4.3.3)
            assert recv_exactly(sock, 4) == bytes.fromhex("50020007")
            sock.sendall(bytes.fromhex("62020007"))  # PUBREL id 7, flags 0b0010
            assert recv_exactly(sock, 4) == bytes.fromhex("70020007")  # PUBCOMP id 7
            sock.sendall(_frame(0x30, _utf8(topic) + b"after"))
            got = await receive(sub, 2)
            sock.close()
            return [m.payload for m in got]

    # The client library hands a QoS 2 message to the application only after its own
    # PUBREL handshake, so the QoS 0 "after" may overtake it: compare without order.
    # Exactly two messages prove the DUP resend was not delivered a second time.
    assert sorted(run(scenario)) == [b"after", b"payload"]


@needs_mosquitto_clients
def test_will_published_when_client_is_sigkilled(embedded_broker: BrokerFactory) -> None:
    broker = embedded_broker()
    host, port = broker.address or ("", 0)
    p = unique_prefix("will")

    async def scenario() -> None:
        async with aiomqtt.Client(host, port) as watcher:
            await watcher.subscribe(f"{p}/will/#")
            proc = subprocess.Popen(
                [
                    MOSQUITTO_SUB,
                    "-h",
                    host,
                    "-p",
                    str(port),
                    "-i",
                    f"victim-{p[-6:]}",
                    "-t",
                    f"{p}/nothing",
                    "--will-topic",
                    f"{p}/will/victim",
                    "--will-payload",
                    "victim died",
                ],
                stdout=subprocess.DEVNULL,
            )
            try:
                await _until(
                    lambda: (
                        (s := broker.client_stats(f"victim-{p[-6:]}")) is not None
                        and s.subscriptions == 1
                    )
                )
                proc.send_signal(signal.SIGKILL)
            finally:
                proc.wait(5)
            # A clean DISCONNECT must not publish the will: mosquitto_pub disconnects cleanly.
            subprocess.run(
                [
                    MOSQUITTO_PUB,
                    "-h",
                    host,
                    "-p",
                    str(port),
                    "-t",
                    f"{p}/will/x",
                    "-m",
                    "clean",
                    "--will-topic",
                    f"{p}/will/clean",
                    "--will-payload",
                    "must not appear",
                ],
                check=True,
                timeout=5,
            )
            async with aiomqtt.Client(host, port) as pub:
                await pub.publish(f"{p}/will/marker", b"end")
            got = await receive(watcher, 3)
            assert [(str(m.topic), m.payload) for m in got] == [
                (f"{p}/will/victim", b"victim died"),
                (f"{p}/will/x", b"clean"),
                (f"{p}/will/marker", b"end"),
            ]

    run(scenario)


async def _until(predicate: Callable[[], bool], timeout_s: float = 5.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError("condition not reached within timeout")
        await asyncio.sleep(0.02)


def test_keepalive_expiry_publishes_will_and_pingreq_keeps_alive(
    embedded_broker: BrokerFactory, caplog: pytest.LogCaptureFixture
) -> None:
    host, port = embedded_broker().address or ("", 0)
    p = unique_prefix("ka")
    caplog.set_level(logging.INFO, logger="imubench.mqtt.broker")

    async def scenario() -> float:
        async with aiomqtt.Client(host, port) as watcher:
            await watcher.subscribe(f"{p}/#")
            pinger, reply = raw_client(
                port, raw_connect_packet("pinger", keepalive_s=1, will=(f"{p}/pinger", b"x"))
            )
            assert reply == CONNACK_OK
            silent, reply = raw_client(
                port, raw_connect_packet("silent", keepalive_s=1, will=(f"{p}/silent", b"bye"))
            )
            assert reply == CONNACK_OK
            start = time.monotonic()
            loop = asyncio.get_running_loop()
            for _ in range(5):  # PINGREQ every 0.5 s for 2.5 s: longer than 1.5 x 1 s
                pinger.sendall(b"\xc0\x00")
                resp = await loop.run_in_executor(None, recv_exactly, pinger, 2)
                assert resp == b"\xd0\x00"  # PINGRESP
                await asyncio.sleep(0.5)
            got = await receive(watcher, 1)
            elapsed = time.monotonic() - start
            assert [(str(m.topic), m.payload) for m in got] == [(f"{p}/silent", b"bye")]
            assert closed_by_peer(silent, 1.0)
            pinger.sendall(b"\xe0\x00")  # DISCONNECT: no will for the pinger
            pinger.close()
            silent.close()
            return elapsed

    elapsed = run(scenario)
    assert isinstance(elapsed, float)
    assert elapsed >= 1.2  # never before 1.5 x keep-alive (lower bound only, no upper bound)
    assert any("timed out" in r.getMessage() and "silent" in r.getMessage() for r in caplog.records)


MALFORMED = {
    "reserved packet type 0": b"\x00\x00",
    "remaining length of 5 bytes": b"\x30\xff\xff\xff\xff\x7f",
    "PUBLISH with QoS 3": b"\x36\x05\x00\x01a\x00\x01",
    "PUBLISH to a wildcard topic": b"\x30\x05\x00\x03a/#",
    "SUBSCRIBE with flags 0": b"\x80\x06\x00\x01\x00\x01a\x00",
    "SUBSCRIBE without filters": b"\x82\x02\x00\x01",
    "second CONNECT": raw_connect_packet("again"),
    "invalid UTF-8 topic": b"\x30\x04\x00\x02\xc3\x28",
    "PUBREL with flags 0": b"\x60\x02\x00\x01",
}


@pytest.mark.parametrize("packet", list(MALFORMED.values()), ids=list(MALFORMED))
def test_malformed_packet_disconnects_logs_and_sends_will(
    embedded_broker: BrokerFactory, caplog: pytest.LogCaptureFixture, packet: bytes
) -> None:
    broker = embedded_broker()
    host, port = broker.address or ("", 0)
    p = unique_prefix("bad")
    caplog.set_level(logging.WARNING, logger="imubench.mqtt.broker")

    async def scenario() -> None:
        async with aiomqtt.Client(host, port) as watcher:
            await watcher.subscribe(f"{p}/#")
            sock, reply = raw_client(port, raw_connect_packet("evil", will=(f"{p}/w", b"evil")))
            assert reply == CONNACK_OK
            sock.sendall(packet)
            loop = asyncio.get_running_loop()
            assert await loop.run_in_executor(None, closed_by_peer, sock, 5.0)
            sock.close()
            got = await receive(watcher, 1)
            assert [(str(m.topic), m.payload) for m in got] == [(f"{p}/w", b"evil")]
            # The broker keeps serving everyone else.
            async with aiomqtt.Client(host, port) as pub:
                await pub.publish(f"{p}/still", b"alive", qos=1)
            assert [m.payload for m in await receive(watcher, 1)] == [b"alive"]

    run(scenario)
    assert broker.stats().malformed == 1
    assert any("'evil'" in r.getMessage() and "malformed" in r.getMessage() for r in caplog.records)


def test_slow_subscriber_is_bounded_and_does_not_stall_others(
    embedded_broker: BrokerFactory,
) -> None:
    broker = embedded_broker(max_queued=50)
    host, port = broker.address or ("", 0)
    topic = unique_prefix("flood")
    n_flood = 3000
    payload = b"x" * 2048

    slow = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    slow.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    slow.settimeout(5)
    slow.connect((host, port))
    slow.sendall(raw_connect_packet("slow"))
    assert recv_exactly(slow, 4) == CONNACK_OK
    slow.sendall(_frame(0x82, b"\x00\x01" + _utf8(topic) + b"\x00"))  # SUBSCRIBE QoS 0
    assert recv_exactly(slow, 5) == bytes.fromhex("9003000100")  # SUBACK granted QoS 0
    # From here on the slow client never reads.

    async def scenario() -> int:
        async with aiomqtt.Client(host, port) as fast, aiomqtt.Client(host, port) as pub:
            await fast.subscribe(topic, qos=1)
            for i in range(n_flood):
                await pub.publish(topic, payload)
                if i % 100 == 0:
                    await asyncio.sleep(0)  # let paho's socket loop run
            await pub.publish(topic, b"last", qos=1)  # returns after the broker's PUBACK
            received = 0
            async with asyncio.timeout(20):
                async for message in fast.messages:
                    received += 1
                    if message.payload == b"last":
                        return received
        return -1

    received = run(scenario)
    stats = broker.client_stats("slow")
    slow.close()
    assert isinstance(received, int)
    assert received > 0  # the fast subscriber got through to the final message
    assert stats is not None
    assert stats.queued <= 50
    assert stats.dropped > 0  # 6 MiB sent; only kernel socket buffers (~1-3 MiB) took any
    assert stats.sent + stats.queued + stats.dropped == n_flood + 1  # nothing lost silently
    assert broker.stats().dropped >= stats.dropped


def test_mqtt5_client_refused_mqtt31_accepted(embedded_broker: BrokerFactory) -> None:
    host, port = embedded_broker().address or ("", 0)

    async def scenario() -> None:
        with pytest.raises(aiomqtt.MqttCodeError) as info:
            async with aiomqtt.Client(host, port, protocol=aiomqtt.ProtocolVersion.V5):
                pass
        assert "Unsupported protocol version" in str(info.value)
        async with aiomqtt.Client(host, port, protocol=aiomqtt.ProtocolVersion.V31) as old:
            await old.publish("x/y", b"1", qos=1)

    run(scenario)


def test_client_id_rules_and_session_takeover(embedded_broker: BrokerFactory) -> None:
    broker = embedded_broker()
    _, port = broker.address or ("", 0)
    # Empty client id with clean session 0: CONNACK return code 2 (§3.1.3-8).
    sock, reply = raw_client(port, raw_connect_packet("", clean=False))
    assert reply == bytes.fromhex("20020002")
    assert closed_by_peer(sock)
    sock.close()
    # Empty client id with clean session 1: accepted, the broker assigns one (§3.1.3-6).
    sock, reply = raw_client(port, raw_connect_packet("", clean=True))
    assert reply == CONNACK_OK
    sock.close()
    # Same client id twice: the first connection is closed (§3.1.4-2).
    first, reply = raw_client(port, raw_connect_packet("twin"))
    assert reply == CONNACK_OK
    second, reply = raw_client(port, raw_connect_packet("twin"))
    assert reply == CONNACK_OK
    assert closed_by_peer(first)
    second.sendall(b"\xc0\x00")
    assert recv_exactly(second, 2) == b"\xd0\x00"
    first.close()
    second.close()
    # A will topic with a wildcard is a protocol violation: no CONNACK, connection closed.
    sock = socket.create_connection(("127.0.0.1", port), timeout=5)
    sock.sendall(raw_connect_packet("wild-will", will=("a/#", b"x")))
    assert recv_exactly(sock, 4) == b""
    sock.close()
    # Unknown protocol level 3 with name "MQTT": CONNACK return code 1 (§3.1.2-2).
    bad_level = raw_connect_packet("lvl").replace(b"MQTT\x04", b"MQTT\x03")
    sock, reply = raw_client(port, bad_level)
    assert reply == bytes.fromhex("20020001")
    sock.close()


def test_persistent_session_keeps_subscription_and_queues_qos1(
    embedded_broker: BrokerFactory,
) -> None:
    host, port = embedded_broker().address or ("", 0)
    topic = unique_prefix("persist")

    async def scenario() -> None:
        async with aiomqtt.Client(host, port, identifier="keeper", clean_session=False) as c:
            await c.subscribe(topic, qos=1)
        async with aiomqtt.Client(host, port) as pub:
            await pub.publish(topic, b"while away", qos=1)
            await pub.publish(topic, b"qos0 not kept", qos=0)
        async with aiomqtt.Client(host, port, identifier="keeper", clean_session=False) as c:
            got = await receive(c, 1)
            assert [(m.payload, m.qos) for m in got] == [(b"while away", 1)]

    run(scenario)


def test_username_password_check(embedded_broker: BrokerFactory) -> None:
    host, port = embedded_broker(users={"alice": "s3cret"}).address or ("", 0)

    async def scenario() -> None:
        with pytest.raises(aiomqtt.MqttCodeError) as wrong:
            async with aiomqtt.Client(host, port, username="alice", password="nope"):
                pass
        assert "Bad user name or password" in str(wrong.value)
        with pytest.raises(aiomqtt.MqttCodeError) as anonymous:
            async with aiomqtt.Client(host, port):
                pass
        assert "Not authorized" in str(anonymous.value)
        async with aiomqtt.Client(host, port, username="alice", password="s3cret") as ok:
            await ok.publish("a/b", b"1", qos=1)

    run(scenario)


def test_unsubscribe_stops_delivery(embedded_broker: BrokerFactory) -> None:
    host, port = embedded_broker().address or ("", 0)
    p = unique_prefix("unsub")

    async def scenario() -> None:
        async with aiomqtt.Client(host, port) as sub, aiomqtt.Client(host, port) as pub:
            await sub.subscribe(f"{p}/a")
            await sub.subscribe(f"{p}/b")
            await sub.unsubscribe(f"{p}/a")
            await pub.publish(f"{p}/a", b"not wanted")
            await pub.publish(f"{p}/b", b"wanted")
            got = await receive(sub, 1)
            assert [m.payload for m in got] == [b"wanted"]

    run(scenario)


def test_port_taken_uses_next_free_or_fails_clearly() -> None:
    blocker = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    blocker.bind(("127.0.0.1", 0))
    blocker.listen()
    taken = blocker.getsockname()[1]
    try:
        broker = EmbeddedBroker("127.0.0.1", taken)
        host, port = broker.start_in_thread()
        try:
            assert host == "127.0.0.1"
            assert taken < port < taken + 100
        finally:
            broker.stop_thread()
        strict = EmbeddedBroker("127.0.0.1", taken, find_free_port=False)
        with pytest.raises(MqttError) as info:
            strict.start_in_thread()
        assert f"port {taken}" in str(info.value)
        assert "find_free_port=True" in str(info.value)
    finally:
        blocker.close()


def test_command_line_broker_serves_clients() -> None:
    import sys

    proc = subprocess.Popen(
        [sys.executable, "-m", "imubench.mqtt.broker", "--port", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert "mqtt://127.0.0.1:" in line
        port = int(line.split("mqtt://127.0.0.1:")[1].split()[0])
        sock, reply = raw_client(port, raw_connect_packet("cli-check"))
        assert reply == CONNACK_OK
        sock.close()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(10)
    assert proc.returncode == 0
