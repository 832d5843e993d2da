"""The daemon's core, shared by live runs and replay: it does not know where frames come from.

A driver (:mod:`~gyrostand.session.live` with a :class:`can.Notifier`, or
:mod:`~gyrostand.session.offline` with a log file) opens the pipeline
(:meth:`Pipeline.open`, or ``with Pipeline(...) as pipe``), feeds frames to
:attr:`Pipeline.listener` and calls :meth:`Pipeline.step` with the bins that closed. Per
step, in this order:

1. every closed bin goes to ``<gyro>/samples.csv``, updates the gyro's online identifiers
   (unless the run is ``idle``) and appends a row to ``<gyro>/estimates.csv``
   (:mod:`~gyrostand.session.acked`);
2. when frame time crosses a multiple of ``responses.period`` (s) at a bin close, a result
   round is sent (:mod:`~gyrostand.session.responses`);
3. commands received since the last step are handled and acknowledged
   (:mod:`~gyrostand.session.commands`: ``start``, ``stop``, ``reset``, ``snapshot``; the
   state machine, refusals and the rate limit);
4. when ``responses.heartbeat`` s of frame time have passed since the last beat, the
   3-page ``GS_STATUS`` heartbeat is sent.

:meth:`Pipeline.finish` ends the run (:mod:`~gyrostand.session.runend`).

All timing is frame time (the newest accepted frame's timestamp, s); only
:meth:`Pipeline.wall_tick` reads the wall clock (live: the heartbeat of a silent bus).
The constructor builds the in-memory parts only; :meth:`Pipeline.open` creates the files,
writes the provisional ``result.json`` and, resuming, feeds the kept bins again.
"""

from __future__ import annotations

import bisect
import logging
import math
import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict
from pathlib import Path
from types import TracebackType
from typing import Any

from ..can.binning import Bin, Binner
from ..can.bus import COMMANDS
from ..can.ingest import Ingest
from ..can.receive.listener import DecodingListener
from ..can.routes import ChannelMap
from ..config import SessionConfig
from ..errors import GyrostandError, OutputError
from ..runfolder import EstimatesWriter, SamplesWriter, SegmentLog
from ..runfolder.layout import RESULT
from .acked import AckedFiles
from .commands import CommandProtocol, TokenBucket
from .final import write_provisional_result
from .online import GyroTracker, OnlineEstimate
from .responses import BusSink, FrameSink, NullSink, Responses
from .resume import ResumeState
from .runend import RunOutcome, finish_run

__all__ = ["Pipeline", "session_ingest", "FrameSink", "NullSink", "BusSink", "RunOutcome",
           "TokenBucket"]

log = logging.getLogger(__name__)


def _quantile(xs: Iterable[float], q: float) -> float:
    s = sorted(xs)
    if not s:
        return math.nan
    return s[min(len(s) - 1, int(q * len(s)))]


def session_ingest(cfg: SessionConfig, channels: ChannelMap | None = None) -> Ingest:
    """The session's receive path: its DBC mapping's decoding listener and the 1-s binner,
    as every run (live, replay) builds them; also what reads a raw log into samples for
    the workbench (:func:`~gyrostand.session.offline.log_samples`), so a log gives the
    bins its replay writes."""
    channels = channels if channels is not None else ChannelMap.from_config(cfg)
    listener = DecodingListener(cfg.db, channels, capacity=cfg.sampling.buffer,
                                command=cfg.responses.command,
                                max_gap=cfg.sampling.max_gap, dt=cfg.sampling.dt)
    binner = Binner(channels.gyros, cfg.sampling.dt, cfg.sampling.epoch,
                    cfg.sampling.max_gap)
    return Ingest(listener, binner)


class Pipeline:
    """Bins → online identification → files and response frames, for one run.

    Args:
        cfg: the session.
        run_dir: the run folder (see :mod:`gyrostand.runfolder`).
        sink: where response frames go.
        source: ``"live"`` or ``"replay of <log>"`` (written into result.json).
        start_idle: begin ``idle`` (binning, no identification) until a ``start`` command.
        wall: the wall clock (s), used only by :meth:`wall_tick` and for timing figures.
        before_flush: called before every acknowledgement writes rows (the raw log's
            commit).
        resume: continue this run folder's kept bins (:mod:`~gyrostand.session.resume`).
        sync: fdatasync the files at each acknowledgement.
        segments: live runs: per raw segment counts, kept over resumes.
    """

    def __init__(self, cfg: SessionConfig, run_dir: Path, sink: FrameSink, *,
                 source: str = "live", start_idle: bool = False,
                 wall: Callable[[], float] = time.time,
                 before_flush: Callable[[], None] | None = None,
                 resume: ResumeState | None = None, sync: bool = False,
                 segments: SegmentLog | None = None) -> None:
        self.cfg, self.run_dir, self.sink, self.source, self.wall = cfg, run_dir, sink, \
            source, wall
        self.resume_state = resume
        self.segments = segments
        self.channels = ChannelMap.from_config(cfg)
        self.ingest = session_ingest(cfg, self.channels)
        self.listener, self.binner = self.ingest.listener, self.ingest.binner
        self.trackers = {g.name: GyroTracker(g, cfg.sampling.dt) for g in cfg.gyros}
        self.files = AckedFiles(run_dir, self.trackers, before_flush=before_flush,
                                append=resume is not None, sync=sync)
        self.responses = Responses(cfg, sink, self.listener, self.binner, self.trackers,
                                   wall)
        self.encoder = self.responses.encoder
        self.protocol = CommandProtocol(
            cfg.responses.node, cfg.responses.command_rate, start_idle=start_idle,
            actions={"reset": self._reset, "snapshot": self.snapshot},
            command_name=self._command_name)
        self.outages = 0
        # (frame time, order, reset None | identifying) of commands not yet applied to bins
        self._events: list[tuple[float, int, bool | None]] = []
        self._seq = 0
        self._identifying = self.protocol.identifying  # of the bins being written
        self.resumed: dict[str, int] = {}
        self.step_ms: deque[float] = deque(maxlen=86_400)  # worker ms per step with bins

    # -- the run's start and the files' end -----------------------------------------------
    def open(self) -> Pipeline:
        """Create the run files, write the provisional ``result.json``, resume the kept
        bins (when ``resume``); the wall clock's reference is taken last. Returns self."""
        self.files.open()
        write_provisional_result(self.run_dir / RESULT, self.cfg, self.source,
                                 self.run_dir)
        st = self.resume_state
        if st is not None:
            if st.t0 is not None:
                self.binner.resume_after(st.t0, st.last_k(self.cfg.sampling.dt))
                last = [c["t"][-1] for c in st.columns.values() if c["t"]]
                if last:  # frames are timed as after the kept bins: a clock that went
                    self.listener.resume_after(max(last))  # back re-anchors, as live
            self.resumed = self.files.resume(st)
            log.info("resumed with %s kept bins per gyro", self.resumed)
        self.responses.start()
        return self

    def close(self) -> None:
        """Close the files if :meth:`finish` did not (a run that failed): what can be
        written is; a write error is logged, not raised."""
        def attempt(close: Callable[[], None]) -> None:
            try:
                close()
            except OutputError as exc:
                log.error("%s", exc)
        self.files.close(attempt)

    def __enter__(self) -> Pipeline:
        return self.open()

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    # -- the parts' state, by the names drivers and tests use -------------------------------
    @property
    def samples(self) -> SamplesWriter:
        return self.files.samples

    @property
    def estimates(self) -> dict[str, EstimatesWriter]:
        return self.files.estimates

    @property
    def state(self) -> str:
        """``idle``, ``running``, ``stopping``, ``stopped`` or ``fault``."""
        return self.protocol.state

    @property
    def stop_requested(self) -> str | None:
        """Why the run should stop (a ``stop`` command), or None."""
        return self.protocol.stop_requested

    @property
    def commands(self) -> dict[str, int]:
        """The command counts (``stats()["commands"]``)."""
        return self.protocol.counts

    # -- per step ----------------------------------------------------------------------
    def flush_files(self) -> None:
        """Acknowledge (:meth:`AckedFiles.flush`), then record the counts in
        ``segments.json``. Raises :class:`~gyrostand.errors.OutputError`."""
        self.files.flush()
        if self.segments is not None:
            self.segments.update(self.counts())

    def step(self, bins: Sequence[Bin]) -> None:
        """Handle commands, process closed bins, send due frames (see module doc).

        Commands come first, and what they change for the bins takes effect at the bin
        that contains their frame time t, whichever step that bin closes in: a ``reset``
        restarts the online identifiers, a ``start`` begins identifying, before that bin.
        So a replay of the raw log applies them at the same bins as the live run did
        (live, bins close in small batches; a replay closes many at once)."""
        self._commands()
        if bins:
            t_start = time.perf_counter()
            dt = self.cfg.sampling.dt
            part: list[Bin] = []
            ev = self._events
            for b in bins:
                if ev and ev[0][0] < b.t + dt:
                    if part:
                        self.files.write(part, self._identifying)
                        part = []
                    while ev and ev[0][0] < b.t + dt:
                        _, _, what = ev.pop(0)
                        if what is None:  # reset
                            for tr in self.trackers.values():
                                tr.reset()
                        else:
                            self._identifying = what
                part.append(b)
            if part:
                self.files.write(part, self._identifying)
            self.responses.bins_closed(max(b.t for b in bins) + dt)
            self.step_ms.append((time.perf_counter() - t_start) * 1e3)
        t = self.responses.beat_due()
        if t is not None:
            self.heartbeat(t)

    def wall_tick(self) -> None:
        """Live only: keep the heartbeat going while the bus is silent
        (:meth:`Responses.wall_tick <gyrostand.session.responses.Responses.wall_tick>`);
        flush the files."""
        self.responses.wall_tick(self.state, self.outages)
        self.flush_files()

    def frame_time(self) -> float:
        return self.responses.frame_time()

    def heartbeat(self, timestamp: float) -> None:
        self.responses.heartbeat(timestamp, self.state, self.outages)

    def send_results(self, extra: dict[str, list[OnlineEstimate]] | None = None) -> None:
        self.responses.send_results(extra)

    # -- commands ----------------------------------------------------------------------
    def _commands(self) -> None:
        for t, values in self.listener.pop_commands():
            try:
                before = self.protocol.identifying
                ack = self.protocol.handle(t, values)
                if self.protocol.identifying != before:
                    self._event(t, self.protocol.identifying)
                if ack is not None:
                    self.responses.ack(ack)
            except GyrostandError as exc:  # a failing snapshot must not end the run
                log.error("command %s failed: %s", values, exc)

    def _command_name(self, code: int) -> str | None:
        """The command a decoded ``Command`` code means, in the numbering of the DBC's
        command message (its value table); the project's numbering without one."""
        ref = self.cfg.responses.command
        if ref is None:
            return COMMANDS.get(code)
        return self.encoder.command_name(ref, code)

    def _reset(self, t: float) -> None:
        """``reset`` at frame time ``t``: the online identifiers restart before the bin
        that contains ``t`` (:meth:`step`)."""
        self._event(t, None)

    def _event(self, t: float, what: bool | None) -> None:
        """What a command changes for the bins, at frame time ``t``: a reset (None) or
        whether bins are identified from then on; applied by :meth:`step`."""
        self._seq += 1
        bisect.insort(self._events, (t, self._seq, what))

    def snapshot(self, t: float) -> Path:
        """Flush the files and write ``snapshot.json`` (current online estimates), then
        send a result round."""
        self.flush_files()
        path = self.files.write_snapshot(t)
        self.send_results()
        log.info("snapshot written to %s", path)
        return path

    # -- counts and the end of run -----------------------------------------------------
    def counts(self) -> dict[str, Any]:
        """The decoder's, the binner's and the samples writer's counts (cheap: what every
        acknowledgement records in ``segments.json``)."""
        d = self.listener.stats()
        dec = asdict(d)
        dec["rejected_total"] = d.rejected_total
        return {"decoder": dec, "binner": asdict(self.binner.stats()),
                "samples": {"rows_written": self.samples.rows,
                            "resumed_bins": dict(self.resumed)}}

    def stats(self) -> dict[str, Any]:
        """:meth:`counts`, and the ids not in the DBC seen most often
        (``decoder.unknown_ids``: ``{"0x123": frames}``, 3 hex digits for a standard id, 8
        for an extended one), the responses, commands and timing."""
        counts = self.counts()
        counts["decoder"]["unknown_ids"] = {
            f"0x{i:08X}" if ext else f"0x{i:03X}": n
            for i, ext, n in self.listener.unknown_ids()}
        return {
            **counts,
            "responses": self.responses.stats(),
            "commands": dict(self.commands),
            "timing": {"bin_steps": len(self.step_ms),
                       "step_ms_median": _quantile(self.step_ms, 0.5),
                       "step_ms_p99": _quantile(self.step_ms, 0.99)},
        }

    def finish(self, reason: str, *, extra_stats: dict[str, Any] | None = None,
               truths: dict[str, dict[str, float]] | None = None,
               state: str = "stopped") -> RunOutcome:
        """Close the files, run the final fits, write result.json and report.txt, send a
        last result round (with the final ML) and a last heartbeat
        (:func:`~gyrostand.session.runend.finish_run`). Call after the driver has
        delivered the last bins (its flush)."""
        return finish_run(self, reason, extra_stats=extra_stats, truths=truths, state=state)
