"""``imubench view``: the live view in the browser.

    imubench view [--broker mqtt://HOST:PORT] [--listen 127.0.0.1:8080]
                  [--password-file FILE] [--user NAME]

Serves a page that subscribes (through this server) to ``imubench/+/+/allan``,
``/status`` and ``/jig`` and shows, per station and sensor, the live sigma-tau curves
with their confidence bands, the noise readouts (N, B, K in datasheet units), health and
jig results. Listens on loopback unless told otherwise; any other address needs
``--password-file`` (HTTP basic authentication, user ``--user``). Runs until SIGINT or
SIGTERM. See docs/live-view.md.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
from pathlib import Path

from imubench.commands.fleet import add_broker_options, broker_credentials, read_secret
from imubench.web.server import DEFAULT_LISTEN, LiveView, ViewOptions


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "view", help="live sigma-tau view of every sensor in the browser",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_broker_options(p)
    p.add_argument("--listen", default=DEFAULT_LISTEN, metavar="HOST:PORT",
                   help=f"address of the web server (default {DEFAULT_LISTEN}; port 0 = any "
                        "free port)")
    p.add_argument("--password-file", type=Path, default=None, metavar="FILE",
                   help="file whose first line is the page's password (HTTP basic auth); "
                        "required to listen on a non-loopback address")
    p.add_argument("--user", default="imubench", help="user name for the password "
                                                      "(default imubench)")
    p.set_defaults(func=run)


async def serve(view: LiveView) -> None:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)
    await view.start()
    print(f"live view on {view.url} (broker {view.listener.url}); Ctrl-C stops it",
          flush=True)
    try:
        await stop.wait()
    finally:
        await view.stop()


def run(args: argparse.Namespace) -> int:
    password = (None if args.password_file is None
                else read_secret(args.password_file, "--password-file"))
    view = LiveView(ViewOptions(
        broker=args.broker, listen=args.listen, user=args.user, password=password,
        mqtt_username=args.mqtt_username, mqtt_password=broker_credentials(args),
        tls_ca=args.tls_ca))
    asyncio.run(serve(view))
    return 0
