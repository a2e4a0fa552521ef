"""MQTT faults (issue 12 acceptance 5): the broker stopped, killed and hung (SIGSTOP) under
a running daemon; malformed packets to the embedded broker.

Broker cases, each ``--repeats`` times, on a private Mosquitto (``persistence true``, on
a free loopback port): ``imubench run`` (simulated LSM6DSL at 104 Hz in real time, a
snapshot every 0.5 s, QoS 1, keep-alive 5 s, backlog 120 snapshots) publishes; at 8 s
the broker is stopped (SIGTERM) or killed (SIGKILL) and started again 5 s later, or hung
with SIGSTOP for 10 s then SIGCONT; at 30 s the daemon gets SIGINT. A subscriber with a
persistent session (QoS 1, reconnecting) collects the snapshots' ``seq``. Produced = the
last ``seq`` + 1 (the final snapshot), delivered = distinct ``seq`` received, lost
(accounted) = the daemon's ``health.mqtt.dropped_snapshots``, unaccounted = produced -
delivered - accounted, duplicated = deliveries beyond the first of a ``seq`` (a snapshot
the broker had taken but not acknowledged before it hung is sent again: QoS 1 is "at
least once"; subscribers deduplicate by ``seq``). Messages a SIGKILLed broker had
acknowledged but not yet delivered are the broker's loss (Mosquitto keeps them only in
memory between saves); they show as unaccounted in the ``kill`` row.

Malformed packets: ``--packets`` random byte strings, truncated and corrupted valid
packets, bad remaining lengths and oversize packets, each on its own TCP connection to
the embedded broker; then a well-formed client must still publish and receive.
Tracebacks are counted from the broker's log records (any record with exception info).

Run: ``.venv/bin/python bench/fault_mqtt.py [--repeats 3] [--packets 100000] [--quick]``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

import aiomqtt

REPO = Path(__file__).resolve().parents[1]
STATION = "faultbench"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Mosquitto:
    def __init__(self, tmp: Path) -> None:
        self.port = free_port()
        self.tmp = tmp
        conf = tmp / "mosquitto.conf"
        conf.write_text(f"listener {self.port} 127.0.0.1\nallow_anonymous true\n"
                        f"persistence true\npersistence_location {tmp}/\n"
                        "autosave_interval 1\nlog_dest none\n")
        self.conf = conf
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self) -> None:
        self.proc = subprocess.Popen(["mosquitto", "-c", str(self.conf)])
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", self.port)) == 0:
                    return
            time.sleep(0.05)
        raise RuntimeError("mosquitto did not start")

    def signal(self, sig: int) -> None:
        assert self.proc is not None
        self.proc.send_signal(sig)
        if sig in (signal.SIGTERM, signal.SIGKILL):
            self.proc.wait(10)


def subscriber(port: int, seqs: list[int], last: dict[str, object],
               stop: threading.Event) -> None:
    async def main() -> None:
        while not stop.is_set():
            try:
                async with aiomqtt.Client("127.0.0.1", port, identifier="fault-sub",
                                          clean_session=False, keepalive=5) as c:
                    await c.subscribe(f"imubench/{STATION}/imu0/allan", qos=1)
                    async for m in c.messages:
                        doc = json.loads(bytes(m.payload))  # type: ignore[arg-type]
                        seqs.append(int(doc["seq"]))
                        last.update(doc)
                        if stop.is_set():
                            return
            except aiomqtt.MqttError:
                await asyncio.sleep(0.1)

    asyncio.run(main())


def broker_case(kind: str, repeats: int) -> dict[str, object]:
    row: dict[str, object] = {"case": f"broker {kind}", "repeats": repeats, "delivered": 0,
                              "lost": 0, "unaccounted": 0, "duplicated": 0, "tracebacks": 0,
                              "hangs": 0}
    for _ in range(repeats):
        tmp = Path(tempfile.mkdtemp(prefix="imubench-fault-mqtt-"))
        broker = Mosquitto(tmp)
        broker.start()
        cfg = tmp / "d.toml"
        cfg.write_text(
            '[source]\nuri = "sim://lsm6dsl?odr_hz=104&seed=1&clock=wall"\n'
            '[log]\nenabled = false\n[allan]\nstats = ["oadev"]\n'
            f'[mqtt]\nbroker = "mqtt://127.0.0.1:{broker.port}"\nstation = "{STATION}"\n'
            'sensor = "imu0"\npublish_interval_s = 0.5\nqos = 1\nkeepalive_s = 5\n'
            'backlog_snapshots = 120\n[display]\nlive_table = "off"\n')
        seqs: list[int] = []
        last: dict[str, object] = {}
        stop = threading.Event()
        sub = threading.Thread(target=subscriber, args=(broker.port, seqs, last, stop),
                               daemon=True)
        sub.start()
        time.sleep(1.0)
        daemon = subprocess.Popen([sys.executable, "-m", "imubench", "run", "--config",
                                   str(cfg)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                  text=True, cwd=tmp)
        time.sleep(8)
        if kind == "sigstop-10s":
            broker.signal(signal.SIGSTOP)
            time.sleep(10)
            broker.signal(signal.SIGCONT)
        else:
            broker.signal(signal.SIGTERM if kind == "stop" else signal.SIGKILL)
            time.sleep(5)
            broker.start()
        time.sleep(30 - 8 - (10 if kind == "sigstop-10s" else 5))
        daemon.send_signal(signal.SIGINT)
        try:
            out, _ = daemon.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            daemon.kill()
            out, _ = daemon.communicate()
            row["hangs"] = int(row["hangs"]) + 1  # type: ignore[call-overload]
        time.sleep(2)  # the last deliveries
        stop.set()
        broker.signal(signal.SIGTERM)
        sub.join(10)
        shutil.rmtree(tmp, ignore_errors=True)
        row["tracebacks"] = int(row["tracebacks"]) + out.count("Traceback")  # type: ignore[call-overload]
        if not seqs:
            row["unaccounted"] = -1
            continue
        health = last.get("health", {})
        dropped = int(health["mqtt"]["dropped_snapshots"])  # type: ignore[index]
        produced = max(seqs) + 1
        distinct = len(set(seqs))
        row["delivered"] = int(row["delivered"]) + distinct  # type: ignore[call-overload]
        row["lost"] = int(row["lost"]) + dropped  # type: ignore[call-overload]
        row["unaccounted"] = int(row["unaccounted"]) + produced - distinct - dropped  # type: ignore[call-overload]
        row["duplicated"] = int(row["duplicated"]) + sum(  # type: ignore[call-overload]
            n - 1 for n in Counter(seqs).values())
    return row


class _Tracebacks(logging.Handler):
    def __init__(self) -> None:
        super().__init__()
        self.count = 0

    def emit(self, record: logging.LogRecord) -> None:
        if record.exc_info:
            self.count += 1


def _malformed(rng: random.Random) -> bytes:
    connect = (b"\x10\x0c\x00\x04MQTT\x04\x02\x00\x3c\x00\x00")
    publish = b"\x30\x0b\x00\x03a/b" + b"hello!"
    kind = rng.randrange(5)
    if kind == 0:
        return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 64)))
    if kind == 1:
        pkt = connect + publish
        return pkt[: rng.randrange(1, len(pkt))]
    if kind == 2:
        pkt = bytearray(connect + publish)
        for _ in range(rng.randint(1, 4)):
            pkt[rng.randrange(len(pkt))] = rng.randrange(256)
        return bytes(pkt)
    if kind == 3:  # remaining length with a fifth continuation byte
        return connect + b"\x30\xff\xff\xff\xff\x01"
    return connect + b"\x30\xff\xff\xff\x7f" + bytes(4096)  # announces 256 MiB


def malformed_case(n: int, seed: int = 1) -> dict[str, object]:
    sys.path.insert(0, str(REPO / "src"))
    from imubench.mqtt.broker import EmbeddedBroker

    handler = _Tracebacks()
    logging.getLogger("imubench").addHandler(handler)
    broker = EmbeddedBroker("127.0.0.1", 0, max_packet_size=64 * 1024)
    host, port = broker.start_in_thread()
    rng = random.Random(seed)
    hangs = 0
    t0 = time.monotonic()
    for _ in range(n):
        with socket.socket() as s:
            s.settimeout(2.0)
            try:
                s.connect((host, port))
                s.sendall(_malformed(rng))
                s.shutdown(socket.SHUT_WR)
                while s.recv(4096):
                    pass
            except TimeoutError:
                hangs += 1
            except OSError:
                pass
    took = time.monotonic() - t0

    async def still_serves() -> bool:
        async with aiomqtt.Client(host, port) as c:
            await c.subscribe("ok/#", qos=1)
            await c.publish("ok/1", b"x", qos=1)
            async for m in c.messages:
                return bytes(m.payload) == b"x"  # type: ignore[arg-type]
        return False

    served = asyncio.run(asyncio.wait_for(still_serves(), 10))
    broker.stop_thread()
    logging.getLogger("imubench").removeHandler(handler)
    return {"case": f"malformed packets ({took:.0f} s)", "repeats": n,
            "delivered": int(served), "lost": 0, "unaccounted": 0 if served else 1,
            "duplicated": 0, "tracebacks": handler.count, "hangs": hangs}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--packets", type=int, default=100_000)
    ap.add_argument("--quick", action="store_true", help="1 repeat, 2000 packets")
    args = ap.parse_args()
    if args.quick:
        args.repeats, args.packets = 1, 2000
    print(f"machine: {os.uname().nodename} {os.cpu_count()} cores; "
          f"{time.strftime('%Y-%m-%d %H:%M')}; load {os.getloadavg()[0]:.2f}")
    rows = [broker_case(k, args.repeats) for k in ("stop", "kill", "sigstop-10s")]
    rows.append(malformed_case(args.packets))
    print("| case | repeats | delivered | lost (accounted) | unaccounted | duplicated | "
          "tracebacks | hangs |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(str(r[k]) for k in ("case", "repeats", "delivered", "lost",
                                                     "unaccounted", "duplicated",
                                                     "tracebacks", "hangs")) + " |")


if __name__ == "__main__":
    main()
