"""The live daemon: a bus, a :class:`can.Notifier`, and a worker loop around the pipeline.

Threads: the Notifier's thread only runs the listeners (decode-and-append, record the raw
frame, watch for bus errors); the worker loop (the calling thread, so SIGINT/SIGTERM reach
it) pumps closed bins into :class:`~gyrostand.session.pipeline.Pipeline`, which identifies
and sends response frames. When idle the worker polls every ``poll`` s (2 ms): that bounds
the frame-to-result latency added by the loop. Once a second (wall clock) the worker
*acknowledges*: the raw log is committed, then the pending bins are written to
``samples.csv`` (so every row on disk replays from the raw log), then ``estimates.csv``.

**Bus outage.** When the bus fails in a way the Notifier cannot recover from (a non-CAN
exception from ``recv``, e.g. a ``remote`` server that went away, or the Notifier thread
dying), the daemon logs the outage, closes the bus, and reopens it with exponential backoff
(``reconnect.first_delay`` doubling up to ``reconnect.max_delay`` s) for up to
``reconnect.max_time`` s, meanwhile binning what it has and keeping the files flushed.
When the bus is back it continues in the same run: frames of the outage are missing, so
its bins are gaps (n = 0; after an outage longer than ``sampling.max_gap`` the frames are
timed as after a clock step, as a replay of the raw log times them), never invented. The outage count is in the heartbeat (page 2, ``Outages``), in
``run.log`` and in ``result.json`` (``stats.bus``). Without a bus after ``max_time`` s the
run ends in state ``fault``.

The run ends on (first wins):

* SIGINT / SIGTERM (when ``handle_signals``) or ``stop_event``;
* a ``stop`` command frame;
* ``duration`` s of **frame time** since the first accepted frame; if frames stop flowing,
  also once ``duration + 5`` s of wall time have passed since the first frame (or since
  start when no frame came);
* no bus for ``reconnect.max_time`` s after an outage: state ``fault``;
* a run file that cannot be written (disk full, ...): state ``fault``, the reason names
  the file; what was acknowledged before stays on disk, readable.

Then the Notifier is stopped (so the raw log and the bins hold exactly the same frames),
the last bins are flushed, and the pipeline writes the final fits and the report.

``resume`` continues an existing run folder (:mod:`~gyrostand.session.resume`).

Under systemd (``NOTIFY_SOCKET``) the daemon notifies READY once listening, a STATUS line
(state, bins, gaps, frames) at every acknowledgement, WATCHDOG pings from this worker loop
(also while it waits out a bus outage) when ``WATCHDOG_USEC`` asks for them, and STOPPING
when it stops (:mod:`~gyrostand.session.notify`).
"""

from __future__ import annotations

import logging
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can

from ..can.bus import open_bus
from ..can.recorder import Recorder
from ..config import ReconnectConfig, SessionConfig
from ..errors import CanEdgeError, OutputError
from .notify import ServiceNotify
from .outputs import (
    RunLock,
    RunLog,
    SegmentLog,
    check_writable,
    make_run_dir,
    next_raw_segment,
    read_segments,
)
from .pipeline import BusSink, Pipeline, RunOutcome
from .resume import find_resume_dir, prepare_resume

__all__ = ["run_live", "NotifierWatch", "BusLink"]

log = logging.getLogger(__name__)

WALL_GRACE = 5.0  # s of wall time beyond --duration when frames stop flowing


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


def open_bus_at_start(cfg: SessionConfig, stop: threading.Event | None = None,
                      handle_signals: bool = True,
                      on_waiting: Callable[[str], None] | None = None) -> can.BusABC:
    """Open ``cfg.bus``; while it cannot be opened, retry with backoff
    (``reconnect.first_delay`` doubling up to ``max_delay``) for ``reconnect.at_start`` s.
    Raises :class:`CanEdgeError` (the last failure, with the time waited) when the time is
    up, at once for a bus that can never open, or when ``stop`` is set / SIGINT or
    SIGTERM arrives (with ``handle_signals``, in the main thread) while waiting.
    ``on_waiting(text)`` is called once when the waiting begins (the CLI prints it: a
    signal for whoever starts the bus after the daemon)."""
    rc = cfg.reconnect
    t0 = time.monotonic()
    delay, attempts = rc.first_delay, 0
    stop = stop or threading.Event()
    old: dict[signal.Signals, Any] = {}
    try:
        while True:
            attempts += 1
            try:
                bus = open_bus(cfg.bus)
            except CanEdgeError as exc:
                waited = time.monotonic() - t0
                if _permanent(exc) or rc.at_start <= 0:
                    raise
                if waited >= rc.at_start or stop.is_set():
                    why = "stopped" if stop.is_set() else "giving up"
                    raise CanEdgeError(f"{exc} ({why} after {waited:.1f} s and {attempts} "
                                       f"attempts, reconnect.at_start {rc.at_start:g} s)"
                                       ) from exc.__cause__
                if attempts == 1:
                    log.warning("%s; waiting for the bus, up to %g s (reconnect.at_start)",
                                exc, rc.at_start)
                    if on_waiting is not None:
                        on_waiting(f"for the bus, up to {rc.at_start:g} s "
                                   f"(reconnect.at_start)")
                    if handle_signals and threading.current_thread() is threading.main_thread():
                        for sig in (signal.SIGINT, signal.SIGTERM):
                            old[sig] = signal.signal(sig, lambda *_: stop.set())
                else:
                    log.info("bus not open yet, attempt %d: %s", attempts, exc)
                stop.wait(max(0.0, min(delay, rc.at_start - waited)))
                delay = min(delay * 2, rc.max_delay)
            else:
                if attempts > 1:
                    log.warning("bus opened after %.1f s (%d attempts)",
                                time.monotonic() - t0, attempts)
                return bus
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)


def run_live(cfg: SessionConfig, *, out: str | Path | None = None,
             duration: float | None = None, start_idle: bool = False,
             on_ready: Callable[[Path], None] | None = None,
             stop_event: threading.Event | None = None, handle_signals: bool = True,
             poll: float = 0.002, truths: dict[str, dict[str, float]] | None = None,
             resume: str | Path | bool | None = None,
             notify: ServiceNotify | None = None,
             on_waiting: Callable[[str], None] | None = None) -> RunOutcome:
    """Run the daemon on ``cfg.bus`` until stopped; return the outcome (paths, fits).

    ``on_ready(run_dir)`` is called once the Notifier listens (frames sent before that are
    lost on most buses). ``truths`` (gyro → parameter values) only label the report.
    ``resume``: continue a run folder instead of starting one (a path, or ``True`` / ``""``
    for the session's newest run folder under ``out``). ``notify``: systemd notifications
    (default: from ``NOTIFY_SOCKET`` / ``WATCHDOG_USEC`` in the environment).
    ``on_waiting(text)``: called when the daemon begins to wait for a bus that cannot be
    opened yet.
    """
    notify = notify if notify is not None else ServiceNotify.from_environ()
    state = None
    lock: RunLock | None = None
    if resume is not None and resume is not False:
        run_dir = find_resume_dir(cfg, None if resume is True else str(resume) or None, out)
        lock = RunLock(run_dir)  # before touching its files: no other daemon writes it
        try:
            state = prepare_resume(cfg, run_dir)
        except BaseException:
            lock.release()
            raise
        raw_path = state.segment
    try:
        bus = open_bus_at_start(cfg, stop_event, handle_signals, on_waiting)
    except BaseException:
        if lock is not None:
            lock.release()
        raise
    try:
        if state is None:
            run_dir = make_run_dir(out or cfg.output, cfg.name)
            raw_path = run_dir / "raw.blf"
            lock = RunLock(run_dir)
        check_writable(run_dir)
        runlog = RunLog(run_dir)
    except BaseException:
        bus.shutdown()
        if lock is not None:
            lock.release()
        raise
    stop = stop_event or threading.Event()
    signalled: list[str] = []
    old_handlers: dict[signal.Signals, Any] = {}
    sink = BusSink(None)
    link: BusLink | None = None
    try:
        recorder = Recorder(raw_path, flush_interval=1.0, durable=cfg.fsync,
                            next_path=lambda: next_raw_segment(run_dir))

        def commit_raw() -> None:  # before any bin reaches samples.csv
            recorder.sync() if cfg.fsync else recorder.flush()
            if recorder.failed is not None:
                raise recorder.failed

        segments = SegmentLog(run_dir, raw_path.name,
                              read_segments(run_dir) if state is not None else ())
        pipe = Pipeline(cfg, run_dir, sink, source="live", start_idle=start_idle,
                        before_flush=commit_raw, resume=state, sync=cfg.fsync,
                        segments=segments)
        if handle_signals and threading.current_thread() is threading.main_thread():
            def on_signal(signum: int, _frame: Any) -> None:
                signalled.append(signal.Signals(signum).name)
                stop.set()
            for sig in (signal.SIGINT, signal.SIGTERM):
                old_handlers[sig] = signal.signal(sig, on_signal)
        link = BusLink(cfg.bus, [pipe.listener, recorder.on_message_received], sink)
        link.open(bus)
        outage_s = 0.0
        try:
            log.info("ready: session %s on %s, run folder %s%s", cfg.name, link.channel,
                     run_dir, f" (resumed, raw log {raw_path.name})" if state else "")
            if on_ready is not None:
                on_ready(run_dir)
            notify.ready(f"listening on {link.channel}; run folder {run_dir}")
            reason, final_state, outage_s = _loop(pipe, recorder, link, stop, signalled,
                                                  duration, poll, cfg.reconnect, notify)
            notify.stopping(f"stopping: {reason}")
        finally:  # the raw log and the bins end with the same frame, even on an error
            link.stop_notifier()
            recorder.stop()
        try:
            pipe.step(pipe.ingest.finish())
        except OutputError as exc:
            log.error("%s", exc)
            reason, final_state = f"{reason}; {exc}", "fault"
        outcome = pipe.finish(reason, state=final_state, truths=truths, extra_stats={
            "recorder": {"file": raw_path.name, "frames": recorder.frames,
                         "flushes": recorder.flushes, "errors": recorder.errors,
                         "unrecordable": recorder.unrecordable,
                         "files": [p.name for p in recorder.files],
                         "unfaithful": recorder.unfaithful,
                         "failed": str(recorder.failed) if recorder.failed else None},
            "bus": {"channel": link.channel,
                    "watch_errors": link.watch_errors + link.watch.errors,
                    "outages": pipe.outages, "outage_s": round(outage_s, 3)}})
        return outcome
    finally:
        for sig, h in old_handlers.items():
            signal.signal(sig, h)
        if link is not None:
            link.close()
        else:
            try:
                bus.shutdown()
            except Exception as exc:
                log.warning("bus shutdown: %s", exc)
        runlog.close()
        if lock is not None:
            lock.release()
        notify.close()


def _service_status(pipe: Pipeline, note: str = "") -> str:
    """The STATUS line ``systemctl status`` shows."""
    d, b = pipe.listener.stats(), pipe.binner.stats()
    return (f"{pipe.state}{note}: {b.bins} bins, {b.gaps} gaps; frames {d.decoded} decoded, "
            f"{d.rejected_total} rejected; {pipe.outages} outages")


def _loop(pipe: Pipeline, recorder: Recorder, link: BusLink, stop: threading.Event,
          signalled: list[str], duration: float | None, poll: float,
          rc: ReconnectConfig, notify: ServiceNotify) -> tuple[str, str, float]:
    """The worker loop; returns (why it stopped, final state, s spent in outages)."""
    start_wall = time.monotonic()
    first_t: float | None = None
    first_wall = start_wall
    next_tick = start_wall + 1.0
    lst = pipe.listener
    outage_s = 0.0
    while True:
        try:
            bins = pipe.ingest.pump()
            pipe.step(bins)
            now = time.monotonic()
            if now >= next_tick:
                pipe.wall_tick()  # acknowledges: raw log, then samples, then estimates
                next_tick = now + 1.0
                notify.status(_service_status(pipe))
            notify.ping(now)  # from this loop only: a hung worker stops the pings
        except OutputError as exc:
            return str(exc), "fault", outage_s
        if recorder.failed is not None:
            return str(recorder.failed), "fault", outage_s
        if first_t is None and lst.last_timestamp > float("-inf"):
            first_t, first_wall = lst.last_timestamp, now
        if pipe.stop_requested:
            return pipe.stop_requested, "stopped", outage_s
        if stop.is_set():
            return (signalled[0] if signalled else "stop requested"), "stopped", outage_s
        why = link.failure()
        if why is not None:
            t_out = time.monotonic()
            back = _reconnect(pipe, recorder, link, stop, rc, why, notify)
            outage_s += time.monotonic() - t_out
            next_tick = time.monotonic()
            if back is not None:
                return back[0], back[1], outage_s
            continue
        if duration is not None:
            if first_t is not None and lst.last_timestamp - first_t >= duration:
                return f"duration {duration:g} s of frame time", "stopped", outage_s
            if now - first_wall >= duration + WALL_GRACE:
                return (f"duration {duration:g} s (wall clock, frames stopped)", "stopped",
                        outage_s)
        if not bins and lst.pending() == 0:
            stop.wait(poll)


def _reconnect(pipe: Pipeline, recorder: Recorder, link: BusLink, stop: threading.Event,
               rc: ReconnectConfig, why: str, notify: ServiceNotify) -> tuple[str, str] | None:
    """An outage: close the bus, reopen it with backoff. None when the bus is back, else
    (why the run stops, state)."""
    pipe.outages += 1
    t0 = time.monotonic()
    log.error("bus outage %d at frame time %.3f: %s; reopening the bus with backoff for "
              "up to %g s (reconnect.max_time)", pipe.outages, pipe.frame_time(), why,
              rc.max_time)
    link.close()
    delay = rc.first_delay
    next_try = t0 + min(delay, rc.max_time)
    next_tick = t0
    attempts = 0
    while True:
        now = time.monotonic()
        notify.ping(now)  # the worker is alive: it is waiting for the bus
        if pipe.stop_requested:
            return pipe.stop_requested, "stopped"
        if stop.is_set():
            return "stop requested during a bus outage", "stopped"
        if now >= next_tick:  # keep binning what arrived and acknowledging it
            try:
                pipe.step(pipe.ingest.pump())
                pipe.wall_tick()
            except OutputError as exc:
                return str(exc), "fault"
            next_tick = now + 1.0
            notify.status(_service_status(pipe, f" (bus outage {pipe.outages})"))
        if now >= next_try:
            attempts += 1
            try:
                link.open()
            except CanEdgeError as exc:
                log.info("bus outage %d: attempt %d failed: %s", pipe.outages, attempts, exc)
                if now - t0 >= rc.max_time:
                    log.error("bus outage %d: no bus after %.1f s (%d attempts); giving up",
                              pipe.outages, now - t0, attempts)
                    return (f"bus failure: {why} (no bus after {now - t0:.1f} s, "
                            f"{attempts} attempts)"), "fault"
                delay = min(delay * 2, rc.max_delay)
                next_try = min(now + delay, t0 + rc.max_time)
            else:
                pipe.listener.resync()
                pipe.binner.rebase()
                log.warning("bus outage %d ended: bus reopened after %.1f s (%d attempts); "
                            "its bins are gaps", pipe.outages, now - t0, attempts)
                return None
        stop.wait(min(0.05, max(0.0, min(next_try, next_tick) - time.monotonic())))
