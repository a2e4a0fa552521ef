"""The MQTT password never leaves the configuration (issue 12): ``imubench run`` with
``mqtt.username``/``password`` and the embedded broker; the broker requires them (anonymous
refused), and the password is in no log line, retained or live payload, recording or CSV
conversion of it."""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
from pathlib import Path

import aiomqtt
from mqtt_fixtures import free_port, speaks_mqtt

from imubench.config import quickstart_file

PASSWORD = "pw-Zq8v1K-never-echo"


def test_password_not_logged_published_or_recorded(tmp_path: Path) -> None:
    port = free_port()
    cfg = tmp_path / "daemon.toml"
    cfg.write_text(
        quickstart_file().read_text()
        .replace("port = 1883", f"port = {port}\nusername = \"imu\"")
        .replace('path = "recordings/', f'path = "{tmp_path}/recordings/')
        + "\n[run]\nduration_s = 6.0\n"
    )
    # Absolute import paths: the daemon runs in tmp_path and must import this tree's code.
    pythonpath = os.pathsep.join(
        os.path.abspath(p) for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p
    )
    env = dict(os.environ, PYTHONUNBUFFERED="1", IMUBENCH_MQTT__PASSWORD=PASSWORD,
               PYTHONPATH=pythonpath)
    proc = subprocess.Popen(
        [sys.executable, "-m", "imubench.cli", "-v", "run", "--config", str(cfg)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env, cwd=tmp_path,
    )

    payloads: list[bytes] = []

    async def listen() -> None:
        for _ in range(200):
            try:
                async with aiomqtt.Client("127.0.0.1", port, username="imu",
                                          password=PASSWORD) as sub:
                    await sub.subscribe("#", qos=1)

                    async def take() -> None:
                        async for message in sub.messages:
                            payloads.append(bytes(message.payload))  # type: ignore[arg-type]
                            if len(payloads) >= 4:
                                return
                    await asyncio.wait_for(take(), 30)
                    return
            except aiomqtt.MqttError:
                await asyncio.sleep(0.1)
        raise AssertionError("never subscribed to the daemon's broker")

    try:
        asyncio.run(listen())
        assert not speaks_mqtt("127.0.0.1", port)  # anonymous clients refused
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, out.decode(errors="replace")[-2000:]
    assert any(b'"state":"online"' in p for p in payloads)
    secret = PASSWORD.encode()
    assert secret not in out
    assert all(secret not in p for p in payloads)
    recs = list((tmp_path / "recordings").glob("*.imbr"))
    assert len(recs) == 1 and secret not in recs[0].read_bytes()
    csv = tmp_path / "rec.csv"
    subprocess.run([sys.executable, "-m", "imubench.cli", "convert", str(recs[0]), str(csv)],
                   check=True, capture_output=True, timeout=60)
    assert secret not in csv.read_bytes()
