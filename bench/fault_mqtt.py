"""MQTT fault matrix (issue 12 acceptance 5): the publisher against a private mosquitto that
is killed, hung and restarted, and the embedded broker under malformed packets.

Rows, in the columns of ``bench/fault_matrix.py``:

* ``broker killed 10 s``: SIGKILL, restart on the same port 10 s later.
* ``broker hung 10 s``: SIGSTOP, SIGCONT 10 s later (keep-alive 30 s: the link is kept,
  snapshots wait in the backlog for their PUBACK).
* ``broker hung 10 s, keep-alive 5 s``: the hang is detected (no PUBACK within the
  keep-alive) and the publisher reconnects; the snapshot in flight may arrive twice.
* ``broker restarted``: SIGKILL and immediate restart.
* ``malformed packets``: ``--packets`` damaged packets (random bytes, truncated and bit-
  flipped valid packets, bad and oversize remaining lengths) to ``python -m
  imubench.mqtt.broker`` in its own process; tracebacks in its output, hangs (a well-formed
  client not served within 5 s, checked every 100 packets) and its RSS before/after.

Snapshots: one every 0.1 s (10x the default cadence), QoS 1, backlog 120; a QoS 1 subscriber
with a persistent session counts distinct ``seq`` values (delivered), repeats (duplicated);
the publisher reports ``dropped_snapshots`` (lost, accounted); unaccounted = produced -
delivered - lost.

Run: ``PYTHONPATH=src:drivers:simulator .venv/bin/python bench/fault_mqtt.py [--repeats 3]
[--packets 100000] [--quick]``.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO / "bench"), str(REPO / "tests")]

from fault_matrix import Row  # noqa: E402
from mqtt_fixtures import (  # noqa: E402
    MosquittoProcess,
    deliver_across_faults,
    find_mosquitto,
    free_port,
    fuzz_broker,
    persistent_mosquitto_config,
    speaks_mqtt,
)


class _Tracebacks(logging.Handler):
    """Counts log records carrying an exception (a traceback in the log)."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.count = 0

    def emit(self, record: logging.LogRecord) -> None:
        if record.exc_info or "Traceback" in record.getMessage():
            self.count += 1


def broker_faults(case: str, faults: list[tuple[str, float]], repeats: int,
                  keepalive_s: int = 30) -> Row:
    row = Row(case)
    binary = find_mosquitto()
    if binary is None:
        row.note = "skipped: no mosquitto"
        return row
    handler = _Tracebacks()
    logging.getLogger().addHandler(handler)
    reconnects = 0
    try:
        for _ in range(repeats):
            with tempfile.TemporaryDirectory(prefix="fault-mqtt-") as tmp:
                broker = MosquittoProcess(binary, Path(tmp),
                                          persistent_mosquitto_config(Path(tmp)))
                broker.start()
                try:
                    count = asyncio.run(deliver_across_faults(
                        broker, faults, keepalive_s=keepalive_s, settle_s=2.0))
                finally:
                    broker.kill()
            row.repeats += 1
            row.delivered += count.received
            row.lost += count.dropped
            row.unaccounted += count.unaccounted
            row.duplicated += count.duplicated
            row.hangs += count.unaccounted > 0 and count.received + count.dropped == 0
            reconnects += count.connections - 1
    finally:
        logging.getLogger().removeHandler(handler)
    row.tracebacks = handler.count
    row.note = f"reconnections {reconnects}; produced {row.delivered + row.lost + row.unaccounted}"
    return row


def _rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise RuntimeError(f"no VmRSS for pid {pid}")


def malformed(n_packets: int) -> Row:
    row = Row(f"malformed packets to the embedded broker ({n_packets})")
    port = free_port()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        str(REPO / d) for d in ("src", "drivers", "simulator")))
    with tempfile.TemporaryFile() as log:
        proc = subprocess.Popen([sys.executable, "-m", "imubench.mqtt.broker", "--port",
                                 str(port), "--exact-port"], stdout=log, stderr=log, env=env)
        try:
            end = time.monotonic() + 20
            while not speaks_mqtt("127.0.0.1", port) and time.monotonic() < end:
                time.sleep(0.1)
            rss0 = _rss_kib(proc.pid)
            t0 = time.monotonic()
            counts = fuzz_broker(port, n_packets, seed=1)
            elapsed = time.monotonic() - t0
            rss1 = _rss_kib(proc.pid)
            served = speaks_mqtt("127.0.0.1", port, timeout_s=5.0)
        finally:
            proc.terminate()
            proc.wait(10)
        log.seek(0)
        text = log.read().decode(errors="replace")
    row.repeats = 1
    row.delivered = n_packets
    row.tracebacks = text.count("Traceback")
    row.hangs = counts.pop("hangs") + (not served)
    kinds = ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
    row.note = (f"{kinds}; broker RSS {rss0 / 1024:.1f} -> {rss1 / 1024:.1f} MiB; "
                f"{n_packets / elapsed:.0f} packets/s")
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--packets", type=int, default=100_000)
    ap.add_argument("--quick", action="store_true", help="1 repeat, 2 s faults, 2000 packets")
    args = ap.parse_args()
    down = 10.0
    if args.quick:
        args.repeats, args.packets, down = 1, 2000, 2.0
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(levelname)s %(message)s")
    print(f"machine: {os.uname().nodename} {os.cpu_count()} cores; "
          f"{time.strftime('%Y-%m-%d %H:%M')}", flush=True)
    rows = [
        broker_faults(f"broker killed {down:g} s", [("kill", down)], args.repeats),
        broker_faults(f"broker hung (SIGSTOP) {down:g} s", [("stop", down)], args.repeats),
        broker_faults(f"broker hung {down:g} s, keep-alive 5 s", [("stop", down)],
                      args.repeats, keepalive_s=5),
        broker_faults("broker restarted (kill + start)", [("kill", 0.0)], args.repeats),
        malformed(args.packets),
    ]
    print("| case | repeats | delivered | lost (accounted) | unaccounted | duplicated | "
          "tracebacks | hangs | note |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(r.line())


if __name__ == "__main__":
    main()
