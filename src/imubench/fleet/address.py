"""HTTP listen addresses of the live view: ``HOST:PORT`` parsing and the rule that only
loopback may listen without a password (light: the configuration checks it at load)."""

from __future__ import annotations

from imubench.fleet import FleetError
from imubench.netaddr import is_loopback


def parse_listen(text: str) -> tuple[str, int]:
    """``HOST:PORT`` or ``[IPv6]:PORT`` -> (host, port). Raises FleetError."""
    forms = "use HOST:PORT, e.g. 127.0.0.1:8080, 0.0.0.0:8080 or [::1]:8080"
    host, sep, port_text = text.rpartition(":")
    if not sep or not port_text:
        raise FleetError(f"--listen {text!r}: no port; {forms}")
    if not host:  # ':8080' reads as every interface elsewhere: say which to give
        raise FleetError(f"--listen {text!r}: no host; use 127.0.0.1:{port_text} (this "
                         f"machine only) or 0.0.0.0:{port_text} (every interface, with "
                         "--password-file)")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    try:
        port = int(port_text)
    except ValueError:
        raise FleetError(f"--listen {text!r}: port {port_text!r} is not a number; "
                         f"{forms}") from None
    if not 0 <= port <= 65535:
        raise FleetError(f"--listen {text!r}: port {port} is outside 0-65535; {forms}")
    return host, port


def check_exposure(host: str, password: str | None) -> None:
    """Refuse a non-loopback listen address without a password (FleetError)."""
    if password is None and not is_loopback(host):
        raise FleetError(
            f"listening on {host} exposes the view beyond this machine: give a password "
            "(imubench view --password-file FILE; HTTP basic authentication) or listen on "
            "127.0.0.1")
    if password is not None and not password:
        raise FleetError("the view's password is empty; put at least one character in it")


__all__ = ["check_exposure", "is_loopback", "parse_listen"]
