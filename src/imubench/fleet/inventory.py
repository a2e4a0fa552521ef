"""The fleet as the broker shows it: one :class:`SensorState` per
``imubench/<station>/<sensor>``, built from the messages of that sensor's topics
(docs/mqtt.md):

- ``status`` (retained): JSON ``{"state": "online", ...}`` while the daemon runs; the
  plain text ``offline`` after a clean stop or as the last will the broker publishes
  1.5 keep-alives after the daemon vanished; an empty retained message clears it (the
  sensor is dropped from the inventory);
- ``allan``: the JSON snapshot (``statistics.<stat>.<channel>`` with ``tau_s``, ``dev``,
  ``ci_low``, ``ci_high``, ``units``; ``samples``, ``lost_samples``, ...);
- ``imubench/<station>/node/<node>/status`` (retained): the status of a daemon that
  publishes several sensors over one connection (it carries that connection's last
  will); a sensor whose status names a node (``"node": NAME``) is offline while that
  node is;
- ``jig``: a JSON result ``{"verdict": ..., "measurements": [{"name", "value", "unit",
  "low", "high", "ci_low", "ci_high", "verdict"}]}``.

A sensor's displayed state is ``online`` (fresh snapshots), ``waiting`` (online status,
no snapshot yet), ``stale`` (online status but no snapshot for ``max(min_stale_s,
stale_factor x its snapshot interval)``: the daemon hangs or its link died and the will
is not due yet) or ``offline`` (the retained status says so). Unknown status and
snapshot fields are kept and shown as they are; the known ones (:data:`HEALTH_FIELDS`)
get labels and units.
"""

from __future__ import annotations

import datetime as dt
import itertools
import json
import logging
import math
import statistics as pystats
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from imubench.fleet.readouts import sensor_readouts
from imubench.mqtt.topics import NODE_LEVEL, TOPIC_ROOT

log = logging.getLogger(__name__)

TOPIC_KINDS: tuple[str, ...] = ("status", "allan", "jig")
SUBSCRIPTIONS: tuple[str, ...] = (
    *(f"{TOPIC_ROOT}/+/+/{k}" for k in TOPIC_KINDS), f"{TOPIC_ROOT}/+/{NODE_LEVEL}/+/status")
"""Topic filters of the fleet view: every station's and sensor's status, allan, jig, and
the status of every node (daemon of several sensors)."""

HEALTH_FIELDS: tuple[tuple[str, str, str, tuple[str, ...]], ...] = (
    ("phase", "phase", "", ("health.phase",)),
    ("samples", "samples", "", ("samples",)),
    ("lost_samples", "lost samples", "", ("lost_samples",)),
    ("gaps", "gaps", "", ("gaps", "health.source.gaps")),
    ("measured_odr_hz", "measured ODR", "Hz",
     ("measured_odr_hz", "health.source.measured_odr_hz")),
    ("odr_hz", "nominal ODR", "Hz", ("odr_hz",)),
    ("temperature_c", "temperature", "°C", ("temperature_c", "health.source.temperature_c")),
    ("recording_state", "recording", "", ("recording_state", "health.recording.state")),
    ("recording_bytes", "recording size", "B", ("recording_bytes", "health.recording.bytes")),
    ("recording_path", "recording file", "", ("recording_path", "health.recording.path")),
    ("chip", "chip", "", ("chip",)),
    ("source", "source", "", ("source",)),
    ("host", "host", "", ("host",)),
    ("pid", "pid", "", ("pid",)),
    ("since", "online since", "", ("since",)),
)
"""(key, label, unit, paths) of the health fields shown by name: the first path present
(dotted paths reach into nested objects such as the snapshot's ``health``, see
docs/pipeline.md), looked up in the status, then in the latest snapshot;
``measured_odr_hz`` falls back to the view's own estimate (samples counted between
snapshots over their time stamps, once they span :data:`MIN_ODR_SPAN_S`)."""

_ALLAN_KEYS = {"time", "station", "sensor", "statistic", "memory", "channels", "statistics"}
_STATUS_IDENTITY = {"state", "station", "sensor", "client_id"}
_CURVE_FIELDS = ("tau_s", "dev", "ci_low", "ci_high", "alpha")
_ODR_WINDOW = 11
"""Snapshots over which the measured ODR is taken (first to last)."""
MIN_ODR_SPAN_S = 5.0
"""Shortest span of snapshot time stamps for a measured ODR: samples reach the engine in
FIFO-sized batches, so a short span would carry a batch's worth of error."""


def _utc_now() -> str:
    return dt.datetime.now(dt.UTC).isoformat(timespec="seconds")


@dataclass
class SensorState:
    """Everything known about one sensor; ``now`` arguments are ``time.monotonic()``."""

    station: str
    sensor: str
    online: bool | None = None
    """From the retained status: True online, False offline, None none seen."""
    node_online: bool | None = None
    """From the retained status of the node named in the status (None: no node, or its
    status not seen); False makes the sensor offline."""
    status: dict[str, Any] = field(default_factory=dict)
    offline_at: str | None = None
    allan: dict[str, Any] | None = None
    allan_at: float | None = None
    curves: dict[str, dict[str, dict[str, Any]]] = field(default_factory=dict)
    readouts: dict[str, Any] = field(default_factory=dict)
    jig: dict[str, Any] | None = None
    errors: deque[str] = field(default_factory=lambda: deque(maxlen=5))
    receipts: deque[float] = field(default_factory=lambda: deque(maxlen=6))
    rate_points: deque[tuple[float, int]] = field(
        default_factory=lambda: deque(maxlen=_ODR_WINDOW))
    version: int = 0
    shown_state: str = ""
    samples_since: tuple[int, float] | None = None
    """The snapshots' sample count and when it was first seen (monotonic s)."""

    @property
    def key(self) -> str:
        return f"{self.station}/{self.sensor}"

    def interval_s(self) -> float | None:
        """Median time between the last snapshots' arrivals (s)."""
        r = list(self.receipts)
        if len(r) < 2:
            return None
        return float(pystats.median(b - a for a, b in itertools.pairwise(r)))

    def measured_odr_hz(self) -> float | None:
        """Samples per second between the oldest and newest snapshot kept (their ``time``)."""
        if len(self.rate_points) < 2:
            return None
        (t0, n0), (t1, n1) = self.rate_points[0], self.rate_points[-1]
        if t1 - t0 < MIN_ODR_SPAN_S or n1 < n0:
            return None
        return (n1 - n0) / (t1 - t0)

    @property
    def node(self) -> str | None:
        """The node (daemon of several sensors) this sensor's status names, if any."""
        node = self.status.get("node")
        return node if isinstance(node, str) else None

    def state(self, now: float, min_stale_s: float, stale_factor: float) -> str:
        if self.online is False or self.node_online is False:
            return "offline"
        if self.allan_at is None:  # a jig's result alone (no daemon status): not waiting
            return "jig" if self.online is None and self.jig is not None else "waiting"
        stated = self.status.get("publish_interval_s")  # the daemon's own cadence
        interval = (self.interval_s() or (float(stated) if isinstance(stated, int | float)
                                          and not isinstance(stated, bool) and stated > 0
                                          else 1.0))
        late = max(min_stale_s, stale_factor * interval)
        if now - self.allan_at > late:
            return "stale"
        if (self.samples_since is not None and len(self.receipts) >= 2
                and self.allan_at - self.samples_since[1] > late):
            return "stalled"  # snapshots arrive, samples do not (a frozen source)
        return "online"


class Inventory:
    """All sensors seen, updated by :meth:`apply` with each MQTT message.

    ``version`` grows with every change; each sensor carries the version of its last
    change, and removed sensors leave a tombstone, so a reader asks
    :meth:`changes` for what happened since the version it has.
    """

    def __init__(self, *, min_stale_s: float = 3.0, stale_factor: float = 3.0) -> None:
        self.min_stale_s = min_stale_s
        self.stale_factor = stale_factor
        self.sensors: dict[str, SensorState] = {}
        self.removed: dict[str, int] = {}
        self.nodes: dict[str, bool] = {}
        """``station/node`` -> online, from the nodes' retained statuses."""
        self.node_sensors: dict[str, list[Any] | None] = {}
        """The sensors each node's online status lists (None: it lists none)."""
        self.version = 0
        self.messages = 0

    # -- updates ---------------------------------------------------------------------
    def _touch(self, s: SensorState) -> None:
        self.version += 1
        s.version = self.version

    def _error(self, s: SensorState, text: str) -> None:
        if text not in s.errors:
            log.warning("%s: %s", s.key, text)
        s.errors.append(text)

    def apply(self, topic: str, payload: bytes, now: float) -> bool:
        """Take one message; True when the inventory changed. Topics outside
        ``imubench/<station>/<sensor>/{status,allan,jig}`` are ignored."""
        parts = topic.split("/")
        if (len(parts) == 5 and parts[0] == TOPIC_ROOT and parts[2] == NODE_LEVEL
                and parts[4] == "status"):
            return self._apply_node(parts[1], parts[3], payload)
        if len(parts) != 4 or parts[0] != TOPIC_ROOT or parts[3] not in TOPIC_KINDS:
            return False
        self.messages += 1
        station, sensor, kind = parts[1], parts[2], parts[3]
        key = f"{station}/{sensor}"
        if kind == "status" and payload == b"":
            if self.sensors.pop(key, None) is None:
                return False
            self.version += 1
            self.removed[key] = self.version
            return True
        s = self.sensors.get(key)
        if s is None:
            s = self.sensors[key] = SensorState(station, sensor)
            self.removed.pop(key, None)
        if kind == "status":
            self._apply_status(s, payload)
        elif kind == "allan":
            self._apply_allan(s, payload, now)
        else:
            self._apply_jig(s, payload)
        s.shown_state = s.state(now, self.min_stale_s, self.stale_factor)
        self._touch(s)
        return True

    def _apply_node(self, station: str, node: str, payload: bytes) -> bool:
        """A node's retained status: every sensor naming it follows (offline with it)."""
        self.messages += 1
        key = f"{station}/{node}"
        if payload == b"":
            online: bool | None = None
        elif payload.strip() == b"offline":
            online = False
        else:
            doc = _json_object(payload)
            online = doc is None or str(doc.get("state", "online")) != "offline"
        if online is None:
            self.nodes.pop(key, None)
        else:
            self.nodes[key] = online
        listed = doc.get("sensors") if online and payload.strip() != b"offline" \
            and isinstance(doc, dict) else None
        self.node_sensors[key] = listed if isinstance(listed, list) else None
        changed = False
        for s in self.sensors.values():
            if s.station != station or s.node != node:
                continue
            mine = self._node_online(station, node, s.sensor)
            if s.node_online != mine:
                if mine is False and s.online is not False:
                    s.offline_at = _utc_now()
                s.node_online = mine
                self._touch(s)
                changed = True
        return changed

    def _node_online(self, station: str, node: str, sensor: str) -> bool | None:
        """Whether ``node``'s status says it runs ``sensor`` (None: no node status): a
        node that restarted without some of its sensors has them offline (they stayed
        "stale" with the dead process's pid)."""
        key = f"{station}/{node}"
        online = self.nodes.get(key)
        listed = self.node_sensors.get(key)
        return False if online and listed is not None and sensor not in listed else online

    def _apply_status(self, s: SensorState, payload: bytes) -> None:
        if payload.strip() == b"offline":
            if s.online is not False:
                s.offline_at = _utc_now()
            s.online = False
            return
        doc = _json_object(payload)
        if doc is None:
            self._error(s, f"status payload is neither 'offline' nor a JSON object: "
                           f"{payload[:60]!r}")
            return
        if str(doc.get("state", "online")) == "offline":
            if s.online is not False:
                s.offline_at = _utc_now()
            s.online = False
        else:
            s.online = True
            s.offline_at = None
        s.status = doc
        node = s.node
        s.node_online = None if node is None else self._node_online(s.station, node, s.sensor)

    def _apply_allan(self, s: SensorState, payload: bytes, now: float) -> None:
        doc = _json_object(payload)
        if doc is None:
            self._error(s, f"allan payload is not a JSON object: {payload[:60]!r}")
            return
        stats = doc.get("statistics")
        if not isinstance(stats, dict) or not stats:
            stats = {str(doc.get("statistic", "oadev")): doc.get("channels")}
        curves: dict[str, dict[str, dict[str, Any]]] = {}
        for stat, chans in stats.items():
            if not isinstance(chans, dict):
                self._error(s, f"allan statistics.{stat} is not an object of channels")
                return
            curves[stat] = {}
            for ch, c in chans.items():
                if not isinstance(c, dict) or not isinstance(c.get("tau_s"), list):
                    self._error(s, f"allan statistics.{stat}.{ch} has no tau_s list")
                    return
                bad = [f for f in _CURVE_FIELDS if not _numbers(c.get(f))]
                if bad:  # someone else's payload: never let it into the views
                    self._error(s, f"allan statistics.{stat}.{ch}.{bad[0]} is not a list of "
                                   "finite numbers")
                    return
                curves[stat][ch] = {f: list(c.get(f) or []) for f in _CURVE_FIELDS}
                curves[stat][ch]["units"] = c.get("units")
        s.allan = {k: v for k, v in doc.items() if k not in ("channels", "statistics")}
        s.curves = curves
        s.readouts = sensor_readouts(curves)
        s.allan_at = now
        s.receipts.append(now)
        t = _parse_time(doc.get("time"))
        samples = doc.get("samples")
        if isinstance(samples, int) and (s.samples_since is None
                                         or s.samples_since[0] != samples):
            s.samples_since = (samples, now)
        if t is not None and isinstance(samples, int):
            if s.rate_points and (t <= s.rate_points[-1][0] or samples < s.rate_points[-1][1]):
                s.rate_points.clear()  # daemon restarted or clock stepped back
            s.rate_points.append((t, samples))

    def _apply_jig(self, s: SensorState, payload: bytes) -> None:
        doc = _json_object(payload)
        if doc is None:
            self._error(s, f"jig payload is not a JSON object: {payload[:60]!r}")
            return
        s.jig = doc

    def refresh(self, now: float) -> bool:
        """Re-derive every sensor's state at ``now`` (a snapshot overdue turns it stale);
        True when one changed."""
        changed = False
        for s in self.sensors.values():
            st = s.state(now, self.min_stale_s, self.stale_factor)
            if st != s.shown_state:
                s.shown_state = st
                self._touch(s)
                changed = True
        return changed

    # -- views -------------------------------------------------------------------------
    def health(self, s: SensorState) -> list[dict[str, Any]]:
        """The known health fields present for ``s``: ``[{"key", "label", "value",
        "unit"}]`` (status first, then snapshot, then the view's measured ODR)."""
        rows = []
        for key, label, unit, paths in HEALTH_FIELDS:
            value = _first(paths, s.status, s.allan or {})
            if value in (_MISSING, None) and key == "measured_odr_hz":
                # the SensorTile publishes null (its firmware's clock is not measured)
                value = s.measured_odr_hz()
            if value is _MISSING or value is None:
                continue
            rows.append({"key": key, "label": label, "value": value, "unit": unit})
        return rows

    def extra(self, s: SensorState) -> dict[str, Any]:
        """Status and snapshot fields not among the known ones, as published; nested
        objects flattened to dotted keys (``health.source.overruns``)."""
        used = {p for _, _, _, paths in HEALTH_FIELDS for p in paths}
        out: dict[str, Any] = {}
        for doc, skip in ((s.status, _STATUS_IDENTITY), (s.allan or {}, _ALLAN_KEYS)):
            for k, v in _flatten(doc):
                if k not in used and k.split(".")[0] not in skip:
                    out.setdefault(k, v)
        return out

    def view(self, s: SensorState, now: float) -> dict[str, Any]:
        """JSON-ready description of one sensor (what the browser and ``fleet status``
        show)."""
        allan = s.allan or {}
        return {
            "key": s.key, "station": s.station, "sensor": s.sensor,
            "state": s.state(now, self.min_stale_s, self.stale_factor),
            "status_state": (None if s.online is None
                             else "offline" if not s.online or s.node_online is False
                             else str(s.status.get("state", "online"))),
            "node": s.node,
            "offline_at": s.offline_at, "version": s.version,
            "age_s": None if s.allan_at is None else round(now - s.allan_at, 3),
            "interval_s": s.interval_s(),
            "snapshot_time": allan.get("time"),
            "statistic": allan.get("statistic"),
            "memory": allan.get("memory"),
            "health": self.health(s), "extra": self.extra(s),
            "statistics": s.curves, "readouts": s.readouts, "jig": s.jig,
            "errors": list(s.errors),
        }

    def views(self, now: float) -> list[dict[str, Any]]:
        return [self.view(s, now) for _, s in sorted(self.sensors.items())]

    def changes(self, since: int, now: float) -> tuple[list[dict[str, Any]], list[str], int]:
        """(views of sensors changed after version ``since``, keys removed after it,
        current version)."""
        changed = [self.view(s, now) for _, s in sorted(self.sensors.items())
                   if s.version > since]
        gone = [k for k, v in self.removed.items() if v > since]
        return changed, gone, self.version


_MISSING: Any = object()


def _lookup(doc: dict[str, Any], path: str) -> Any:
    node: Any = doc
    for part in path.split("."):
        if not isinstance(node, dict) or part not in node:
            return _MISSING
        node = node[part]
    return node


def _first(paths: tuple[str, ...], *docs: dict[str, Any]) -> Any:
    """The value at the first path present in the first document that has one."""
    for doc in docs:
        for path in paths:
            value = _lookup(doc, path)
            if value is not _MISSING:
                return value
    return _MISSING


def _flatten(doc: dict[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = []
    for k, v in doc.items():
        if isinstance(v, dict) and v:
            out.extend(_flatten(v, f"{prefix}{k}."))
        else:
            out.append((f"{prefix}{k}", v))
    return out


def _json_object(payload: bytes) -> dict[str, Any] | None:
    """The payload as a JSON object, None when it is none: NaN, Infinity and numbers that
    overflow to them are refused (one such snapshot made ``/api/fleet`` answer 500 and the
    browser's event stream fail to parse, until the view restarted)."""
    try:
        doc = json.loads(payload, parse_constant=_no_constant, parse_float=_finite_float)
    except (UnicodeDecodeError, ValueError, RecursionError):
        return None
    return doc if isinstance(doc, dict) else None


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not JSON")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"{text} overflows")
    return value


def _numbers(values: Any) -> bool:
    """Whether a curve field is absent or a list of numbers (None allowed: no value)."""
    return values is None or (isinstance(values, list) and all(
        v is None or (isinstance(v, int | float) and not isinstance(v, bool))
        for v in values))


def _parse_time(text: Any) -> float | None:
    """POSIX seconds of an ISO 8601 time stamp, or None."""
    if not isinstance(text, str):
        return None
    try:
        t = dt.datetime.fromisoformat(text)
    except ValueError:
        return None
    if t.tzinfo is None:
        t = t.replace(tzinfo=dt.UTC)
    return t.timestamp()


__all__ = ["HEALTH_FIELDS", "SUBSCRIPTIONS", "TOPIC_KINDS", "Inventory",
           "SensorState"]
