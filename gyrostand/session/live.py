"""The live daemon: a bus, a :class:`can.Notifier`, and a worker loop around the pipeline.

Threads: the Notifier's thread only runs the listeners (decode-and-append, record the raw
frame, watch for bus errors); the worker loop (the calling thread, so SIGINT/SIGTERM reach
it) pumps closed bins into :class:`~gyrostand.session.pipeline.Pipeline`, which identifies
and sends response frames. When idle the worker polls every ``poll`` s (2 ms): that bounds
the frame-to-result latency added by the loop.

The run ends on (first wins):

* SIGINT / SIGTERM (when ``handle_signals``) or ``stop_event``;
* a ``stop`` command frame;
* ``duration`` s of **frame time** since the first accepted frame; if frames stop flowing,
  also once ``duration + 5`` s of wall time have passed since the first frame (or since
  start when no frame came);
* a bus failure the Notifier cannot recover from (a non-CAN exception from ``recv``, e.g. a
  remote bus whose server died, or the Notifier thread dying): state ``fault``.

Then the Notifier is stopped (so the raw log and the bins hold exactly the same frames),
the last bins are flushed, and the pipeline writes the final fits and the report.
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
from ..config import SessionConfig
from .outputs import RunLog, make_run_dir
from .pipeline import BusSink, Pipeline, RunOutcome

__all__ = ["run_live", "NotifierWatch"]

log = logging.getLogger(__name__)

WALL_GRACE = 5.0  # s of wall time beyond --duration when frames stop flowing


class NotifierWatch(can.Listener):
    """A listener that only watches: ``on_error`` counts bus errors and marks as *fatal*
    any exception that is not a :class:`can.CanError` (a dead connection, a broken pipe),
    which the Notifier would otherwise report again on every ``recv``."""

    def __init__(self) -> None:
        self.errors = 0
        self.fatal: BaseException | None = None

    def on_message_received(self, msg: can.Message) -> None:
        pass

    def on_error(self, exc: Exception) -> None:
        self.errors += 1
        if self.fatal is None and not isinstance(exc, can.CanError):
            self.fatal = exc
            log.error("bus failure: %s: %s", type(exc).__name__, exc)


def _notifier_dead(notifier: can.Notifier) -> bool:
    threads = [r for r in getattr(notifier, "_readers", []) if isinstance(r, threading.Thread)]
    return any(not t.is_alive() for t in threads)


def run_live(cfg: SessionConfig, *, out: str | Path | None = None,
             duration: float | None = None, start_idle: bool = False,
             on_ready: Callable[[Path], None] | None = None,
             stop_event: threading.Event | None = None, handle_signals: bool = True,
             poll: float = 0.002, truths: dict[str, dict[str, float]] | None = None
             ) -> RunOutcome:
    """Run the daemon on ``cfg.bus`` until stopped; return the outcome (paths, fits).

    ``on_ready(run_dir)`` is called once the Notifier listens (frames sent before that are
    lost on most buses). ``truths`` (gyro → parameter values) only label the report.
    """
    bus = open_bus(cfg.bus)
    run_dir = make_run_dir(out or cfg.output, cfg.name)
    runlog = RunLog(run_dir)
    stop = stop_event or threading.Event()
    signalled: list[str] = []
    old_handlers: dict[signal.Signals, Any] = {}
    try:
        sink = BusSink(bus)
        pipe = Pipeline(cfg, run_dir, sink, source="live", start_idle=start_idle)
        recorder = Recorder(run_dir / "raw.blf", flush_interval=1.0)
        watch = NotifierWatch()
        if handle_signals and threading.current_thread() is threading.main_thread():
            def on_signal(signum: int, _frame: Any) -> None:
                signalled.append(signal.Signals(signum).name)
                stop.set()
            for sig in (signal.SIGINT, signal.SIGTERM):
                old_handlers[sig] = signal.signal(sig, on_signal)
        notifier = can.Notifier(bus, [pipe.listener, recorder, watch], timeout=0.05)
        try:
            log.info("ready: session %s on %s, run folder %s", cfg.name, bus.channel_info,
                     run_dir)
            if on_ready is not None:
                on_ready(run_dir)
            reason, state = _loop(pipe, recorder, watch, notifier, stop, signalled,
                                  duration, poll)
        finally:  # the raw log and the bins end with the same frame, even on an error
            notifier.stop(timeout=2.0)
            recorder.stop()
        pipe.step(pipe.ingest.finish())
        outcome = pipe.finish(reason, state=state, truths=truths, extra_stats={
            "recorder": {"frames": recorder.frames, "flushes": recorder.flushes,
                         "errors": recorder.errors, "unrecordable": recorder.unrecordable},
            "bus": {"channel": str(bus.channel_info), "watch_errors": watch.errors}})
        return outcome
    finally:
        for sig, h in old_handlers.items():
            signal.signal(sig, h)
        try:
            bus.shutdown()
        except Exception as exc:  # a dead remote bus may fail to shut down
            log.warning("bus shutdown: %s", exc)
        runlog.close()


def _loop(pipe: Pipeline, recorder: Recorder, watch: NotifierWatch, notifier: can.Notifier,
          stop: threading.Event, signalled: list[str], duration: float | None,
          poll: float) -> tuple[str, str]:
    """The worker loop; returns (why it stopped, final state)."""
    start_wall = time.monotonic()
    first_t: float | None = None
    first_wall = start_wall
    next_tick = start_wall + 1.0
    lst = pipe.listener
    while True:
        bins = pipe.ingest.pump()
        pipe.step(bins)
        now = time.monotonic()
        if now >= next_tick:
            recorder.flush()
            pipe.wall_tick()
            next_tick = now + 1.0
        if first_t is None and lst.last_timestamp > float("-inf"):
            first_t, first_wall = lst.last_timestamp, now
        if pipe.stop_requested:
            return pipe.stop_requested, "stopped"
        if stop.is_set():
            return (signalled[0] if signalled else "stop requested"), "stopped"
        if watch.fatal is not None:
            return f"bus failure: {type(watch.fatal).__name__}: {watch.fatal}", "fault"
        if _notifier_dead(notifier):
            return "the Notifier thread died", "fault"
        if duration is not None:
            if first_t is not None and lst.last_timestamp - first_t >= duration:
                return f"duration {duration:g} s of frame time", "stopped"
            if now - first_wall >= duration + WALL_GRACE:
                return f"duration {duration:g} s (wall clock, frames stopped)", "stopped"
        if not bins and lst.pending() == 0:
            stop.wait(poll)
