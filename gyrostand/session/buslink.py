"""The bus side of a live run: opening it (with :class:`Backoff` while it cannot be opened
yet), its :class:`can.Notifier` and the watch that tells a dead bus from bus errors
(:class:`BusLink`), and SIGINT / SIGTERM / SIGHUP as a stop request (:class:`StopSignals`).

One backoff serves the start-up (``reconnect.at_start`` s) and the reopening after an
outage (``reconnect.max_time`` s, in :mod:`~gyrostand.session.live`): ``first_delay`` s,
doubling up to ``max_delay`` s.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
import time
from collections.abc import Callable
from typing import Any

import can

from ..can.bus import open_bus
from ..config import ReconnectConfig, SessionConfig
from ..errors import BusUnavailableError, CanEdgeError
from .responses import BusSink

__all__ = ["BusLink", "NotifierWatch", "Backoff", "StopSignals", "STOP_SIGNALS",
           "open_bus_at_start"]

log = logging.getLogger(__name__)


class NotifierWatch(can.Listener):
    """A listener that only watches: ``on_error`` counts bus errors and marks as *fatal*
    any exception that is not a :class:`can.CanError` (a dead connection, a broken pipe),
    which the Notifier would otherwise report again on every ``recv``: after a fatal one it
    slows the Notifier's thread down (``pause`` s per error) until the worker stops it."""

    def __init__(self, pause: float = 0.05) -> None:
        self.errors = 0
        self.fatal: BaseException | None = None
        self.pause = pause

    def on_message_received(self, msg: can.Message) -> None:
        pass

    def on_error(self, exc: Exception) -> None:
        self.errors += 1
        if self.fatal is not None:
            time.sleep(self.pause)
        elif not isinstance(exc, can.CanError):
            self.fatal = exc
            log.error("bus failure: %s: %s", type(exc).__name__, exc)


def _notifier_dead(notifier: can.Notifier) -> bool:
    threads = [r for r in getattr(notifier, "_readers", []) if isinstance(r, threading.Thread)]
    return any(not t.is_alive() for t in threads)


class BusLink:
    """The bus, its Notifier and watch; closed and reopened across outages.

    ``listeners`` are what the Notifier calls per frame: listener objects (their
    ``on_error`` sees bus errors) or plain callables. ``Notifier.stop`` calls ``stop()`` on
    every listener object, so the recorder is given as its bound ``on_message_received``:
    an outage must not close the raw log."""

    def __init__(self, bus_cfg: Any, listeners: list[Any], sink: BusSink) -> None:
        self.bus_cfg, self.listeners, self.sink = bus_cfg, listeners, sink
        self.bus: can.BusABC | None = None
        self.notifier: can.Notifier | None = None
        self.watch = NotifierWatch()
        self.watch_errors = 0
        self.channel = ""

    def open(self, bus: can.BusABC | None = None) -> None:
        """Open the bus (or take ``bus``) and start a Notifier on it. Raises
        :class:`~gyrostand.errors.CanEdgeError`."""
        self.bus = bus if bus is not None else open_bus(self.bus_cfg)
        self.channel = str(self.bus.channel_info)
        self.watch_errors += self.watch.errors
        self.watch = NotifierWatch()
        self.notifier = can.Notifier(self.bus, [self.watch, *self.listeners], timeout=0.05)
        self.sink.bus = self.bus

    def failure(self) -> str | None:
        """Why the bus is unusable, or None."""
        if self.watch.fatal is not None:
            return f"{type(self.watch.fatal).__name__}: {self.watch.fatal}"
        if self.notifier is not None and _notifier_dead(self.notifier):
            return "the Notifier thread died"
        return None

    def stop_notifier(self) -> None:
        """Stop the Notifier: its listeners get nothing more (the bus stays open for the
        daemon's last frames)."""
        if self.notifier is not None:
            try:
                self.notifier.stop(timeout=2.0)
            except Exception as exc:  # a dead Notifier thread may have left an error
                log.warning("notifier stop: %s", exc)
            self.notifier = None

    def close(self) -> None:
        """Stop the Notifier and shut the bus down."""
        self.sink.bus = None
        self.stop_notifier()
        if self.bus is not None:
            try:
                self.bus.shutdown()
            except Exception as exc:  # a dead remote bus may fail to shut down
                log.warning("bus shutdown: %s", exc)
            self.bus = None


def _permanent(exc: CanEdgeError) -> bool:
    """A bus that no retry can open: unknown interface, driver not installed, bad args."""
    return isinstance(exc.__cause__, (can.CanInterfaceNotImplementedError, ImportError,
                                      TypeError, ValueError))


class Backoff:
    """The waits between attempts to open the bus, at start-up and after an outage:
    ``first`` s, then twice as long each time up to ``cap`` s (no jitter: one daemon per
    bus), none reaching past ``limit`` s after ``start`` (monotonic clock, s)."""

    def __init__(self, first: float, cap: float, limit: float, start: float) -> None:
        self.first, self.cap, self.limit, self.start = first, cap, limit, start
        self._delay = first

    @classmethod
    def of(cls, rc: ReconnectConfig, limit: float) -> Backoff:
        """``reconnect.first_delay`` doubling up to ``reconnect.max_delay``, for ``limit``
        s from now."""
        return cls(rc.first_delay, rc.max_delay, limit, time.monotonic())

    def expired(self, now: float) -> bool:
        return now - self.start >= self.limit

    def next_wait(self, now: float) -> float:
        """The wait (s) before the next attempt, at ``now``; the one after doubles."""
        wait = max(0.0, min(self._delay, self.start + self.limit - now))
        self._delay = min(self._delay * 2, self.cap)
        return wait


#: the signals that end a run: Ctrl-C, ``kill`` / ``systemctl stop``, and a closing terminal
#: (SIGHUP, where the platform has it); each ends it as SIGTERM does, never unfinished
STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP")
                     if hasattr(signal, n))


class StopSignals:
    """SIGINT / SIGTERM / SIGHUP (:data:`STOP_SIGNALS`) as a stop request, for as long as
    the ``with`` block runs (only in the main thread, when ``enabled``; the previous
    handlers come back at its end).

    The handler only appends the signal's name to :attr:`names` (an atomic append, no
    lock): a handler that called :meth:`threading.Event.set` could deadlock, since it runs
    in the main thread, which may hold that event's lock at that moment (inside
    ``Event.wait``). Waiters poll :meth:`is_set` (see :meth:`wait`), which then sets
    ``stop``.

    ``once``: the process ends with this block (the daemon). When a stop signal came, the
    stop signals are *ignored* from its end on instead of getting their old handlers back:
    the run is finished and its files written, and a second Ctrl-C (or a SIGHUP after a
    SIGTERM) while the process closes its bus and exits must not kill it half-way
    (``KeyboardInterrupt`` in the clean-up, exit -2 during the interpreter's shutdown)."""

    def __init__(self, stop: threading.Event, enabled: bool = True, *,
                 once: bool = False) -> None:
        self.stop = stop
        self.names: list[str] = []  # the signals received, in order
        self.enabled = enabled and threading.current_thread() is threading.main_thread()
        self.once = once
        self._old: dict[signal.Signals, Any] = {}

    def __enter__(self) -> StopSignals:
        if self.enabled:
            for sig in STOP_SIGNALS:
                self._old[sig] = signal.signal(sig, self._on_signal)
        return self

    def __exit__(self, *exc: object) -> None:
        ignore = self.once and bool(self.names)
        for sig, handler in self._old.items():
            signal.signal(sig, signal.SIG_IGN if ignore else handler)
        self._old.clear()

    def _on_signal(self, signum: int, _frame: Any) -> None:
        self.names.append(signal.Signals(signum).name)

    def is_set(self) -> bool:
        """Whether a stop was asked for: a signal (then ``stop`` is set too, from here,
        outside the handler, for whoever else watches it) or ``stop``."""
        if self.names and not self.stop.is_set():
            self.stop.set()
        return self.stop.is_set()

    def reason(self, default: str) -> str:
        return self.names[0] if self.names else default

    def wait(self, seconds: float, slice_s: float = 0.05) -> None:
        """Wait up to ``seconds`` or until a stop (seen within ``slice_s`` s of a signal)."""
        end = time.monotonic() + seconds
        while not self.is_set():
            left = end - time.monotonic()
            if left <= 0 or self.stop.wait(min(left, slice_s)):
                return


def open_bus_at_start(cfg: SessionConfig, stop: threading.Event | None = None,
                      handle_signals: bool = True,
                      on_waiting: Callable[[str], None] | None = None) -> can.BusABC:
    """Open ``cfg.bus``; while it cannot be opened, retry with backoff
    (``reconnect.first_delay`` doubling up to ``max_delay``, :class:`Backoff`) for
    ``reconnect.at_start`` s. Raises :class:`CanEdgeError` (the last failure, with the time
    waited) when the time is up, at once for a bus that can never open, or when ``stop`` is
    set / a stop signal arrives (:data:`STOP_SIGNALS`, with ``handle_signals``, in the main thread) while
    waiting. ``on_waiting(text)`` is called once when the waiting begins (the CLI prints
    it: a signal for whoever starts the bus after the daemon)."""
    rc = cfg.reconnect
    backoff = Backoff.of(rc, rc.at_start)
    attempts = 0
    with contextlib.ExitStack() as stack:
        stopping = StopSignals(stop or threading.Event(), enabled=False)
        while True:
            attempts += 1
            try:
                bus = open_bus(cfg.bus)
            except CanEdgeError as exc:
                now = time.monotonic()
                waited = now - backoff.start
                if _permanent(exc) or rc.at_start <= 0:
                    raise
                if backoff.expired(now) or stopping.is_set():
                    why = "stopped" if stopping.is_set() else "giving up"
                    raise BusUnavailableError(f"{exc} ({why} after {waited:.1f} s and {attempts} "
                                              f"attempts, reconnect.at_start {rc.at_start:g} s)"
                                       ) from exc.__cause__
                if attempts == 1:
                    log.warning("%s; waiting for the bus, up to %g s (reconnect.at_start)",
                                exc, rc.at_start)
                    if on_waiting is not None:
                        on_waiting(f"for the bus, up to {rc.at_start:g} s "
                                   f"(reconnect.at_start)")
                    stopping = stack.enter_context(StopSignals(stopping.stop,
                                                               handle_signals))
                else:
                    log.info("bus not open yet, attempt %d: %s", attempts, exc)
                stopping.wait(backoff.next_wait(now))
            else:
                if attempts > 1:
                    log.warning("bus opened after %.1f s (%d attempts)",
                                time.monotonic() - backoff.start, attempts)
                return bus
