"""An MQTT subscriber that feeds an :class:`~imubench.fleet.inventory.Inventory`.

It subscribes to :data:`~imubench.fleet.inventory.SUBSCRIPTIONS` at QoS 0: the retained
statuses of a large fleet arrive in one burst, and at QoS 1 Mosquitto queues at most
1000 messages (plus 20 in flight) for a client and drops the rest (5000 retained
statuses showed as 1020 sensors, without a word); at QoS 0 it writes them to the
connection as they come, and over TCP none is lost while the link holds (a lost link
brings the retained ones again on reconnection). It applies every message, and reconnects with
capped exponential backoff when the broker goes away; ``connected``, ``last_error`` and
``connections`` say how the link is (the view shows them).
"""

from __future__ import annotations

import asyncio
import logging
import math
import ssl
import time
import uuid
from collections.abc import Callable
from typing import Any

import aiomqtt

from imubench.fleet.inventory import SUBSCRIPTIONS, Inventory
from imubench.mqtt.publisher import BrokerAddress

log = logging.getLogger(__name__)


class BrokerListener:
    """Subscribes to every imubench sensor on one broker until cancelled.

    ``on_change`` is called (in the event loop) after each message that changed the
    inventory and after each change of the connection state.
    """

    def __init__(self, address: BrokerAddress, inventory: Inventory, *,
                 username: str | None = None, password: str | None = None,
                 tls_ca: str | None = None, keepalive_s: int = 30,
                 reconnect_min_s: float = 0.5, reconnect_max_s: float = 10.0,
                 on_change: Callable[[], None] | None = None) -> None:
        self.address = address
        self.inventory = inventory
        self._username = username
        self._password = password
        self._tls = (ssl.create_default_context(cafile=tls_ca) if address.tls else None)
        self._keepalive_s = keepalive_s
        self._reconnect_min_s = reconnect_min_s
        self._reconnect_max_s = reconnect_max_s
        self._on_change = on_change
        self.client_id = f"imubench-view-{uuid.uuid4().hex[:8]}"
        self.connected = False
        self.connections = 0
        self.last_error: str | None = None
        self.subscribed = asyncio.Event()
        self.last_retained_s = -math.inf
        """``time.monotonic()`` of the last retained message (the broker sends the
        retained statuses in a burst right after the subscription; live messages reach a
        subscriber without the retain flag, MQTT 3.1.1 sec. 3.3.1.3)."""

    @property
    def url(self) -> str:
        return f"{'mqtts' if self.address.tls else 'mqtt'}://{self.address.host}:" \
               f"{self.address.port}"

    def info(self) -> dict[str, Any]:
        """The link's state for display: url, connected, connections, last_error."""
        return {"url": self.url, "connected": self.connected,
                "connections": self.connections, "last_error": self.last_error}

    def _changed(self) -> None:
        if self._on_change is not None:
            self._on_change()

    async def run(self) -> None:
        """Connect, subscribe, apply messages; reconnect on loss. Runs until cancelled."""
        backoff = self._reconnect_min_s
        while True:
            client = aiomqtt.Client(
                self.address.host, self.address.port, username=self._username,
                password=self._password, identifier=self.client_id, clean_session=True,
                keepalive=self._keepalive_s, tls_context=self._tls, timeout=10.0)
            try:
                async with client:
                    await client.subscribe([(t, 0) for t in SUBSCRIPTIONS])  # see above
                    self.connected = True
                    self.connections += 1
                    self.last_error = None
                    backoff = self._reconnect_min_s
                    self.subscribed.set()
                    self._changed()
                    async for msg in client.messages:
                        if msg.retain:
                            self.last_retained_s = time.monotonic()
                        payload = msg.payload
                        data = (bytes(payload) if isinstance(payload, bytes | bytearray)
                                else b"" if payload is None else str(payload).encode())
                        try:
                            changed = self.inventory.apply(str(msg.topic), data,
                                                           time.monotonic())
                        except Exception:  # anyone may publish anything
                            # one message must never end the listener (a malformed
                            # payload stopped every view for good, silently)
                            log.exception("broker %s: message on %s not taken", self.url,
                                          msg.topic)
                            continue
                        if changed:
                            self._changed()
                    raise aiomqtt.MqttError("message stream ended")
            except aiomqtt.MqttError as exc:
                if self.connected or self.last_error is None:
                    log.warning("broker %s: %s; reconnecting", self.url, exc)
                self.last_error = str(exc)
            finally:
                self.connected = False
            self._changed()
            await asyncio.sleep(backoff)
            backoff = min(backoff * 2, self._reconnect_max_s)


__all__ = ["BrokerListener"]
