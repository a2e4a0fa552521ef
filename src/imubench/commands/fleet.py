"""``imubench fleet status``: every sensor the broker knows, with its health.

    imubench fleet status [--broker mqtt://HOST:PORT] [--wait-s 2] [--json PATH|-]

Subscribes to ``imubench/+/+/status`` (retained: the fleet's inventory, online or
offline), ``/allan`` and ``/jig`` for ``--wait-s`` seconds, then prints one line per
sensor: state (``online``: snapshots arriving; ``waiting``: online status but no snapshot
within the wait; ``stalled``: snapshots whose sample count stands still; ``offline``:
the retained status, the last will or its node's status says so), chip,
ODR, samples, lost samples, the measured ODR (over the snapshots seen), the host and
process, and any further status fields. Exit status 0, or 2 when the broker cannot be
reached. See docs/fleet.md.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import time
from pathlib import Path
from typing import Any

from imubench.commands import write_json
from imubench.fleet import FleetError
from imubench.fleet.inventory import Inventory
from imubench.fleet.listener import BrokerListener
from imubench.mqtt.publisher import parse_broker_url

DEFAULT_BROKER = "mqtt://127.0.0.1:1883"


def read_secret(path: Path, option: str) -> str:
    """The first line of a password file (``option`` names the flag in errors)."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise FleetError(f"{option} {path}: cannot read ({exc.strerror})") from None
    secret = text.splitlines()[0] if text else ""
    if not secret.strip():  # blanks only: a password anyone could guess
        raise FleetError(f"{option} {path}: line 1 is empty or blank; put the password on "
                         "line 1")
    return secret


def add_broker_options(p: argparse.ArgumentParser) -> None:
    """--broker, --mqtt-username, --mqtt-password-file, --tls-ca (view and fleet)."""
    p.add_argument("--broker", default=DEFAULT_BROKER, metavar="URL",
                   help=f"mqtt://HOST[:PORT] or mqtts://HOST[:PORT] (default {DEFAULT_BROKER})")
    p.add_argument("--mqtt-username", default=None, metavar="NAME", help="broker user name")
    p.add_argument("--mqtt-password-file", type=Path, default=None, metavar="FILE",
                   help="file whose first line is the broker password")
    p.add_argument("--tls-ca", default=None, metavar="FILE",
                   help="CA certificate file for mqtts:// (default: the system CAs)")


def broker_credentials(args: argparse.Namespace) -> str | None:
    """The broker password from ``--mqtt-password-file``, if given."""
    if args.mqtt_password_file is None:
        return None
    return read_secret(args.mqtt_password_file, "--mqtt-password-file")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "fleet", help="the fleet of daemons on one broker (fleet status)",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("action", choices=("status",),
                   help="status: every sensor seen on the broker, with its health")
    add_broker_options(p)
    p.add_argument("--wait-s", type=float, default=2.0,
                   help="listen this long for snapshots after the retained statuses "
                        "(default 2 s)")
    p.add_argument("--connect-timeout-s", type=float, default=5.0,
                   help="give up when the broker does not answer within this (default 5 s)")
    p.add_argument("--json", default=None, metavar="PATH|-",
                   help="write the sensors' full health as JSON here")
    p.set_defaults(func=run)


async def collect(broker: str, wait_s: float, connect_timeout_s: float, *,
                  username: str | None = None, password: str | None = None,
                  tls_ca: str | None = None) -> tuple[Inventory, BrokerListener]:
    """Subscribe to every sensor for ``wait_s`` after the subscription is acknowledged,
    and on while the broker's burst of retained statuses is still arriving (the last one
    within :data:`RETAINED_QUIET_S`), at most ``connect_timeout_s`` longer: 3000
    retained statuses took more than 1 s on a loaded machine, and a fixed wait listed
    2606 of them without a word."""
    inventory = Inventory()
    listener = BrokerListener(parse_broker_url(broker, "--broker"), inventory, username=username,
                              password=password, tls_ca=tls_ca, reconnect_max_s=1.0)
    task = asyncio.create_task(listener.run())
    try:
        deadline = time.monotonic() + connect_timeout_s
        while not listener.subscribed.is_set():
            error = listener.last_error or ""
            if any(code in error for code in REFUSED_CODES):  # an answer: say it now
                raise FleetError(f"broker {listener.url} refused the connection ({error}); "
                                 "check --mqtt-username and --mqtt-password-file")
            if time.monotonic() > deadline:
                raise FleetError(f"broker {listener.url} did not answer within "
                                 f"{connect_timeout_s:g} s ({error or 'no reply'})")
            await asyncio.sleep(0.05)
        await asyncio.sleep(wait_s)
        cap = time.monotonic() + connect_timeout_s
        while (time.monotonic() - listener.last_retained_s < RETAINED_QUIET_S
               and time.monotonic() < cap):
            await asyncio.sleep(0.05)
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
    return inventory, listener


RETAINED_QUIET_S = 0.5
"""``fleet status`` listens on until no retained status has arrived for this long."""


REFUSED_CODES = ("[code:134]", "[code:135]", "[code:4]", "[code:5]", "Not authorized",
                 "Bad user name or password")
"""A broker's refusal in a connection error: the credentials (it waited the whole timeout
and then said the broker "did not answer")."""


COLUMNS: tuple[tuple[str, str], ...] = (
    ("station", "STATION"), ("sensor", "SENSOR"), ("state", "STATE"), ("chip", "CHIP"),
    ("odr_hz", "ODR_HZ"), ("measured_odr_hz", "MEAS_ODR"), ("samples", "SAMPLES"),
    ("lost_samples", "LOST"), ("host", "HOST"), ("pid", "PID"), ("since", "SINCE"),
)


def _cell(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def status_rows(views: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One flat row per sensor: identity, state, known health fields, then the rest."""
    rows = []
    for v in views:
        row: dict[str, Any] = {"station": v["station"], "sensor": v["sensor"],
                               "state": v["state"]}
        row.update({h["key"]: h["value"] for h in v["health"]})
        row["extra"] = v["extra"]
        if v["jig"] is not None:
            row["jig_verdict"] = v["jig"].get("verdict")
        if v["errors"]:
            row["errors"] = v["errors"]
        rows.append(row)
    return rows


def format_table(rows: list[dict[str, Any]]) -> str:
    """Aligned text table; fields beyond :data:`COLUMNS` go to a last column as k=v."""
    known = {k for k, _ in COLUMNS} | {"extra"}
    body = []
    for r in rows:
        cells = [_cell(r.get(k)) for k, _ in COLUMNS]
        rest = {**{k: v for k, v in r.items() if k not in known}, **r.get("extra", {})}
        cells.append(" ".join(f"{k}={_cell(v)}" for k, v in rest.items()) or "-")
        body.append(cells)
    head = [h for _, h in COLUMNS] + ["OTHER"]
    widths = [max(len(x) for x in col) for col in zip(head, *body, strict=False)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(line, widths, strict=True)).rstrip()
             for line in (head, *body)]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    inventory, listener = asyncio.run(collect(
        args.broker, args.wait_s, args.connect_timeout_s, username=args.mqtt_username,
        password=broker_credentials(args), tls_ca=args.tls_ca))
    rows = status_rows(inventory.views(time.monotonic()))
    if args.json is not None:
        write_json({"broker": listener.url, "sensors": rows}, args.json)
        if args.json == "-":
            return 0
    counts: dict[str, int] = {}
    for r in rows:
        counts[r["state"]] = counts.get(r["state"], 0) + 1
    if rows:
        print(format_table(rows))
    summary = ", ".join(f"{n} {s}" for s, n in sorted(counts.items()))
    print(f"# {len(rows)} sensor(s) on {listener.url}" + (f": {summary}" if rows else ""))
    return 0
