"""The live view in a real headless Chromium (Debian ``chromium``), driven by Playwright's
Python package with the system browser (nothing is downloaded or installed here; the
test skips, saying why, when either is missing).

A simulated daemon (``imubench run``, embedded broker) and ``imubench view`` run as
subprocesses. The page must load, show the sensor's curves, gain points as the daemon
runs, show a published jig result and an injected ``offline`` status, and raise no script
error. The screenshot and
the measured delay from the first snapshot to the page showing it are kept in
``tests/artifacts/`` (ignored by git).
"""

from __future__ import annotations

import json
import shutil
import threading
import time
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
import pytest
from fleet_helpers import daemon_config, start_daemon, start_view
from mqtt_fixtures import free_port

ARTIFACTS = Path(__file__).resolve().parent / "artifacts"
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMIUM_FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update",
                  "--disable-sync"]


def chromium_or_skip() -> str:
    if not Path(CHROMIUM).is_file():
        pytest.skip("Debian chromium is not installed (/usr/bin/chromium): "
                    "apt-get install chromium to run the browser test")
    pytest.importorskip("playwright.sync_api",
                        reason="the playwright Python package is not installed (dev extra)")
    return CHROMIUM


class FirstSnapshot:
    """An independent MQTT subscriber noting when the first allan snapshot arrived."""

    def __init__(self, port: int, topic: str) -> None:
        self.at: float | None = None
        self.got = threading.Event()
        self.client = paho.Client(paho.CallbackAPIVersion.VERSION2)
        self.client.on_connect = lambda c, *a: c.subscribe(topic)
        self.client.on_message = self._message
        self.client.connect("127.0.0.1", port)
        self.client.loop_start()

    def _message(self, client: Any, userdata: Any, msg: Any) -> None:
        if self.at is None:
            self.at = time.monotonic()
            self.got.set()

    def close(self) -> None:
        self.client.loop_stop()
        self.client.disconnect()


def publish_retained(port: int, topic: str, payload: bytes) -> None:
    c = paho.Client(paho.CallbackAPIVersion.VERSION2)
    c.connect("127.0.0.1", port)
    c.loop_start()
    c.publish(topic, payload, qos=1, retain=True).wait_for_publish(5)
    c.loop_stop()
    c.disconnect()


def test_live_view_in_chromium(tmp_path: Path) -> None:
    chromium = chromium_or_skip()
    from playwright.sync_api import sync_playwright

    ARTIFACTS.mkdir(exist_ok=True)
    station, sensor = "browser", "imu0"
    cfg = daemon_config(tmp_path / "d.toml", broker="embedded", station=station,
                        sensor=sensor, port=free_port())
    daemon = start_daemon(cfg, tmp_path)
    view = None
    first = None
    try:
        port = int(daemon.wait_for(r"embedded MQTT broker listening on mqtt://[\d.]+:(\d+)",
                                   60).group(1))
        first = FirstSnapshot(port, f"imubench/{station}/{sensor}/allan")
        view, url = start_view(f"mqtt://127.0.0.1:{port}", tmp_path)
        errors: list[str] = []
        with sync_playwright() as p:
            ctx = p.chromium.launch_persistent_context(
                str(tmp_path / "chromium-profile"), executable_path=chromium, headless=True,
                args=CHROMIUM_FLAGS, viewport={"width": 1400, "height": 1000})
            page = ctx.new_page()
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(url)
            loaded_at = time.monotonic()
            assert page.title() == "imubench live view"
            card = page.locator(f'section.sensor[data-key="{station}/{sensor}"]')
            page.wait_for_function(
                "k => { const c = document.querySelector(`section[data-key='${k}']`);"
                " return c && Number(c.dataset.points) > 0; }",
                arg=f"{station}/{sensor}", timeout=60_000)
            shown_at = time.monotonic()
            assert first.got.wait(5)
            assert first.at is not None
            delay_s = shown_at - max(first.at, loaded_at)
            points0 = int(card.get_attribute("data-points") or 0)
            assert card.get_attribute("data-state") == "online"
            assert page.locator("#broker").get_attribute("data-connected") == "true"
            # two uPlot canvases (gyro, accel) and the readouts of six channels
            assert card.locator(".plot canvas").count() == 2
            assert card.locator("table.readouts tr[data-channel]").count() == 6
            page.wait_for_function(
                "([k, n]) => Number(document.querySelector(`section[data-key='${k}']`)"
                ".dataset.points) > n", arg=[f"{station}/{sensor}", points0], timeout=30_000)
            points1 = int(card.get_attribute("data-points") or 0)
            samples = int(card.get_attribute("data-samples") or 0)
            jig = {"verdict": "pass", "measurements": [
                {"name": "gyro noise density", "value": 4.1, "unit": "mdps/√Hz", "low": None,
                 "high": 6.0, "ci_low": 3.9, "ci_high": 4.3, "verdict": "pass"}]}
            publish_retained(port, f"imubench/{station}/{sensor}/jig",
                             json.dumps(jig).encode())
            card.locator(".jig table.jig-measurements").wait_for(timeout=10_000)
            assert card.locator(".jig h3").inner_text() == "jig: pass"
            assert card.locator(".jig table.jig-measurements tr").count() == 2
            page.screenshot(path=str(ARTIFACTS / "live-view-online.png"), full_page=True)

            publish_retained(port, f"imubench/{station}/{sensor}/status", b"offline")
            page.wait_for_function(
                "k => document.querySelector(`section[data-key='${k}']`).dataset.state"
                " === 'offline'", arg=f"{station}/{sensor}", timeout=10_000)
            assert card.locator(".state").inner_text() == "offline"
            page.screenshot(path=str(ARTIFACTS / "live-view-offline.png"), full_page=True)
            ctx.close()
        assert errors == [], errors
        result = {"first_snapshot_to_shown_s": round(delay_s, 3), "points_first": points0,
                  "points_later": points1, "samples": samples}
        (ARTIFACTS / "live-view.json").write_text(json.dumps(result, indent=1) + "\n")
        print(f"\nlive view: {result}; screenshots in {ARTIFACTS}")
        assert points1 > points0 and samples > 0
    finally:
        if first is not None:
            first.close()
        if view is not None:
            view.stop()
        daemon.stop()
