"""systemd's service notification protocol (``sd_notify(3)``), spoken directly.

systemd (``Type=notify``) passes ``NOTIFY_SOCKET``, the path of a unix datagram socket (an
abstract one when it starts with ``@``), and, with ``WatchdogSec=``, ``WATCHDOG_USEC``
(the watchdog period, µs) and ``WATCHDOG_PID`` (the process it applies to). A message is
one datagram of newline-separated ``KEY=VALUE`` assignments:

* ``READY=1`` once the daemon listens on the bus (``systemctl start`` returns then);
* ``STATUS=...`` a line ``systemctl status`` shows (state, bins, frames);
* ``WATCHDOG=1`` the keep-alive; systemd restarts the service (``Restart=on-watchdog``
  or ``on-failure``) when none comes for ``WATCHDOG_USEC``;
* ``STOPPING=1`` when it begins to shut down.

The daemon pings from its worker loop (:func:`~gyrostand.session.live.run_live`), never
from a thread of its own, so a worker that hangs stops the pings and systemd notices.
Pings go out every half watchdog period (``sd_watchdog_enabled(3)``'s advice), statuses at
most once a second. Without ``NOTIFY_SOCKET`` every call is a no-op. A notification that
cannot be sent is logged once and never stops the daemon.
"""

from __future__ import annotations

import logging
import os
import socket
import time
from collections.abc import Mapping

__all__ = ["ServiceNotify"]

log = logging.getLogger(__name__)


class ServiceNotify:
    """Notifications to systemd over ``address`` (None: disabled).

    ``watchdog`` is the watchdog period (s) or None when systemd asks for no pings.
    """

    def __init__(self, address: str | None = None, watchdog: float | None = None) -> None:
        self.address = address
        self.watchdog = watchdog
        self.sent = 0
        self.pings = 0
        self._sock: socket.socket | None = None
        self._next_ping = 0.0
        self._failed = False

    @classmethod
    def from_environ(cls, environ: Mapping[str, str] | None = None) -> ServiceNotify:
        """From ``NOTIFY_SOCKET`` / ``WATCHDOG_USEC`` / ``WATCHDOG_PID`` (``os.environ``)."""
        env = os.environ if environ is None else environ
        address = env.get("NOTIFY_SOCKET") or None
        watchdog = None
        usec = env.get("WATCHDOG_USEC", "")
        pid = env.get("WATCHDOG_PID", "")
        if usec.isdigit() and int(usec) > 0 and (not pid or pid == str(os.getpid())):
            watchdog = int(usec) / 1e6
        elif usec:
            log.debug("WATCHDOG_USEC=%r (WATCHDOG_PID=%r) is not for this process", usec, pid)
        return cls(address, watchdog)

    @property
    def enabled(self) -> bool:
        return self.address is not None

    def send(self, **fields: str | int) -> bool:
        """Send one datagram ``KEY=VALUE\\n...`` (``ready=1`` -> ``READY=1``); True if sent."""
        if self.address is None:
            return False
        text = "\n".join(f"{k.upper()}={v}" for k, v in fields.items())
        addr = "\0" + self.address[1:] if self.address.startswith("@") else self.address
        try:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.sendto(text.encode("utf-8", "replace"), addr)
        except OSError as exc:
            if not self._failed:
                log.warning("sd_notify to %s failed: %s (not retried in the log)",
                            self.address, exc)
                self._failed = True
            return False
        self.sent += 1
        return True

    def ready(self, status: str) -> None:
        self.send(ready=1, status=status)
        self._next_ping = 0.0

    def status(self, status: str) -> None:
        self.send(status=status)

    def ping(self, now: float | None = None) -> None:
        """``WATCHDOG=1`` when systemd asked for it and half a period has passed since the
        last one (call it from every pass of the worker loop; it is cheap when not due)."""
        if self.watchdog is None or self.address is None:
            return
        now = time.monotonic() if now is None else now
        if now < self._next_ping:
            return
        if self.send(watchdog=1):
            self.pings += 1
        self._next_ping = now + self.watchdog / 2

    def stopping(self, status: str) -> None:
        self.send(stopping=1, status=status)

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
