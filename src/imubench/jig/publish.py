"""Publication of a jig result on ``imubench/<station>/<sensor>/jig``.

One JSON message per run, **retained**, QoS 1 by default: the topic holds the station's
latest verdict, so a dashboard or line controller that connects after the run (or
restarts) still finds it; the next run replaces it. Payload::

    {"verdict": "PASS|FAIL|INCONCLUSIVE", "serial": ..., "station": ..., "sensor": ...,
     "run_id": ..., "time": ISO-8601 UTC, "exit_status": 0|1|3,
     "measurements": [{"name", "value", "unit", "low", "high", "ci_low", "ci_high",
                       "verdict"}, ...],
     "broken_tests": [{"test": nodeid, "reason": text}, ...]}

``broken_tests`` are the tests that failed without a measurement (a FAIL with every
measurement PASS is one of them, with its reason).

NaN becomes null (JSON). The broker is the station's ``mqtt.broker``
(``mqtt://host:port`` or ``mqtts://``), through aiomqtt like the daemon's publisher
(:func:`imubench.mqtt.publisher.parse_broker_url`, ``encode_json``).
"""

from __future__ import annotations

import asyncio
import ssl
from typing import Any

import aiomqtt

from imubench.jig.errors import JigError
from imubench.jig.station import MqttSection
from imubench.mqtt.publisher import encode_json, parse_broker_url
from imubench.mqtt.topics import base_topic

PAYLOAD_KEYS = ("name", "value", "unit", "low", "high", "ci_low", "ci_high", "verdict")


def jig_topic(station: str, sensor: str) -> str:
    """``imubench/<station>/<sensor>/jig`` (both names validated as topic levels)."""
    return f"{base_topic(station, sensor)}/jig"


def payload(result: dict[str, Any]) -> dict[str, Any]:
    """The message for ``result`` (a result.json document)."""
    return {
        "verdict": result["verdict"],
        "serial": result["serial"],
        "station": result["station"],
        "sensor": result["sensor"],
        "run_id": result["run_id"],
        "time": result["finished_utc"],
        "exit_status": result["exit_status"],
        "measurements": [{k: m[k] for k in PAYLOAD_KEYS} for m in result["measurements"]],
        "broken_tests": [{"test": t, "reason": result.get("broken_reasons", {}).get(t, "")}
                         for t in result["broken_tests"]],
    }


async def _publish(cfg: MqttSection, topic: str, data: bytes) -> None:
    assert cfg.broker is not None
    addr = parse_broker_url(cfg.broker)
    tls = ssl.create_default_context(cafile=cfg.tls_ca) if addr.tls else None
    async with aiomqtt.Client(addr.host, addr.port, username=cfg.username,
                              password=cfg.password, tls_context=tls,
                              timeout=cfg.timeout_s) as client:
        await client.publish(topic, data, qos=cfg.qos, retain=True, timeout=cfg.timeout_s)


def publish_result(cfg: MqttSection, result: dict[str, Any]) -> str:
    """Publish ``result`` (retained); returns the topic. Raises JigError on failure."""
    topic = jig_topic(result["station"], result["sensor"])
    try:
        asyncio.run(asyncio.wait_for(_publish(cfg, topic, encode_json(payload(result))),
                                     cfg.timeout_s + 5.0))
    except (aiomqtt.MqttError, OSError, TimeoutError) as exc:
        raise JigError(f"MQTT broker {cfg.broker}: could not publish the jig result on"
                       f" {topic} ({exc})") from None
    return topic


__all__ = ["PAYLOAD_KEYS", "jig_topic", "payload", "publish_result"]
