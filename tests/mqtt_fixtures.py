"""Pytest fixtures that provide real MQTT brokers over TCP (never a mock).

- ``mqtt_broker`` (session): ``(host, port, kind)`` of a running broker. ``kind`` is
  ``"mosquitto"`` for the machine's mosquitto on 127.0.0.1:1883 when it answers MQTT,
  ``"private-mosquitto"`` for a mosquitto started on a free port with its own config, or
  ``"embedded"`` for imubench's own broker in a thread.
- ``private_mosquitto`` (function): a factory ``private_mosquitto(config="", port=None)``
  that starts a mosquitto with the given extra configuration on a free port (or ``port``)
  and returns a ``MosquittoProcess`` (``host``, ``port``, ``dir``, ``kill()``,
  ``restart()``, ``stop()``). Skips when no mosquitto binary is installed.
- ``embedded_broker`` (function): a factory ``embedded_broker(**kwargs)`` that starts an
  ``EmbeddedBroker`` in a thread on a free port and returns it (``.address``).

Import them in a conftest with ``from mqtt_fixtures import *``.
"""

from __future__ import annotations

import contextlib
import os
import pwd
import shutil
import signal
import socket
import subprocess
import tempfile
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from imubench.mqtt.broker import EmbeddedBroker

__all__ = [
    "DeliveryCount",
    "MosquittoProcess",
    "deliver_across_faults",
    "embedded_broker",
    "find_mosquitto",
    "free_port",
    "fuzz_broker",
    "malformed_packet",
    "mqtt_broker",
    "persistent_mosquitto_config",
    "private_mosquitto",
    "speaks_mqtt",
    "unique_prefix",
    "valid_packets",
]

LOCALHOST = "127.0.0.1"


def find_mosquitto() -> str | None:
    """Path of the mosquitto broker binary (often in /usr/sbin, outside a user's PATH)."""
    found = shutil.which("mosquitto")
    if found:
        return found
    for candidate in ("/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto"):
        if os.access(candidate, os.X_OK):
            return candidate
    return None


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((LOCALHOST, 0))
        return sock.getsockname()[1]


def unique_prefix(name: str = "test") -> str:
    """A topic prefix no other test run uses: ``imubench-test/<name>/<random>``."""
    return f"imubench-test/{name}/{uuid.uuid4().hex[:12]}"


def speaks_mqtt(host: str, port: int, timeout_s: float = 1.0) -> bool:
    """True when ``host:port`` accepts an anonymous MQTT 3.1.1 CONNECT (CONNACK code 0)."""
    client_id = b"imubench-probe-" + uuid.uuid4().hex[:8].encode()
    body = b"\x00\x04MQTT\x04\x02\x00\x05" + len(client_id).to_bytes(2, "big") + client_id
    try:
        with socket.create_connection((host, port), timeout=timeout_s) as sock:
            sock.settimeout(timeout_s)
            sock.sendall(bytes([0x10, len(body)]) + body)
            reply = sock.recv(4)
            sock.sendall(b"\xe0\x00")  # DISCONNECT
    except OSError:
        return False
    return reply == b"\x20\x02\x00\x00"


def _user_name() -> str:
    return pwd.getpwuid(os.geteuid()).pw_name


def _wait_listening(host: str, port: int, proc: subprocess.Popen[bytes], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"mosquitto exited with code {proc.returncode} at start-up")
        with contextlib.suppress(OSError), socket.create_connection((host, port), timeout=0.2):
            return
        time.sleep(0.02)
    raise RuntimeError(f"mosquitto did not listen on {host}:{port} within {timeout_s} s")


class MosquittoProcess:
    """A private mosquitto broker in a temp directory, listening on 127.0.0.1:``port``.

    ``config`` is appended to ``listener <port> 127.0.0.1``; it may refer to files in
    ``dir`` (write them before calling ``start``) e.g. a password file or certificates.
    """

    def __init__(
        self,
        binary: str,
        directory: Path,
        config: str = "",
        port: int | None = None,
        allow_anonymous: bool = True,
    ) -> None:
        self.binary = binary
        self.dir = directory
        self.host = LOCALHOST
        self.port = port or free_port()
        self.config_path = directory / "mosquitto.conf"
        self.log_path = directory / "mosquitto.log"
        lines = [
            f"listener {self.port} {self.host}",
            f"allow_anonymous {'true' if allow_anonymous else 'false'}",
            "persistence false",
            f"log_dest file {self.log_path}",
            "log_type all",
            # Run as the invoking user: as root mosquitto would switch to user 'mosquitto',
            # which cannot read pytest's private temp directories.
            f"user {_user_name()}",
            config,
        ]
        self.config_path.write_text("\n".join(lines) + "\n")
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self, timeout_s: float = 5.0) -> MosquittoProcess:
        """Start (or restart) the broker on the same port; return self."""
        if self.proc is not None and self.proc.poll() is None:
            return self
        self.proc = subprocess.Popen(
            [self.binary, "-c", str(self.config_path)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        )
        try:
            _wait_listening(self.host, self.port, self.proc, timeout_s)
        except RuntimeError as exc:
            err = self.proc.stderr.read().decode(errors="replace") if self.proc.stderr else ""
            log = self.log_path.read_text() if self.log_path.exists() else ""
            self.kill()
            raise RuntimeError(f"{exc}\nstderr: {err}\nlog: {log[-2000:]}") from None
        return self

    def kill(self) -> None:
        """SIGKILL the broker (clients see the TCP connection drop) and reap it."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(5)

    def stop(self) -> None:
        """Terminate the broker politely (SIGTERM), SIGKILL after 5 s."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.kill()

    def restart(self, timeout_s: float = 5.0) -> MosquittoProcess:
        """Kill and start again on the same port."""
        self.kill()
        return self.start(timeout_s)

    def log_text(self) -> str:
        """The broker's log so far (for assertion messages)."""
        return self.log_path.read_text(errors="replace") if self.log_path.exists() else ""


@pytest.fixture(scope="session")
def mqtt_broker() -> Iterator[tuple[str, int, str]]:
    """A real MQTT broker for the session: system mosquitto, private mosquitto, or embedded."""
    if speaks_mqtt(LOCALHOST, 1883):
        yield LOCALHOST, 1883, "mosquitto"
        return
    binary = find_mosquitto()
    if binary is not None:
        with tempfile.TemporaryDirectory(prefix="imubench-mosquitto-") as tmp:
            broker = MosquittoProcess(binary, Path(tmp))
            try:
                broker.start()
            except RuntimeError:
                broker = None  # fall through to the embedded broker
            if broker is not None:
                try:
                    yield broker.host, broker.port, "private-mosquitto"
                finally:
                    broker.stop()
                return
    embedded = EmbeddedBroker(LOCALHOST, 0)
    host, port = embedded.start_in_thread()
    try:
        yield host, port, "embedded"
    finally:
        embedded.stop_thread()


@pytest.fixture
def private_mosquitto(tmp_path: Path) -> Iterator[Callable[..., MosquittoProcess]]:
    """Factory: ``private_mosquitto(config="", port=None, allow_anonymous=True, start=True)``."""
    binary = find_mosquitto()
    if binary is None:
        pytest.skip("no mosquitto binary installed (apt-get install mosquitto)")
    started: list[MosquittoProcess] = []

    def make(
        config: str = "", port: int | None = None, allow_anonymous: bool = True, start: bool = True
    ) -> MosquittoProcess:
        directory = tmp_path / f"mosquitto-{len(started)}"
        directory.mkdir()
        broker = MosquittoProcess(binary, directory, config, port, allow_anonymous)
        started.append(broker)
        return broker.start() if start else broker

    yield make
    for broker in started:
        broker.kill()


@pytest.fixture
def embedded_broker() -> Iterator[Callable[..., EmbeddedBroker]]:
    """Factory: ``embedded_broker(**kwargs)`` -> a started thread-hosted EmbeddedBroker."""
    started: list[EmbeddedBroker] = []

    def make(**kwargs: Any) -> EmbeddedBroker:
        kwargs.setdefault("port", 0)
        broker = EmbeddedBroker(LOCALHOST, **kwargs)
        broker.start_in_thread()
        started.append(broker)
        return broker

    yield make
    for broker in started:
        broker.stop_thread()


PERSISTENT_SESSIONS = (
    "persistence true\n"
    "autosave_interval 1\n"
    "autosave_on_changes true\n"
)
"""Extra mosquitto configuration (with ``persistence_location``) that saves subscriptions
at once, so a SIGKILLed broker restarts with the subscriber's session and queues for it."""


def persistent_mosquitto_config(directory: Path) -> str:
    """``PERSISTENT_SESSIONS`` storing its database in ``directory``."""
    return PERSISTENT_SESSIONS + f"persistence_location {directory}/\n"


@dataclass
class DeliveryCount:
    """Snapshots across broker faults: produced by the publisher (``seq`` 0..produced-1),
    received by a persistent subscriber (distinct ``seq``), received more than once
    (``duplicated``), reported dropped by the publisher (``dropped``), and the publisher's
    connections (1 + reconnections)."""

    produced: int = 0
    received: int = 0
    duplicated: int = 0
    dropped: int = 0
    connections: int = 0

    @property
    def unaccounted(self) -> int:
        """produced - received - dropped: snapshots gone without being reported."""
        return self.produced - self.received - self.dropped


async def deliver_across_faults(
    broker: MosquittoProcess,
    faults: list[tuple[str, float]],
    *,
    interval_s: float = 0.1,
    settle_s: float = 1.0,
    backlog_snapshots: int = 120,
    keepalive_s: int = 30,
) -> DeliveryCount:
    """Publish a snapshot every ``interval_s`` with ``MqttPublisher`` while ``broker`` goes
    through ``faults`` (``("kill", down_s)``: SIGKILL, restart after down_s; ``("stop",
    hung_s)``: SIGSTOP, SIGCONT after hung_s), ``settle_s`` of normal service before, between
    and after; count what a QoS 1 subscriber with a persistent session receives.

    ``broker`` must be configured with ``persistent_mosquitto_config`` so its subscription
    survives a SIGKILL.
    """
    import asyncio
    import json

    import aiomqtt

    from imubench.mqtt.publisher import MqttPublisher

    station = f"f{uuid.uuid4().hex[:10]}"
    seqs: list[int] = []
    subscribed = asyncio.Event()
    stop = asyncio.Event()

    async def subscriber() -> None:
        while not stop.is_set():
            try:
                async with aiomqtt.Client(
                    broker.host, broker.port, identifier=f"sub-{station}", clean_session=False,
                    keepalive=300,
                ) as sub:
                    await sub.subscribe(f"imubench/{station}/imu0/allan", qos=1)
                    subscribed.set()
                    async for message in sub.messages:
                        seqs.append(json.loads(message.payload)["seq"])  # type: ignore[arg-type]
            except aiomqtt.MqttError:
                await asyncio.sleep(0.05)

    sub_task = asyncio.create_task(subscriber())
    await asyncio.wait_for(subscribed.wait(), 10)
    pub = MqttPublisher(
        broker.host, broker.port, station, "imu0", qos=1, keepalive_s=keepalive_s,
        backlog_snapshots=backlog_snapshots, reconnect_min_s=0.2, reconnect_max_s=2.0,
    )
    count = DeliveryCount()

    async def produce(duration_s: float) -> None:
        end = time.monotonic() + duration_s
        while time.monotonic() < end:
            await pub.publish_allan({"k": pub.produced_snapshots})
            await asyncio.sleep(interval_s)

    async with pub:
        await pub.wait_connected(10)
        await produce(settle_s)
        for kind, duration_s in faults:
            if kind == "kill":
                broker.kill()
                await produce(duration_s)
                await asyncio.to_thread(broker.start)
            elif kind == "stop":
                assert broker.proc is not None
                broker.proc.send_signal(signal.SIGSTOP)
                await produce(duration_s)
                broker.proc.send_signal(signal.SIGCONT)
            else:
                raise ValueError(f"fault {kind!r}: use 'kill' or 'stop'")
            await produce(settle_s)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and (
            pub.buffered_snapshots
            or len(set(seqs)) + pub.dropped_snapshots < pub.produced_snapshots
        ):
            await asyncio.sleep(0.05)
        count.produced = pub.produced_snapshots
        count.dropped = pub.dropped_snapshots
        count.connections = pub.connections
    stop.set()
    sub_task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await sub_task
    count.received = len(set(seqs))
    count.duplicated = len(seqs) - count.received
    return count


def _remaining_length(n: int) -> bytes:
    """MQTT variable-length integer (§2.2.3)."""
    out = bytearray()
    while True:
        n, digit = divmod(n, 128)
        out.append(digit | (0x80 if n else 0))
        if not n:
            return bytes(out)


def valid_packets(client_id: bytes = b"fuzz") -> list[bytes]:
    """Well-formed MQTT 3.1.1 packets (CONNECT first), the seeds the fuzzer damages."""

    def frame(first: int, body: bytes) -> bytes:
        return bytes([first]) + _remaining_length(len(body)) + body

    def utf8(raw: bytes) -> bytes:
        return len(raw).to_bytes(2, "big") + raw

    connect = utf8(b"MQTT") + b"\x04\x02\x00\x3c" + utf8(client_id)
    will = utf8(b"MQTT") + b"\x04\x2e\x00\x3c" + utf8(client_id) + utf8(b"w/t") + utf8(b"bye")
    return [
        frame(0x10, connect),
        frame(0x10, will),
        frame(0x30, utf8(b"a/b") + b"payload"),
        frame(0x32, utf8(b"a/b") + b"\x00\x07" + b"q1"),
        frame(0x34, utf8(b"a/b") + b"\x00\x08" + b"q2"),
        frame(0x31, utf8(b"a/r") + b"retained"),
        frame(0x82, b"\x00\x01" + utf8(b"a/#") + b"\x01"),
        frame(0xA2, b"\x00\x02" + utf8(b"a/#")),
        frame(0x62, b"\x00\x08"),
        frame(0x40, b"\x00\x01"),
        b"\xc0\x00",
        b"\xe0\x00",
    ]


def malformed_packet(rng: Any, max_packet_size: int) -> tuple[str, bytes]:
    """One damaged packet and its kind: ``random`` bytes, ``truncated`` valid packet,
    ``bitflip`` in a valid packet, ``bad-length`` (5-byte or lying remaining length),
    ``oversize`` (remaining length above ``max_packet_size``). ``rng``: numpy Generator."""
    seeds = valid_packets()
    kind = ("random", "truncated", "bitflip", "bad-length", "oversize")[int(rng.integers(5))]
    seed = seeds[int(rng.integers(len(seeds)))]
    if kind == "random":
        data = rng.bytes(int(rng.integers(1, 300)))
    elif kind == "truncated":
        data = seed[: int(rng.integers(1, len(seed)))]
    elif kind == "bitflip":
        buf = bytearray(seed)
        for _ in range(int(rng.integers(1, 4))):
            buf[int(rng.integers(len(buf)))] ^= 1 << int(rng.integers(8))
        data = bytes(buf)
    elif kind == "bad-length":
        if rng.integers(2):
            data = seed[:1] + b"\xff\xff\xff\xff\x7f" + seed[2:]  # 5 length bytes (§2.2.3)
        else:
            data = seed[:1] + _remaining_length(len(seed) + int(rng.integers(1, 1000))) + seed[2:]
    else:
        data = seed[:1] + _remaining_length(max_packet_size + int(rng.integers(1, 1 << 20)))
        data += rng.bytes(int(rng.integers(0, 2000)))
    return kind, data


def fuzz_broker(port: int, n_packets: int, seed: int = 0, max_packet_size: int = 1 << 20,
                check_every: int = 100) -> dict[str, int]:
    """Send ``n_packets`` damaged packets to the broker on 127.0.0.1:``port``, each on a new
    connection, half of them after a valid CONNECT; every ``check_every`` packets a
    well-formed client must get its CONNACK within 5 s. Returns counts per kind, plus
    ``hangs`` (well-formed clients not served)."""
    import numpy as np

    rng = np.random.default_rng(seed)
    counts: dict[str, int] = {"hangs": 0}
    connect = valid_packets(b"fuzz")[0]
    for i in range(n_packets):
        kind, data = malformed_packet(rng, max_packet_size)
        counts[kind] = counts.get(kind, 0) + 1
        with contextlib.suppress(OSError), socket.create_connection(
            (LOCALHOST, port), timeout=5
        ) as sock:
            if rng.integers(2):
                sock.sendall(connect)
            sock.sendall(data)
        if (i + 1) % check_every == 0 and not speaks_mqtt(LOCALHOST, port, timeout_s=5.0):
            counts["hangs"] += 1
    return counts
