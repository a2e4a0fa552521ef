"""The embedded broker's security and bounds (issue 12): loopback unless authenticated,
per-user publish rights, sessions bound to their user, retained store bounded in count
and bytes, and malformed packets from the network (fuzz; the 1e5-packet run is in
``bench/fault_mqtt.py``)."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable

import aiomqtt
import mqtt_fixtures
import pytest
from mqtt_fixtures import fuzz_broker, speaks_mqtt

from imubench.mqtt.broker import EmbeddedBroker
from imubench.mqtt.errors import MqttError

embedded_broker = mqtt_fixtures.embedded_broker
BrokerFactory = Callable[..., EmbeddedBroker]


async def _drain(client: aiomqtt.Client, quiet_s: float = 0.5) -> list[tuple[str, bytes]]:
    """Every message until none came for ``quiet_s``."""
    got: list[tuple[str, bytes]] = []
    while True:
        try:
            message = await asyncio.wait_for(anext(aiter(client.messages)), quiet_s)
        except TimeoutError:
            return got
        got.append((str(message.topic), bytes(message.payload)))  # type: ignore[arg-type]


@pytest.mark.parametrize("host", ["0.0.0.0", "192.0.2.1", "::"])
def test_non_loopback_refused_without_authentication(host: str) -> None:
    with pytest.raises(MqttError, match="without authentication"):
        EmbeddedBroker(host, 0)
    with pytest.raises(MqttError, match="without authentication"):
        EmbeddedBroker(host, 0, users={"a": "b"}, allow_anonymous=True)
    EmbeddedBroker(host, 0, users={"a": "b"})  # authenticated: allowed (not started here)
    EmbeddedBroker("127.0.0.2", 0)  # loopback


def test_publish_rights_per_user(
    embedded_broker: BrokerFactory, caplog: pytest.LogCaptureFixture
) -> None:
    broker = embedded_broker(
        users={"daemon": "pw-d", "reader": "pw-r"},
        publish_rights={"daemon": ["imubench/lab/imu0/#"]},
    )
    host, port = broker.address or ("", 0)
    caplog.set_level(logging.WARNING, logger="imubench.mqtt.broker")

    async def scenario() -> list[tuple[str, bytes]]:
        async with aiomqtt.Client(host, port, username="reader", password="pw-r") as reader:
            await reader.subscribe("#", qos=1)
            async with aiomqtt.Client(host, port, username="daemon", password="pw-d") as daemon:
                await daemon.publish("imubench/lab/imu0/status", b"online", qos=1, retain=True)
                await daemon.publish("imubench/lab/imu1/status", b"not mine", qos=1)
            await reader.publish("imubench/lab/imu0/status", b"offline", qos=1, retain=True)
            await reader.publish("imubench/lab/imu0/status", b"offline", qos=2, retain=True)
            await reader.publish("imubench/lab/imu0/status", b"offline", qos=0, retain=True)
            got = await _drain(reader)
        async with aiomqtt.Client(host, port, username="reader", password="pw-r") as late:
            await late.subscribe("imubench/#", qos=1)
            got += await _drain(late)
        return got

    got = asyncio.run(scenario())
    # Delivered once live and once as the retained status to the late subscriber.
    assert got == [("imubench/lab/imu0/status", b"online")] * 2
    assert broker.stats().denied == 4
    assert any("may not publish" in r.getMessage() for r in caplog.records)
    # Anonymous clients are refused when users are configured.
    assert not speaks_mqtt(host, port)


def test_session_taken_over_only_by_its_user(embedded_broker: BrokerFactory) -> None:
    broker = embedded_broker(users={"daemon": "pw-d", "other": "pw-o"})
    host, port = broker.address or ("", 0)

    async def scenario() -> None:
        async with aiomqtt.Client(
            host, port, username="daemon", password="pw-d", identifier="imubench-lab-imu0"
        ) as daemon:
            with pytest.raises(aiomqtt.MqttCodeError, match="identifier not valid"):
                async with aiomqtt.Client(
                    host, port, username="other", password="pw-o", identifier="imubench-lab-imu0"
                ):
                    pass
            await daemon.publish("x/y", b"still connected", qos=1)

    asyncio.run(scenario())


def test_retained_store_bounded_in_count_and_bytes(embedded_broker: BrokerFactory) -> None:
    broker = embedded_broker(max_retained=3, max_retained_bytes=2000)
    host, port = broker.address or ("", 0)

    async def retained_now() -> list[tuple[str, bytes]]:
        async with aiomqtt.Client(host, port) as sub:
            await sub.subscribe("r/#")
            return await _drain(sub)

    async def scenario() -> None:
        async with aiomqtt.Client(host, port) as pub:
            for k in range(5):
                await pub.publish(f"r/{k}", f"v{k}".encode(), qos=1, retain=True)
        assert sorted(await retained_now()) == [("r/2", b"v2"), ("r/3", b"v3"), ("r/4", b"v4")]
        stats = broker.stats()
        assert (stats.retained, stats.retained_dropped) == (3, 2)
        async with aiomqtt.Client(host, port) as pub:
            await pub.publish("r/big1", b"x" * 900, qos=1, retain=True)
            await pub.publish("r/big2", b"y" * 900, qos=1, retain=True)  # 1800 + 2 small > 2000
            await pub.publish("r/big3", b"z" * 900, qos=1, retain=True)
        kept = dict(await retained_now())
        assert set(kept) == {"r/big2", "r/big3"}
        stats = broker.stats()
        assert stats.retained_bytes == 1800 + 2 * len("r/bigN") <= 2000
        assert stats.retained_dropped == 2 + 4  # r/2, r/3, r/4 by count, r/big1 by bytes

    asyncio.run(scenario())


def test_malformed_packets_fuzz_no_traceback_no_hang(
    embedded_broker: BrokerFactory, caplog: pytest.LogCaptureFixture
) -> None:
    broker = embedded_broker(max_packet_size=64 * 1024, connect_timeout_s=2.0)
    host, port = broker.address or ("", 0)
    caplog.set_level(logging.DEBUG)
    counts = fuzz_broker(port, 2000, seed=12, max_packet_size=64 * 1024)
    assert counts["hangs"] == 0
    kinds = ("random", "truncated", "bitflip", "bad-length", "oversize")
    assert min(counts[k] for k in kinds) > 300
    tracebacks = [r for r in caplog.records if r.exc_info or "Traceback" in r.getMessage()]
    assert tracebacks == []
    assert broker.stats().malformed > 500
    assert speaks_mqtt(host, port)

    async def still_serves() -> None:
        async with aiomqtt.Client(host, port) as sub, aiomqtt.Client(host, port) as pub:
            await sub.subscribe("after/fuzz")
            await pub.publish("after/fuzz", b"ok")
            assert await _drain(sub) == [("after/fuzz", b"ok")]

    asyncio.run(still_serves())


def test_the_standalone_broker_grants_publish_rights_from_its_command_line() -> None:
    """``python -m imubench.mqtt.broker --user bench:PW`` gave that user no publish
    right and no way to grant one: a daemon pointed at it had every snapshot denied."""
    import socket
    import subprocess
    import sys
    import time

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen(
        [sys.executable, "-m", "imubench.mqtt.broker", "--port", str(port), "--exact-port",
         "--user", "bench:pw", "--publish", "bench:imubench/#"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:  # listening (anonymous CONNECTs are refused)
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                time.sleep(0.1)

        async def main() -> list[tuple[str, bytes]]:
            async with aiomqtt.Client("127.0.0.1", port, username="bench",
                                      password="pw") as sub:
                await sub.subscribe("#")
                await sub.publish("imubench/s/i/allan", b"{}", qos=1)
                await sub.publish("elsewhere/x", b"{}", qos=1)
                return await _drain(sub)

        got = asyncio.run(main())
        assert ("imubench/s/i/allan", b"{}") in got and not any(t == "elsewhere/x"
                                                                  for t, _ in got)
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_the_standalone_broker_refuses_an_open_address_in_one_line(
        capsys: pytest.CaptureFixture[str]) -> None:
    """``--host 0.0.0.0`` without ``--user`` is refused with the flag to give, not a
    traceback naming the daemon's settings."""
    from imubench.mqtt.broker import main

    with pytest.raises(SystemExit) as info:
        main(["--host", "0.0.0.0", "--port", "0"])
    assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "Traceback" not in "\n".join(err)
    assert "without authentication" in err[-1] and "--user NAME:PASSWORD" in err[-1]
    assert "mqtt.username" not in err[-1]
