"""Running under systemd (``Type=notify``): readiness, status, watchdog and stop messages.

The sd_notify(3) datagrams go through the maintained pure-Python ``systemd-watchdog``
package (``READY=1``, ``STATUS=...``, ``WATCHDOG=1``, and ``STOPPING=1`` through its
send method); outside systemd (no ``NOTIFY_SOCKET``) every call does nothing. A failed
send is logged once and never stops the daemon. The daemon calls, in this order::

    notifier = ServiceNotifier()
    notifier.status("opening sim://lsm6dsl ...")
    ...                                    # source open, broker up, recording started
    notifier.ready("recording to ...; publishing imubench/bench1/imu0/allan")
    while running:                         # from the loop that proves the daemon works
        notifier.watchdog()                # at least every notifier.watchdog_interval_s
    notifier.stopping("stopping: draining the ring buffer")

With ``WatchdogSec=`` in the unit, systemd kills and (``Restart=on-failure``) restarts a
daemon whose ``WATCHDOG=1`` messages stop for that long; docs/service.md.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

from systemd_watchdog import WatchDog

log = logging.getLogger(__name__)


class _Notify(WatchDog):
    """``systemd_watchdog.WatchDog`` plus the ``STOPPING=1`` message."""

    def stopping(self) -> None:
        self._send("STOPPING=1\n")


class ServiceNotifier:
    """sd_notify messages to the service manager named by ``NOTIFY_SOCKET`` (read when
    made); ``WATCHDOG_USEC`` (and ``WATCHDOG_PID``) give the watchdog timeout."""

    def __init__(self) -> None:
        self._notify = _Notify()
        self._failed = False
        self._last_watchdog = float("-inf")

    @property
    def active(self) -> bool:
        """True under a service manager that listens (``NOTIFY_SOCKET`` set)."""
        return self._notify.is_enabled

    @property
    def watchdog_interval_s(self) -> float:
        """Send :meth:`watchdog` at least this often: half the ``WatchdogSec=`` timeout
        (sd_watchdog_enabled(3) advice); 12 h when no watchdog is configured."""
        return self._notify.timeout / 2e6

    def _send(self, what: str, call: Callable[[], None]) -> None:
        try:
            call()
        except OSError as exc:
            if not self._failed:
                log.warning("cannot notify the service manager (%s): %s", what, exc)
            self._failed = True

    def ready(self, status: str | None = None) -> None:
        """``READY=1``: start-up is complete (``Type=notify`` units become active)."""
        if status is not None:
            self.status(status)
        self._send("READY=1", self._notify.ready)

    def status(self, text: str) -> None:
        """``STATUS=text``: one line shown by ``systemctl status``."""
        line = " ".join(text.split())
        self._send("STATUS", lambda: self._notify.status(line))

    def watchdog(self) -> None:
        """``WATCHDOG=1``: the daemon is alive (call it from the loop that does the work)."""
        self._last_watchdog = time.monotonic()
        self._send("WATCHDOG=1", self._notify.notify)

    def watchdog_due(self) -> bool:
        """Whether :attr:`watchdog_interval_s` has passed since the last :meth:`watchdog`
        (monotonic clock: a wall-clock step cannot starve the watchdog)."""
        return time.monotonic() - self._last_watchdog >= self.watchdog_interval_s

    def stopping(self, status: str | None = None) -> None:
        """``STOPPING=1``: a clean shutdown has begun."""
        if status is not None:
            self.status(status)
        self._send("STOPPING=1", self._notify.stopping)


__all__ = ["ServiceNotifier"]
