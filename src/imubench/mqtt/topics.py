"""MQTT topic names for imubench and the topic-filter rules of MQTT 3.1.1 section 4.7.

imubench publishes under ``imubench/<station>/<sensor>/...``:

- ``allan``: a JSON snapshot of the Allan deviations, once per second, not retained;
- ``status``: retained; JSON ``{"state": "online", ...}`` while the daemon runs, the plain
  string ``offline`` after a clean stop or as the broker-published last will.
"""

from __future__ import annotations

from imubench.mqtt.errors import MqttError

TOPIC_ROOT = "imubench"
MAX_LEVEL_LENGTH = 64
"""Longest station or sensor name accepted, in characters."""

_FORBIDDEN = {
    "+": "'+' (MQTT single-level wildcard)",
    "#": "'#' (MQTT multi-level wildcard)",
    "/": "'/' (MQTT topic level separator)",
    "\x00": "NUL (U+0000)",
}


def validate_topic_level(name: str, what: str) -> str:
    """Check that ``name`` can be used as one level of an MQTT topic name and return it.

    Rules (MQTT 3.1.1 sections 1.5.3 and 4.7): a topic level must not contain the
    wildcards ``+`` or ``#``, the separator ``/`` or NUL; imubench also refuses empty names,
    names longer than ``MAX_LEVEL_LENGTH`` characters, leading/trailing whitespace, control
    characters, and a leading ``$`` (``$``-topics are reserved for brokers).

    ``what`` names the thing being checked in the error message, e.g. ``"mqtt.station"``.
    Raises ``MqttError`` naming the bad value and what is allowed.
    """
    allowed = (
        f"use 1 to {MAX_LEVEL_LENGTH} printable characters without '+', '#', '/', "
        "NUL or a leading '$', e.g. 'lab1' or 'lsm6dsl-0x6a'"
    )
    if not isinstance(name, str):
        raise MqttError(f"{what} must be a string, got {type(name).__name__} {name!r}; {allowed}")
    if not name:
        raise MqttError(f"{what} is empty; {allowed}")
    for char, label in _FORBIDDEN.items():
        if char in name:
            raise MqttError(f"{what} {name!r} contains {label}; {allowed}")
    if len(name) > MAX_LEVEL_LENGTH:
        raise MqttError(f"{what} {name!r} is {len(name)} characters long; {allowed}")
    if name != name.strip():
        raise MqttError(f"{what} {name!r} has leading or trailing whitespace; {allowed}")
    if name.startswith("$"):
        raise MqttError(f"{what} {name!r} starts with '$' (reserved for brokers); {allowed}")
    bad = [c for c in name if not c.isprintable()]
    if bad:
        raise MqttError(f"{what} {name!r} contains control character {bad[0]!r}; {allowed}")
    if len(name.encode("utf-8")) > MAX_LEVEL_LENGTH * 4:  # pragma: no cover - implied above
        raise MqttError(f"{what} {name!r} is too long in UTF-8; {allowed}")
    return name


def base_topic(station: str, sensor: str) -> str:
    """``imubench/<station>/<sensor>`` after validating both names."""
    validate_topic_level(station, "station name")
    validate_topic_level(sensor, "sensor name")
    return f"{TOPIC_ROOT}/{station}/{sensor}"


def allan_topic(station: str, sensor: str) -> str:
    """Topic of the per-second Allan snapshot: ``imubench/<station>/<sensor>/allan``."""
    return f"{base_topic(station, sensor)}/allan"


def status_topic(station: str, sensor: str) -> str:
    """Topic of the retained status: ``imubench/<station>/<sensor>/status``."""
    return f"{base_topic(station, sensor)}/status"


NODE_LEVEL = "node"
"""The topic level under a station that holds the nodes (daemons) of several sensors."""


def node_status_topic(station: str, node: str) -> str:
    """Retained status of a daemon that publishes several sensors over one connection:
    ``imubench/<station>/node/<node>/status`` (five levels, so it never matches a
    sensor's ``imubench/+/+/status``). It carries the connection's last will; each
    sensor's own status names its node (``"node": NAME``), and a sensor whose node is
    offline is offline, like Sparkplug B's NDEATH for its devices."""
    validate_topic_level(station, "station name")
    validate_topic_level(node, "node name")
    return f"{TOPIC_ROOT}/{station}/{NODE_LEVEL}/{node}/status"


def is_valid_topic_name(topic: str) -> bool:
    """True when ``topic`` may be published to (MQTT 3.1.1 sections 4.7.1 and 4.7.3).

    At least one character, no wildcard characters, no NUL, at most 65535 UTF-8 bytes.
    """
    return (
        bool(topic)
        and "+" not in topic
        and "#" not in topic
        and "\x00" not in topic
        and len(topic.encode("utf-8")) <= 65535
    )


def is_valid_topic_filter(topic_filter: str) -> bool:
    """True when ``topic_filter`` may be subscribed to (MQTT 3.1.1 section 4.7.1).

    ``#`` only as a whole last level; ``+`` only as a whole level; no NUL; not empty.
    """
    if not topic_filter or "\x00" in topic_filter:
        return False
    if len(topic_filter.encode("utf-8")) > 65535:
        return False
    levels = topic_filter.split("/")
    for index, level in enumerate(levels):
        if "#" in level and (level != "#" or index != len(levels) - 1):
            return False
        if "+" in level and level != "+":
            return False
    return True


def topic_matches(topic_filter: str, topic: str) -> bool:
    """True when the topic name ``topic`` matches ``topic_filter`` (MQTT 3.1.1 4.7.1-4.7.2).

    ``+`` matches exactly one level (possibly empty), ``#`` matches the parent level and any
    number of child levels; a filter starting with a wildcard does not match a topic name
    starting with ``$`` (section 4.7.2).
    """
    if topic.startswith("$") and topic_filter[:1] in ("+", "#"):
        return False
    filter_levels = topic_filter.split("/")
    topic_levels = topic.split("/")
    for index, level in enumerate(filter_levels):
        if level == "#":
            return True
        if index >= len(topic_levels):
            return False
        if level != "+" and level != topic_levels[index]:
            return False
    return len(filter_levels) == len(topic_levels)
