"""The live daemon: a bus, a :class:`can.Notifier`, and a worker loop around the pipeline.

Threads: the Notifier's thread only runs the listeners (decode-and-append, record the raw
frame, watch for bus errors); the worker loop (the calling thread, so SIGINT / SIGTERM /
SIGHUP reach it) pumps closed bins into :class:`~gyrostand.session.pipeline.Pipeline`, which identifies
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

* SIGINT / SIGTERM / SIGHUP (when ``handle_signals``) or ``stop_event``; a run stopped
  by a signal then ignores the stop signals until the process exits (a second Ctrl-C
  cannot cut the final fits or files short: :class:`StopSignals` ``once``);
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

import contextlib
import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path

from ..can.recorder import Recorder
from ..config import ReconnectConfig, SessionConfig
from ..errors import CanEdgeError, OutputError
from ..runfolder import (
    RunLock,
    RunLog,
    SegmentLog,
    check_writable,
    make_run_dir,
    next_raw_segment,
    read_segments,
)
from ..runfolder.layout import RAW_LOG
from .buslink import Backoff, BusLink, NotifierWatch, StopSignals, open_bus_at_start
from .notify import ServiceNotify
from .pipeline import BusSink, Pipeline, RunOutcome
from .resume import find_resume_dir, prepare_resume

__all__ = ["run_live", "NotifierWatch", "BusLink", "Backoff", "StopSignals",
           "open_bus_at_start"]

log = logging.getLogger(__name__)

WALL_GRACE = 5.0  # s of wall time beyond --duration when frames stop flowing


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

    Every resource (the run folder's lock, the bus, ``run.log``, the raw log, the files,
    the signal handlers, the notification socket) is released in reverse order of
    acquisition however the run ends (a :class:`contextlib.ExitStack`).
    """
    notify = notify if notify is not None else ServiceNotify.from_environ()
    with contextlib.ExitStack() as stack:
        stack.callback(notify.close)
        state = None
        if resume is not None and resume is not False:
            run_dir = find_resume_dir(cfg, None if resume is True else str(resume) or None,
                                      out)
            stack.callback(RunLock(run_dir).release)  # before touching its files
            state = prepare_resume(cfg, run_dir)
            raw_path = state.segment
        sink = BusSink(None)
        link = BusLink(cfg.bus, [], sink)
        stack.callback(link.close)  # the bus, then (once listening) its Notifier
        link.bus = open_bus_at_start(cfg, stop_event, handle_signals, on_waiting)
        if state is None:
            run_dir = make_run_dir(out or cfg.output, cfg.name)
            raw_path = run_dir / RAW_LOG
            stack.callback(RunLock(run_dir).release)
        check_writable(run_dir)
        stack.callback(RunLog(run_dir).close)
        stack.callback(link.close)  # (again: so the bus is shut down before run.log closes)
        recorder = Recorder(raw_path, flush_interval=1.0, durable=cfg.fsync,
                            next_path=lambda: next_raw_segment(run_dir))
        stack.callback(recorder.stop)

        def commit_raw() -> None:  # before any bin reaches samples.csv
            recorder.sync() if cfg.fsync else recorder.flush()
            if recorder.failed is not None:
                raise recorder.failed

        segments = SegmentLog(run_dir, raw_path.name,
                              read_segments(run_dir) if state is not None else ())
        pipe = stack.enter_context(Pipeline(
            cfg, run_dir, sink, source="live", start_idle=start_idle,
            before_flush=commit_raw, resume=state, sync=cfg.fsync, segments=segments))
        stopping = stack.enter_context(StopSignals(stop_event or threading.Event(),
                                                   handle_signals, once=True))
        link.listeners += [pipe.listener, recorder.on_message_received]
        link.open(link.bus)
        try:
            log.info("ready: session %s on %s, run folder %s%s", cfg.name, link.channel,
                     run_dir, f" (resumed, raw log {raw_path.name})" if state else "")
            if on_ready is not None:
                on_ready(run_dir)
            notify.ready(f"listening on {link.channel}; run folder {run_dir}")
            reason, final_state, outage_s = _loop(pipe, recorder, link, stopping, duration,
                                                  poll, cfg.reconnect, notify)
            notify.stopping(f"stopping: {reason}")
        finally:  # the raw log and the bins end with the same frame, even on an error
            link.stop_notifier()
            recorder.stop()
        try:
            pipe.step(pipe.ingest.finish())
        except OutputError as exc:
            log.error("%s", exc)
            reason, final_state = f"{reason}; {exc}", "fault"
        return pipe.finish(reason, state=final_state, truths=truths, extra_stats={
            "recorder": {"file": raw_path.name, "frames": recorder.frames,
                         "flushes": recorder.flushes, "errors": recorder.errors,
                         "unrecordable": recorder.unrecordable,
                         "files": [p.name for p in recorder.files],
                         "unfaithful": recorder.unfaithful,
                         "failed": str(recorder.failed) if recorder.failed else None},
            "bus": {"channel": link.channel,
                    "watch_errors": link.watch_errors + link.watch.errors,
                    "outages": pipe.outages, "outage_s": round(outage_s, 3)}})


def _service_status(pipe: Pipeline, note: str = "") -> str:
    """The STATUS line ``systemctl status`` shows."""
    d, b = pipe.listener.stats(), pipe.binner.stats()
    return (f"{pipe.state}{note}: {b.bins} bins, {b.gaps} gaps; frames {d.decoded} decoded, "
            f"{d.rejected_total} rejected; {pipe.outages} outages")


def _loop(pipe: Pipeline, recorder: Recorder, link: BusLink, stop: StopSignals,
          duration: float | None, poll: float, rc: ReconnectConfig,
          notify: ServiceNotify) -> tuple[str, str, float]:
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
            return stop.reason("stop requested"), "stopped", outage_s
        why = link.failure()
        if why is not None:
            t_out = time.monotonic()
            back = _reconnect(pipe, link, stop, rc, why, notify)
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
            stop.stop.wait(poll)


def _reconnect(pipe: Pipeline, link: BusLink, stop: StopSignals, rc: ReconnectConfig,
               why: str, notify: ServiceNotify) -> tuple[str, str] | None:
    """An outage: close the bus, reopen it with :class:`Backoff` for up to
    ``reconnect.max_time`` s. None when the bus is back, else (why the run stops, state)."""
    pipe.outages += 1
    backoff = Backoff.of(rc, rc.max_time)
    t0 = backoff.start
    log.error("bus outage %d at frame time %.3f: %s; reopening the bus with backoff for "
              "up to %g s (reconnect.max_time)", pipe.outages, pipe.frame_time(), why,
              rc.max_time)
    link.close()
    next_try = t0 + backoff.next_wait(t0)
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
                if backoff.expired(now):
                    log.error("bus outage %d: no bus after %.1f s (%d attempts); giving up",
                              pipe.outages, now - t0, attempts)
                    return (f"bus failure: {why} (no bus after {now - t0:.1f} s, "
                            f"{attempts} attempts)"), "fault"
                next_try = now + backoff.next_wait(now)
            else:
                pipe.listener.resync()
                pipe.binner.rebase()
                log.warning("bus outage %d ended: bus reopened after %.1f s (%d attempts); "
                            "its bins are gaps", pipe.outages, now - t0, attempts)
                return None
        stop.stop.wait(min(0.05, max(0.0, min(next_try, next_tick) - time.monotonic())))
