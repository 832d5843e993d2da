"""The daemon's core, shared by live runs and replay: it does not know where frames come from.

A driver (:mod:`~gyrostand.session.live` with a :class:`can.Notifier`, or
:mod:`~gyrostand.session.offline` with a log file) feeds frames to :attr:`Pipeline.listener`
and calls :meth:`Pipeline.step` with the bins that closed. Per step, in this order:

1. every closed bin goes to ``<gyro>/samples.csv``, updates the gyro's online identifiers
   (unless the run is ``idle``) and appends a row to ``<gyro>/estimates.csv``;
2. when frame time crosses a multiple of ``responses.period`` (s) at a bin close, a result
   round is sent: per gyro and online identifier, the ``GS_RESULT`` value/std frames of
   every model parameter and a ``GS_SUMMARY`` frame;
3. commands received since the last step are handled and acknowledged;
4. when ``responses.heartbeat`` s of frame time have passed since the last beat, the
   3-page ``GS_STATUS`` heartbeat is sent.

All timing is frame time (the newest accepted frame's timestamp, s). Only
:meth:`Pipeline.wall_tick` reads the wall clock: live drivers call it so the heartbeat
continues (with wall-clock timestamps) while the bus is silent. Sent frames carry the frame
time as timestamp (a ``virtual`` bus with ``preserve_timestamps`` keeps it).

Commands (``GS_COMMAND``, only from the configured message; ``Target`` must be this node or
255, other targets are ignored): ``start`` (idle → running, else nack ``wrong_state``),
``stop`` (ends the run: the driver stops reading), ``reset`` (online identifiers restart
at the next bin; bins and files are kept), ``snapshot`` (flush files, write
``snapshot.json`` with the current online estimates and send a result round now). Unknown
codes are nacked ``unknown_command``; frames of the command id with a wrong length, that
cannot be decoded, or without Command/Sequence are nacked ``malformed`` (echoing what
can be read). At most ``responses.command_rate`` commands per second of frame time are
handled (a token bucket holding ``max(1, rate)``); the excess is nacked ``rate_limited``,
and those nacks are themselves limited to the same rate (beyond it they are only counted,
``nacks_suppressed``), so a flood of commands cannot make the daemon flood the bus. Every
outcome is counted in ``stats()["commands"]``.
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Protocol

import can

from ..can.binning import Bin, Binner, SamplesWriter, read_samples_csv
from ..can.bus import FrameEncoder
from ..can.decode import MALFORMED, REASONS, ChannelMap, DecodingListener
from ..can.ingest import Ingest
from ..config import SessionConfig
from ..errors import GyrostandError, OutputError
from .final import (
    GyroFinal,
    fit_gyro,
    write_provisional_result,
    write_report,
    write_result_json,
)
from .online import GyroTracker, OnlineEstimate
from .outputs import EstimatesWriter, SegmentLog, write_atomic
from .resume import ResumeState

__all__ = ["Pipeline", "FrameSink", "NullSink", "BusSink", "RunOutcome"]

log = logging.getLogger(__name__)


class FrameSink(Protocol):
    """Where the daemon's frames go."""

    def send(self, frames: Sequence[can.Message]) -> None: ...


@dataclass
class NullSink:
    """Replay: frames are built (same code path) and counted, not sent."""

    sent: int = 0
    errors: int = 0
    offline: int = 0

    def send(self, frames: Sequence[can.Message]) -> None:
        self.sent += len(frames)


@dataclass
class BusSink:
    """Send on a bus; a failed send is counted and logged, never raised (a full transmit
    queue must not stop the daemon)."""

    bus: can.BusABC | None
    timeout: float = 0.05
    sent: int = 0
    errors: int = 0
    offline: int = 0  # frames not sent because the bus was gone (an outage)
    log_every: int = 100

    def send(self, frames: Sequence[can.Message]) -> None:
        if self.bus is None:
            self.offline += len(frames)
            return
        for f in frames:
            try:
                self.bus.send(f, timeout=self.timeout)
                self.sent += 1
            except Exception as exc:  # CanError, BrokenPipeError of a remote bus, ...
                self.errors += 1
                if self.errors % self.log_every == 1:
                    log.warning("cannot send frame 0x%X (%d send errors so far): %s",
                                f.arbitration_id, self.errors, exc)


@dataclass
class RunOutcome:
    """What a finished run produced: paths, final fits, why it stopped, the state."""

    run_dir: Path
    result_json: Path
    report: Path
    finals: list[GyroFinal]
    stop_reason: str
    state: str
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.state != "fault"


class TokenBucket:
    """At most ``rate`` events per second of frame time, bursts up to ``max(1, rate)``."""

    def __init__(self, rate: float) -> None:
        self.rate = float(rate)
        self.capacity = max(1.0, self.rate)
        self.tokens = self.capacity
        self.t = -math.inf

    def take(self, t: float) -> bool:
        """A timestamp earlier than the last one (a command frame of a clock that stepped
        back, or after a stray future one) refills nothing and becomes the reference, so
        one wild timestamp cannot block later commands."""
        if math.isfinite(t):
            if self.t > -math.inf and t > self.t:
                self.tokens = min(self.capacity, self.tokens + (t - self.t) * self.rate)
            self.t = t
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        return False


def _quantile(xs: Iterable[float], q: float) -> float:
    s = sorted(xs)
    if not s:
        return math.nan
    return s[min(len(s) - 1, int(q * len(s)))]


class Pipeline:
    """Bins → online identification → files and response frames, for one run.

    Args:
        cfg: the session.
        run_dir: the run folder (see :mod:`~gyrostand.session.outputs`).
        sink: where response frames go.
        source: ``"live"`` or ``"replay of <log>"`` (written into result.json).
        start_idle: begin ``idle`` (binning, no identification) until a ``start`` command.
        wall: the wall clock (s), used only by :meth:`wall_tick` and for timing figures.
    """

    def __init__(self, cfg: SessionConfig, run_dir: Path, sink: FrameSink, *,
                 source: str = "live", start_idle: bool = False,
                 wall: Callable[[], float] = time.time,
                 before_flush: Callable[[], None] | None = None,
                 resume: ResumeState | None = None, sync: bool = False,
                 segments: SegmentLog | None = None) -> None:
        self.cfg, self.run_dir, self.sink, self.source, self.wall = cfg, run_dir, sink, \
            source, wall
        self.channels = ChannelMap.from_config(cfg)
        self.listener = DecodingListener(cfg.db, self.channels, capacity=cfg.sampling.buffer,
                                         command=cfg.responses.command,
                                         max_gap=cfg.sampling.max_gap, dt=cfg.sampling.dt)
        self.binner = Binner(self.channels.gyros, cfg.sampling.dt, cfg.sampling.epoch,
                             cfg.sampling.max_gap)
        self.ingest = Ingest(self.listener, self.binner)
        self.encoder = FrameEncoder(cfg.db)
        self.trackers = {g.name: GyroTracker(g, cfg.sampling.dt) for g in cfg.gyros}
        self.samples = SamplesWriter(run_dir, self.channels.gyros, before_flush=before_flush,
                                     append=resume is not None, sync=sync)
        self.estimates = {
            g.name: EstimatesWriter(run_dir / g.name / "estimates.csv",
                                    self.trackers[g.name].identifiers,
                                    self.trackers[g.name].model.param_names,
                                    append=resume is not None, sync=sync)
            for g in cfg.gyros}
        self.outages = 0
        self.segments: SegmentLog | None = None  # set once the counters exist (below)
        self.resumed: dict[str, Any] = {}
        write_provisional_result(run_dir / "result.json", cfg, source, run_dir)
        if resume is not None:
            self._resume(resume)
        self.state = "idle" if start_idle else "running"
        self.stop_requested: str | None = None
        r = cfg.responses
        self._next_result = -math.inf
        self._next_beat = -math.inf
        self._beat_frame_t = -math.inf
        self._last_beat_ts = -math.inf
        self._last_beat_wall = wall()
        self._tick_t, self._tick_wall = -math.inf, self._last_beat_wall
        self._beats = 0
        self._rounds = 0
        self.commands: dict[str, int] = {
            "received": 0, "acked": 0, "nacked": 0, "ignored": 0, "malformed": 0,
            "unknown": 0, "rate_limited": 0, "nacks_suppressed": 0}
        self._cmd_bucket = TokenBucket(r.command_rate)
        self._nack_bucket = TokenBucket(r.command_rate)
        self.step_ms: deque[float] = deque(maxlen=86_400)  # worker ms per step with bins
        self._logged_bad: tuple[int, ...] = (0, 0, 0, 0)
        self._logged_t = -math.inf
        self._period, self._beat = r.period, r.heartbeat
        self.segments = segments  # live runs: per raw segment counts, kept over resumes

    def _resume(self, st: ResumeState) -> None:
        """Continue the kept bins: grid, online identifiers fed again, missing estimate
        rows written (see :mod:`~gyrostand.session.resume`)."""
        if st.t0 is not None:
            self.binner.resume_after(st.t0, st.last_k(self.cfg.sampling.dt))
        for name, cols in st.columns.items():
            tr, until = self.trackers[name], st.estimates_until.get(name, -math.inf)
            for t, d, tm in zip(cols["t"], cols["drift"], cols["temp"], strict=True):
                tr.update(d, tm)
                if t > until:
                    self.estimates[name].write(t, tr.estimates())
            self.resumed[name] = len(cols["t"])
        self.flush_files()
        log.info("resumed with %s kept bins per gyro", self.resumed)

    def flush_files(self) -> None:
        """Acknowledge: the raw log (``before_flush``), then the pending bins, then the
        estimates, to disk. Raises :class:`~gyrostand.errors.OutputError`."""
        self.samples.flush()
        for w in self.estimates.values():
            w.flush()
        if self.segments is not None:
            self.segments.update(self.counts())

    # -- per step ----------------------------------------------------------------------
    def step(self, bins: Sequence[Bin]) -> None:
        """Process closed bins, send due frames, handle commands (see module doc)."""
        if bins:
            t_start = time.perf_counter()
            self._bins(bins)
            end = max(b.t for b in bins) + self.cfg.sampling.dt
            if end >= self._next_result:
                self._next_result = (math.floor(end / self._period) + 1) * self._period
                self.send_results()
            self.step_ms.append((time.perf_counter() - t_start) * 1e3)
        self._commands()
        t = self.listener.last_timestamp
        if t >= self._next_beat and math.isfinite(t):
            self.heartbeat(t)

    def _bins(self, bins: Sequence[Bin]) -> None:
        self.samples.write(bins)
        running = self.state in ("running", "stopping")
        for b in bins:
            tr = self.trackers[b.gyro]
            if running:
                tr.update(b.drift, b.temp)
            self.estimates[b.gyro].write(b.t, tr.estimates())

    def wall_tick(self) -> None:
        """Live only: keep the heartbeat going while no new frame has arrived since the
        last beat, or frame time has not moved for a heartbeat period of wall time (the
        frames stopped between two beats); flush the files. Such a beat is stamped with
        the last beat's timestamp plus the wall time elapsed since (at least the newest
        frame time, so beat timestamps keep increasing in frame time), or with the wall
        clock before the first frame."""
        now = self.wall()
        t = self.listener.last_timestamp
        if t != self._tick_t:  # frame time moved since the last tick
            self._tick_t, self._tick_wall = t, now
        elapsed = now - self._last_beat_wall
        silent = now - self._tick_wall >= self._beat  # frames stopped (maybe mid-period)
        if elapsed >= self._beat and (t <= self._beat_frame_t or silent):
            framed = math.isfinite(t)
            self.heartbeat(max(self._last_beat_ts + elapsed, t) if framed else now)
        self.flush_files()

    # -- frames out --------------------------------------------------------------------
    def frame_time(self) -> float:
        t = self.listener.last_timestamp
        return t if math.isfinite(t) else 0.0

    def heartbeat(self, timestamp: float) -> None:
        ref = self.cfg.responses.status
        self._beats += 1
        self._last_beat_wall = self.wall()
        self._beat_frame_t = self.listener.last_timestamp
        if math.isfinite(self._beat_frame_t):  # frame time runs: beats a period apart
            self._last_beat_ts = timestamp
            self._next_beat = timestamp + self._beat
        d, b = self.listener.stats(), self.binner.stats()
        self._log_rejections(d, b, timestamp)
        if ref is None:
            return
        self.sink.send(self.encoder.status_frames(
            ref, self.state, self._beats - 1, bins=b.bins, gaps=b.gaps, decoded=d.decoded,
            rejected=d.rejected_total, bus_errors=d.bus_errors, late=b.late,
            outages=self.outages, timestamp=timestamp))

    def _log_rejections(self, d: Any, b: Any, t: float, force: bool = False) -> None:
        """Log what was rejected/lost since the last such line (at most every 10 s of
        frame time, or when ``force``)."""
        bad = (d.rejected_total, d.bus_errors, b.late, d.listener_errors)
        if bad == self._logged_bad or not (force or t - self._logged_t >= 10.0):
            return
        self._logged_bad, self._logged_t = bad, t
        rej = ", ".join(f"{k} {v}" for k, v in d.rejected.items() if v) or "none"
        log.warning("rejected frames %d (%s); bus errors %d, counter jumps %d, late samples "
                    "%d, listener errors %d", d.rejected_total, rej, d.bus_errors,
                    d.counter_jumps, b.late, d.listener_errors)

    def send_results(self, extra: dict[str, list[OnlineEstimate]] | None = None) -> None:
        """One result round: every gyro's online estimates (plus ``extra`` per gyro, e.g.
        the final ML) as GS_RESULT value/std frames and a GS_SUMMARY per identifier."""
        ts = self.frame_time()
        frames: list[can.Message] = []
        for g in self.cfg.gyros:
            if g.result is None:
                continue
            tr = self.trackers[g.name]
            ests = list(tr.estimates()) + list((extra or {}).get(g.name, ()))
            names = tr.model.param_names
            for e in ests:
                vals = [e.values[n][0] for n in names]
                stds = [e.values[n][1] for n in names]
                frames += self.encoder.result_frames(g.result.values, e.identifier, vals,
                                                     stds, self._rounds, timestamp=ts)
                if g.result.summary is not None:
                    frames.append(self.encoder.summary_frame(
                        g.result.summary, e.identifier, e.status, tr.model.names, e.samples,
                        e.residual_rms, timestamp=ts))
        self._rounds += 1
        if frames:
            self.sink.send(frames)

    # -- commands ----------------------------------------------------------------------
    def _commands(self) -> None:
        for t, values in self.listener.pop_commands():
            self.commands["received"] += 1
            try:
                self._command(t, values)
            except GyrostandError as exc:  # a failing snapshot must not end the run
                log.error("command %s failed: %s", values, exc)

    def _ack(self, code: int, seq: int, ok: bool, reason: str = "ok") -> None:
        self.commands["acked" if ok else "nacked"] += 1
        ref = self.cfg.responses.ack
        if ref is not None:
            self.sink.send([self.encoder.ack_frame(ref, code, seq, ok, reason,
                                                   self.cfg.responses.node,
                                                   timestamp=self.frame_time())])

    def _command(self, t: float, values: dict[str, float]) -> None:
        target = values.get("Target")
        if target is not None and int(target) not in (255, self.cfg.responses.node):
            self.commands["ignored"] += 1
            log.info("command for node %d ignored (this is node %d)", int(target),
                     self.cfg.responses.node)
            return
        code, seq = values.get("Command"), values.get("Sequence")
        c, q = int(code or 0), int(seq or 0)
        if not self._cmd_bucket.take(t):
            self.commands["rate_limited"] += 1
            if self.commands["rate_limited"] % 100 == 1:
                log.warning("commands over responses.command_rate = %g/s: %d refused so far",
                            self.cfg.responses.command_rate, self.commands["rate_limited"])
            if self._nack_bucket.take(t):
                self._ack(c, q, False, "rate_limited")
            else:
                self.commands["nacks_suppressed"] += 1
            return
        if MALFORMED in values or code is None or seq is None:
            self.commands["malformed"] += 1
            why = REASONS[int(values[MALFORMED])] if MALFORMED in values else \
                "no Command/Sequence"
            log.warning("malformed command at t=%.3f (%s): %s", t, why,
                        {k: v for k, v in values.items() if k != MALFORMED})
            self._ack(c, q, False, "malformed")
            return
        code, seq = c, q
        name = self.encoder.command_name(self.cfg.responses.command, code)
        log.info("command %s (seq %d) at t=%.3f", name or code, seq, t)
        if name is None:
            self.commands["unknown"] += 1
            self._ack(code, seq, False, "unknown_command")
        elif name == "start":
            if self.state != "idle":
                self._ack(code, seq, False, "wrong_state")
                return
            self.state = "running"
            self._ack(code, seq, True)
        elif name == "stop":
            if self.stop_requested is not None:
                self._ack(code, seq, False, "wrong_state")
                return
            self.stop_requested = "stop command"
            self.state = "stopping"
            self._ack(code, seq, True)
        elif name == "reset":
            for tr in self.trackers.values():
                tr.reset()
            self._ack(code, seq, True)
        else:  # snapshot
            self.snapshot(t)
            self._ack(code, seq, True)

    def snapshot(self, t: float) -> Path:
        """Flush the files and write ``snapshot.json`` (current online estimates)."""
        self.flush_files()
        doc = {"t": t, "gyros": {
            name: {e.identifier: {"status": e.status, "samples": e.samples, "note": e.note,
                                  "parameters": {k: {"value": _j(v), "std": _j(s)}
                                                 for k, (v, s) in e.values.items()}}
                   for e in tr.estimates()} for name, tr in self.trackers.items()}}
        path = self.run_dir / "snapshot.json"
        write_atomic(path, json.dumps(doc, indent=2, allow_nan=False) + "\n")
        self.send_results()
        log.info("snapshot written to %s", path)
        return path

    # -- end of run --------------------------------------------------------------------
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
        return {
            **self.counts(),
            "responses": {"result_rounds": self._rounds, "heartbeats": self._beats,
                          "frames_sent": getattr(self.sink, "sent", 0),
                          "send_errors": getattr(self.sink, "errors", 0),
                          "not_sent_offline": getattr(self.sink, "offline", 0)},
            "commands": dict(self.commands),
            "timing": {"bin_steps": len(self.step_ms),
                       "step_ms_median": _quantile(self.step_ms, 0.5),
                       "step_ms_p99": _quantile(self.step_ms, 0.99)},
        }

    def finish(self, reason: str, *, extra_stats: dict[str, Any] | None = None,
               truths: dict[str, dict[str, float]] | None = None,
               state: str = "stopped") -> RunOutcome:
        """Close the files, run the final fits, write result.json and report.txt, send a
        last result round (with the final ML) and a last heartbeat. Call after the driver
        has delivered the last bins (its flush)."""
        self.state = "stopping" if state != "fault" else state
        unwritten: list[str] = []

        def attempt(write: Callable[[], None]) -> None:
            try:
                write()
            except OutputError as exc:  # e.g. the disk is full: say so, finish the rest
                unwritten.append(str(exc))
                log.error("%s", exc)

        attempt(self.samples.close)
        for w in self.estimates.values():
            attempt(w.close)
        finals: list[GyroFinal] = []
        extra: dict[str, list[OnlineEstimate]] = {}
        for g in self.cfg.gyros:
            cols = read_samples_csv(self.samples.paths[g.name])
            tr = self.trackers[g.name]
            tr.finish()  # the online LKF's last re-linearisation: `lkf` at stop
            f = fit_gyro(g, cols, self.cfg.sampling.dt,
                         f"{self.run_dir.name}/{g.name}/samples.csv", None, tr.estimates(),
                         tr.lkf_fit if "lkf" in tr.identifiers else None)
            finals.append(f)
            ml = f.fits.get("ml")
            if ml is not None and not isinstance(ml, str):
                vals = {n: (e.value, e.std) for n, e in ml.parameters.items()}
                extra[g.name] = [OnlineEstimate("ml", "warning" if ml.warnings else "ok",
                                                vals, ml.n_observed, ml.residual_rms)]
        self.send_results(extra)
        if unwritten and state != "fault":
            state, reason = "fault", f"{reason}; {unwritten[0]}"
        self.state = state
        self.heartbeat(max(self.frame_time(), self._last_beat_ts))
        self._log_rejections(self.listener.stats(), self.binner.stats(), self.frame_time(),
                             force=True)
        stats = self.stats()
        stats.update(extra_stats or {})
        stats["stop_reason"] = reason
        if self.segments is not None:  # this segment's counts, then the whole run's
            segs = self.segments
            attempt(lambda: segs.update(stats, ended_by=reason, extra={
                k: stats[k] for k in ("recorder", "bus") if k in stats}))
            stats["segments"] = segs.segments()
            stats["run_totals"] = segs.totals()
        result = self.run_dir / "result.json"
        report = self.run_dir / "report.txt"
        stats["unwritten"] = unwritten
        attempt(lambda: write_result_json(result, self.cfg, self.source, self.run_dir,
                                          finals, stats))
        attempt(lambda: write_report(report, self.cfg, self.source, finals, stats,
                                     truths or {}))
        if unwritten and state != "fault":
            state, reason = "fault", f"{reason}; {unwritten[0]}"
            stats["stop_reason"] = reason
        log.info("run finished (%s): %s, %s", reason, result, report)
        return RunOutcome(self.run_dir, result, report, finals, reason, state, stats)


def _j(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None
