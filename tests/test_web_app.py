"""The live view's server (imubench.web) over real TCP: a private mosquitto, messages
published by a real MQTT client, the page, its static files, /api/fleet and the
server-sent event stream; the password rule and HTTP basic authentication."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import subprocess
import sys
import urllib.error
import urllib.request
from collections.abc import AsyncIterator
from typing import Any

import aiomqtt
import pytest
from test_fleet_inventory import online, snapshot

from imubench.fleet import FleetError
from imubench.web.server import LiveView, ViewOptions, check_exposure, parse_listen

STATION = "webtest"
T = f"imubench/{STATION}/imu0"


def http_get(url: str, auth: tuple[str, str] | None = None) -> tuple[int, dict[str, str], bytes]:
    req = urllib.request.Request(url)
    if auth is not None:
        token = base64.b64encode(f"{auth[0]}:{auth[1]}".encode()).decode()
        req.add_header("Authorization", f"Basic {token}")
    try:
        with urllib.request.urlopen(req, timeout=5) as resp:
            return resp.status, dict(resp.headers), resp.read()
    except urllib.error.HTTPError as exc:
        return exc.code, dict(exc.headers), exc.read()


@contextlib.asynccontextmanager
async def live_view(broker_port: int, **options: Any) -> AsyncIterator[tuple[LiveView, str]]:
    """A started LiveView on a free loopback port; (view, base URL)."""
    view = LiveView(ViewOptions(broker=f"mqtt://127.0.0.1:{broker_port}",
                                listen="127.0.0.1:0", **options))
    host, port = await view.start()
    try:
        yield view, f"http://{host}:{port}/"
    finally:
        await view.stop()


async def sse_events(host: str, port: int) -> AsyncIterator[tuple[str, Any]]:
    """(event, data) pairs from GET /events, parsed from the raw byte stream."""
    reader, writer = await asyncio.open_connection(host, port)
    writer.write(f"GET /events HTTP/1.1\r\nHost: {host}\r\nAccept: text/event-stream\r\n\r\n"
                 .encode())
    await writer.drain()
    head = await reader.readuntil(b"\r\n\r\n")
    assert b"200" in head.split(b"\r\n")[0] and b"text/event-stream" in head
    event, data = None, []
    try:
        while True:
            line = (await reader.readline()).decode().rstrip("\r\n")
            if line.startswith("event: "):
                event = line[7:]
            elif line.startswith("data: "):
                data.append(line[6:])
            elif line == "" and event is not None:
                yield event, json.loads("\n".join(data))
                event, data = None, []
    finally:
        writer.close()


async def until(events: AsyncIterator[tuple[str, Any]], pred: Any, timeout_s: float) -> Any:
    async def scan() -> Any:
        async for ev, data in events:
            if pred(ev, data):
                return data
        raise AssertionError("event stream ended")

    return await asyncio.wait_for(scan(), timeout_s)


def test_view_with_mosquitto_end_to_end(private_mosquitto: Any) -> None:
    broker = private_mosquitto()

    async def main() -> None:
        async with live_view(broker.port) as (view, base):
            await asyncio.wait_for(view.listener.subscribed.wait(), 10)
            events = sse_events("127.0.0.1", view.port)
            b = await until(events, lambda e, d: e == "broker", 5)
            assert b["connected"] is True and b["url"] == f"mqtt://127.0.0.1:{broker.port}"
            async with aiomqtt.Client("127.0.0.1", broker.port) as pub:
                await pub.publish(f"{T}/status", online(recording_bytes=2048), qos=1,
                                  retain=True)
                await pub.publish(f"{T}/allan", snapshot(104, "2026-11-23T10:00:01+00:00"))
                await pub.publish(f"{T}/jig", json.dumps(
                    {"verdict": "fail", "measurements": [{"name": "bias", "value": 9.0,
                     "unit": "dps", "low": -5, "high": 5, "ci_low": 8.5, "ci_high": 9.5,
                     "verdict": "fail"}]}))
                seen = await until(events, lambda e, d: e == "sensor" and d["jig"]
                                   and d["statistics"], 10)
                assert seen["key"] == f"{STATION}/imu0" and seen["state"] == "online"
                assert seen["statistics"]["oadev"]["gx"]["tau_s"] == [0.01, 0.02, 0.04]
                assert seen["jig"]["verdict"] == "fail"

                status, _, body = await asyncio.to_thread(http_get, base + "api/fleet")
                assert status == 200
                fleet = json.loads(body)
                (s,) = [x for x in fleet["sensors"] if x["station"] == STATION]
                assert {h["key"]: h["value"] for h in s["health"]}["recording_bytes"] == 2048

                await pub.publish(f"{T}/status", b"offline", qos=1, retain=True)
                off = await until(events, lambda e, d: e == "sensor"
                                  and d["state"] == "offline", 5)
                assert off["status_state"] == "offline"
                await pub.publish(f"{T}/status", b"", qos=1, retain=True)  # clear
                gone = await until(events, lambda e, d: e == "remove", 5)
                assert gone == {"key": f"{STATION}/imu0"}
            await events.aclose()

            status, _, body = await asyncio.to_thread(http_get, base)
            assert status == 200 and b"static/vendor/uPlot.iife.min.js" in body
            status, _, js = await asyncio.to_thread(
                http_get, base + "static/vendor/uPlot.iife.min.js")
            assert status == 200 and js.startswith(b"/*! https://github.com/leeoniya/uPlot")
            status, _, lic = await asyncio.to_thread(
                http_get, base + "static/vendor/uPlot.LICENSE")
            assert status == 200 and b"MIT License" in lic

    asyncio.run(main())


def test_view_follows_a_broker_restart(private_mosquitto: Any) -> None:
    broker = private_mosquitto()

    async def main() -> None:
        async with live_view(broker.port) as (view, _):
            await asyncio.wait_for(view.listener.subscribed.wait(), 10)
            broker.kill()
            for _ in range(100):
                if not view.listener.connected:
                    break
                await asyncio.sleep(0.05)
            assert not view.listener.connected and view.listener.last_error
            broker.start()
            for _ in range(400):  # reconnection backoff 0.5, 1, 2, ... s
                if view.listener.connected:
                    break
                await asyncio.sleep(0.05)
            assert view.listener.connected and view.listener.connections == 2

    asyncio.run(main())


def test_basic_auth_on_every_route(private_mosquitto: Any) -> None:
    broker = private_mosquitto()

    async def main() -> None:
        async with live_view(broker.port, password="s3cret") as (_, base):
            for path in ("", "api/fleet", "static/view.js", "events"):
                status, headers, _ = await asyncio.to_thread(http_get, base + path)
                assert status == 401, path
                assert headers["www-authenticate"].startswith('Basic realm="imubench"')
            status, _, _ = await asyncio.to_thread(http_get, base + "api/fleet",
                                                   ("imubench", "wrong"))
            assert status == 401
            status, _, body = await asyncio.to_thread(http_get, base + "api/fleet",
                                                      ("imubench", "s3cret"))
            assert status == 200 and "sensors" in json.loads(body)

    asyncio.run(main())


def test_a_view_without_a_password_answers_to_loopback_names_only(
        private_mosquitto: Any) -> None:
    """DNS rebinding: a page on another site that points its own name at 127.0.0.1 could
    read the fleet (hosts, pids, recording paths) from a view without a password; such a
    Host is refused."""
    from imubench.web.app import host_name

    assert [host_name(h) for h in (b"[::1]:8080", b"localhost:80", b"Evil.example")] == \
        ["::1", "localhost", "evil.example"]
    broker = private_mosquitto()

    async def main() -> None:
        async with live_view(broker.port) as (_, base):
            port = base.rstrip("/").rsplit(":", 1)[1]
            for host, want in ((f"attacker.example:{port}", 421), ("localhost", 200),
                               (f"127.0.0.1:{port}", 200)):
                req = urllib.request.Request(base + "api/fleet", headers={"Host": host})
                try:
                    status = (await asyncio.to_thread(urllib.request.urlopen, req, None,
                                                      5)).status
                except urllib.error.HTTPError as exc:
                    status = exc.code
                assert status == want, host

    asyncio.run(main())


@pytest.mark.parametrize("listen", ["0.0.0.0:8080", "192.168.1.5:80", "[::]:8080"])
def test_non_loopback_needs_a_password(listen: str) -> None:
    host, _ = parse_listen(listen)
    with pytest.raises(FleetError, match="--password-file"):
        check_exposure(host, None)
    check_exposure(host, "pw")  # accepted with one


@pytest.mark.parametrize("listen", ["127.0.0.1:8080", "localhost:0", "[::1]:8080",
                                    "127.0.0.2:1"])
def test_loopback_needs_none(listen: str) -> None:
    check_exposure(parse_listen(listen)[0], None)


@pytest.mark.parametrize(("bad", "says"), [
    ("8080", "no port"), ("host:", "no port"), ("host:http", "not a number"),
    ("127.0.0.1:70000", "outside 0-65535"),
    (":8080", "no host; use 127.0.0.1:8080"),  # it said "no port"
])
def test_bad_listen_addresses(bad: str, says: str) -> None:
    with pytest.raises(FleetError, match="--listen") as info:
        parse_listen(bad)
    assert says in str(info.value)


def test_cli_refuses_an_exposed_view_without_password(tmp_path: Any) -> None:
    proc = subprocess.run([sys.executable, "-m", "imubench.cli", "view", "--listen",
                           "0.0.0.0:0"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert "imubench view: error: listening on 0.0.0.0 exposes the view" in proc.stderr
    empty = tmp_path / "pw"
    for text in ("", "   \n"):  # blanks only were taken as a password
        empty.write_text(text)
        proc = subprocess.run([sys.executable, "-m", "imubench.cli", "view", "--listen",
                               "0.0.0.0:0", "--password-file", str(empty)],
                              capture_output=True, text=True, timeout=60)
        assert proc.returncode == 2 and "line 1 is empty or blank" in proc.stderr
