"""Run the live view: uvicorn serving :func:`imubench.web.app.create_app` plus the MQTT
listener, both as tasks of the caller's event loop.

    view = LiveView(ViewOptions(broker="mqtt://127.0.0.1:1883", listen="127.0.0.1:8080"))
    host, port = await view.start()      # bound and serving; port 0 picks a free one
    ...
    await view.stop()                    # closes the event streams, the server, the link

The server binds to loopback by default. Any other address needs a password (HTTP basic
authentication, user ``ViewOptions.user``): without one :class:`LiveView` refuses to
start with :class:`~imubench.fleet.FleetError`. Signals are left to the caller (the
``imubench view`` command, or the daemon that embeds the view).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import Iterator
from dataclasses import dataclass

import uvicorn

from imubench.fleet import FleetError
from imubench.fleet.address import check_exposure, is_loopback, parse_listen
from imubench.fleet.inventory import Inventory
from imubench.fleet.listener import BrokerListener
from imubench.mqtt.publisher import parse_broker_url
from imubench.web.app import Notifier, create_app, refresh_loop

log = logging.getLogger(__name__)

DEFAULT_LISTEN = "127.0.0.1:8080"
DEFAULT_BROKER = "mqtt://127.0.0.1:1883"


@dataclass(frozen=True)
class ViewOptions:
    """What the view connects to and where it listens.

    ``broker``: ``mqtt://host[:port]`` or ``mqtts://host[:port]``; ``listen``:
    ``HOST:PORT`` (``[v6]:PORT`` for IPv6; port 0 = any free port); ``password``: HTTP
    basic authentication for user ``user`` (required unless ``listen`` is loopback);
    ``mqtt_username``/``mqtt_password``/``tls_ca``: the broker's credentials and CA file.
    ``min_stale_s``/``stale_factor``: a sensor without a snapshot for
    ``max(min_stale_s, stale_factor x its interval)`` is shown stale.
    """

    broker: str = DEFAULT_BROKER
    listen: str = DEFAULT_LISTEN
    user: str = "imubench"
    password: str | None = None
    mqtt_username: str | None = None
    mqtt_password: str | None = None
    tls_ca: str | None = None
    min_stale_s: float = 3.0
    stale_factor: float = 3.0


class _Server(uvicorn.Server):
    """uvicorn without its own signal handlers: the embedding program owns the signals."""

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        yield


class LiveView:
    """The live view's web server and MQTT listener (module docstring)."""

    def __init__(self, options: ViewOptions) -> None:
        self.options = options
        self.host, self.port = parse_listen(options.listen)
        check_exposure(self.host, options.password)
        self.inventory = Inventory(min_stale_s=options.min_stale_s,
                                   stale_factor=options.stale_factor)
        self.notifier = Notifier()
        self.listener = BrokerListener(
            parse_broker_url(options.broker, "--broker"), self.inventory,
            username=options.mqtt_username, password=options.mqtt_password,
            tls_ca=options.tls_ca, on_change=self.notifier.notify)
        auth = None if options.password is None else (options.user, options.password)
        self.app = create_app(self.inventory, self.listener, self.notifier, auth=auth,
                              listen_host=self.host)
        self._server: _Server | None = None
        self._tasks: list[asyncio.Task[None]] = []

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    def _bind(self) -> socket.socket:
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((self.host, self.port))
        except OSError as exc:
            sock.close()
            raise FleetError(f"cannot listen on {self.options.listen}: {exc.strerror}") \
                from None
        sock.listen(128)
        sock.setblocking(False)
        return sock

    async def start(self) -> tuple[str, int]:
        """Bind, start serving and subscribing; return the bound (host, port)."""
        sock = self._bind()
        self.port = int(sock.getsockname()[1])
        config = uvicorn.Config(self.app, lifespan="off", access_log=False,
                                log_level="warning", timeout_graceful_shutdown=1)
        self._server = _Server(config)
        self._tasks = [
            asyncio.create_task(self._server.serve(sockets=[sock]), name="view-http"),
            asyncio.create_task(self.listener.run(), name="view-mqtt"),
            asyncio.create_task(refresh_loop(self.inventory, self.notifier),
                                name="view-refresh"),
        ]
        while not self._server.started:
            if self._tasks[0].done():
                await self._tasks[0]  # raises what stopped it
                raise FleetError(f"the web server on {self.options.listen} stopped at start")
            await asyncio.sleep(0.01)
        log.info("live view on %s (broker %s)", self.url, self.listener.url)
        return self.host, self.port

    async def stop(self) -> None:
        """Close the event streams, stop the server and the MQTT link."""
        self.notifier.closing = True
        self.notifier.notify()
        if self._server is not None:
            self._server.should_exit = True
        for t in self._tasks[1:]:  # the MQTT link and the refresh loop
            t.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks = []

    async def run_until(self, stop: asyncio.Event) -> None:
        """Start, wait for ``stop``, stop."""
        await self.start()
        try:
            await stop.wait()
        finally:
            await self.stop()


__all__ = ["DEFAULT_BROKER", "DEFAULT_LISTEN", "LiveView", "ViewOptions", "check_exposure",
           "is_loopback", "parse_listen"]
