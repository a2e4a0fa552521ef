"""The live view in the browser: ``imubench view`` (and the daemon's ``[web]`` section).

- :mod:`~imubench.web.app`: the ASGI application (Starlette): the page, its static files
  (uPlot served from the package), ``/api/fleet`` (JSON) and ``/events`` (server-sent
  events, one per changed sensor), optional HTTP basic authentication;
- :mod:`~imubench.web.server`: :class:`LiveView`, which runs that application on uvicorn
  together with the MQTT listener in the caller's event loop.
"""

from __future__ import annotations

from imubench.web.server import LiveView, ViewOptions, parse_listen

__all__ = ["LiveView", "ViewOptions", "parse_listen"]
