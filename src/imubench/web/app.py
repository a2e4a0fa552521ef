"""The live view's ASGI application (Starlette).

Routes:

- ``/``: the page (``static/index.html``); ``/static/...``: its script, style sheet and
  the vendored plotting library (uPlot, MIT, ``static/vendor/``), all from the package;
- ``/api/fleet``: ``{"broker": {...}, "sensors": [view, ...]}`` (JSON, see
  :meth:`imubench.fleet.inventory.Inventory.view`);
- ``/events``: server-sent events (text/event-stream): ``broker`` (the MQTT link),
  ``sensor`` (one sensor's view, sent when it changed) and ``remove`` (its key), plus a
  comment every :data:`HEARTBEAT_S` so proxies keep the stream open. A client gets the
  whole fleet first, then only changes, coalesced to at most one message per sensor per
  :data:`MIN_PUSH_INTERVAL_S`.

With ``auth=(user, password)`` every route asks for HTTP basic authentication
(RFC 7617), compared in constant time.
"""

from __future__ import annotations

import asyncio
import base64
import binascii
import contextlib
import hmac
import json
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response, StreamingResponse
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles
from starlette.types import ASGIApp, Receive, Scope, Send

from imubench.fleet.inventory import Inventory
from imubench.fleet.listener import BrokerListener

STATIC_DIR = Path(__file__).resolve().parent / "static"
HEARTBEAT_S = 15.0
MIN_PUSH_INTERVAL_S = 0.1
"""Changes closer together than this reach a client in one batch (s)."""
REFRESH_S = 0.5
"""How often sensor states are re-derived from the clock (stale detection), in s."""


class Notifier:
    """Wakes every waiting event stream when the inventory or the link changed."""

    def __init__(self) -> None:
        self._event = asyncio.Event()
        self.closing = False

    def notify(self) -> None:
        self._event.set()
        self._event = asyncio.Event()

    async def wait(self, timeout_s: float) -> None:
        event = self._event
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(event.wait(), timeout_s)


class BasicAuth:
    """ASGI middleware: HTTP basic authentication for every request (RFC 7617)."""

    def __init__(self, app: ASGIApp, user: str, password: str) -> None:
        self.app = app
        self._expected = f"{user}:{password}".encode()

    def _ok(self, scope: Scope) -> bool:
        for name, value in scope.get("headers", []):
            if name == b"authorization":
                scheme, _, token = value.partition(b" ")
                if scheme.lower() != b"basic":
                    return False
                try:
                    given = base64.b64decode(token.strip(), validate=True)
                except (binascii.Error, ValueError):
                    return False
                return hmac.compare_digest(given, self._expected)
        return False

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or self._ok(scope):
            await self.app(scope, receive, send)
            return
        response = Response("authentication required\n", status_code=401,
                            headers={"WWW-Authenticate": 'Basic realm="imubench", '
                                                         'charset="UTF-8"'})
        await response(scope, receive, send)


LOCAL_NAMES = frozenset({"localhost", "127.0.0.1", "::1"})
"""Host names a view without a password answers to (its own loopback address)."""


def host_name(header: bytes) -> str:
    """The name in an HTTP ``Host`` header, without its port (``[::1]:8080`` -> ``::1``)."""
    text = header.decode("latin-1").strip().lower()
    if text.startswith("["):
        return text[1:text.find("]")] if "]" in text else text
    return text.rsplit(":", 1)[0] if text.count(":") == 1 else text


class LocalHostOnly:
    """ASGI middleware for a view without a password (it listens on loopback only):
    requests whose ``Host`` is not a loopback name are refused (421). A web page on
    another site could otherwise rebind its own name to 127.0.0.1 (DNS rebinding) and
    read the fleet's hosts, pids, recording paths and source URIs."""

    def __init__(self, app: ASGIApp, names: frozenset[str]) -> None:
        self.app = app
        self.names = names

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            host = next((v for k, v in scope.get("headers", []) if k == b"host"), b"")
            if host_name(host) not in self.names:
                await Response("this view answers to its loopback address only\n",
                               status_code=421)(scope, receive, send)
                return
        await self.app(scope, receive, send)


def _sse(event: str, data: Any) -> str:
    return f"event: {event}\ndata: {json.dumps(data, separators=(',', ':'))}\n\n"


def create_app(inventory: Inventory, listener: BrokerListener, notifier: Notifier, *,
               auth: tuple[str, str] | None = None, listen_host: str = "127.0.0.1"
               ) -> ASGIApp:
    """The view's ASGI application over ``inventory`` (fed by ``listener``); without
    ``auth`` it answers only to loopback names (:class:`LocalHostOnly`; ``listen_host``,
    the address it listens on, is one too)."""

    async def page(request: Request) -> Response:
        return FileResponse(STATIC_DIR / "index.html",
                            headers={"Cache-Control": "no-cache"})

    async def fleet(request: Request) -> Response:
        return JSONResponse({"broker": listener.info(),
                             "sensors": inventory.views(time.monotonic())})

    async def stream() -> AsyncIterator[str]:
        version = 0
        broker: dict[str, Any] | None = None
        yield "retry: 1000\n\n"
        while not notifier.closing:
            info = listener.info()
            if info != broker:
                broker = info
                yield _sse("broker", info)
            changed, gone, version_now = inventory.changes(version, time.monotonic())
            version = version_now
            for key in gone:
                yield _sse("remove", {"key": key})
            for view in changed:
                yield _sse("sensor", view)
            t0 = time.monotonic()
            await notifier.wait(HEARTBEAT_S)
            if time.monotonic() - t0 >= HEARTBEAT_S:
                yield ": keep-alive\n\n"
            await asyncio.sleep(MIN_PUSH_INTERVAL_S)

    async def events(request: Request) -> Response:
        return StreamingResponse(stream(), media_type="text/event-stream",
                                 headers={"Cache-Control": "no-cache",
                                          "X-Accel-Buffering": "no"})

    app: ASGIApp = Starlette(routes=[
        Route("/", page),
        Route("/api/fleet", fleet),
        Route("/events", events),
        Mount("/static", StaticFiles(directory=STATIC_DIR), name="static"),
    ])
    if auth is not None:
        app = BasicAuth(app, *auth)
    else:
        app = LocalHostOnly(app, LOCAL_NAMES | {listen_host.lower()})
    return app


async def refresh_loop(inventory: Inventory, notifier: Notifier) -> None:
    """Every :data:`REFRESH_S`: re-derive sensor states (stale when snapshots stop)."""
    while True:
        await asyncio.sleep(REFRESH_S)
        if inventory.refresh(time.monotonic()):
            notifier.notify()


__all__ = ["HEARTBEAT_S", "MIN_PUSH_INTERVAL_S", "REFRESH_S", "STATIC_DIR", "BasicAuth",
           "LocalHostOnly", "Notifier", "create_app", "host_name", "refresh_loop"]
