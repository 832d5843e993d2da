"""Response scheduling: which of the daemon's frames go out when, and where they go.

* **Result rounds**: when frame time crosses a multiple of ``responses.period`` (s) at a
  bin close (:meth:`Responses.bins_closed`), per gyro and online identifier the
  ``GS_RESULT`` value/std frames of every model parameter and a ``GS_SUMMARY`` frame.
* **Heartbeat**: the 3-page ``GS_STATUS`` every ``responses.heartbeat`` s of frame time
  (:meth:`Responses.beat_due`); live, :meth:`Responses.wall_tick` keeps it going while
  the bus is silent (the only reader of the wall clock, besides timing figures).
* **Acknowledgements** of commands (:meth:`Responses.ack`).

Sent frames carry the frame time as timestamp (a ``virtual`` bus with
``preserve_timestamps`` keeps it). Frames go to a :class:`FrameSink`: :class:`BusSink`
live, :class:`NullSink` in replay (built by the same code, counted, not sent).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import can

from ..can.binning import Binner
from ..can.bus import FrameEncoder
from ..can.receive.counts import DecodeStats
from ..can.receive.listener import DecodingListener
from ..config import SessionConfig
from .commands import Ack
from .online import GyroTracker, OnlineEstimate

__all__ = ["Responses", "FrameSink", "NullSink", "BusSink"]

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


class Responses:
    """The schedule and the encoding of one run's response frames (see the module doc).

    Reads the listener's frame time and counters, the binner's counters and the trackers'
    estimates; :meth:`start` takes the wall clock's reference when the run begins.
    """

    def __init__(self, cfg: SessionConfig, sink: FrameSink, listener: DecodingListener,
                 binner: Binner, trackers: Mapping[str, GyroTracker],
                 wall: Callable[[], float]) -> None:
        self.cfg, self.sink, self.listener, self.binner = cfg, sink, listener, binner
        self.trackers, self.wall = trackers, wall
        self.encoder = FrameEncoder(cfg.db)
        self.period, self.beat = cfg.responses.period, cfg.responses.heartbeat
        self.rounds = 0  # result rounds sent
        self.beats = 0  # heartbeats sent
        self._next_result = -math.inf
        self._next_beat = -math.inf
        self._beat_frame_t = -math.inf  # frame time at the last beat
        self._last_beat_ts = -math.inf  # timestamp of the last beat
        self._last_beat_wall = math.nan  # wall time of the last beat (start(): the start)
        self._tick_t, self._tick_wall = -math.inf, math.nan
        self._logged_bad: tuple[int, ...] = (0, 0, 0, 0)
        self._logged_t = -math.inf

    def start(self) -> None:
        """The run begins: the wall clock's reference for :meth:`wall_tick`."""
        self._last_beat_wall = self.wall()
        self._tick_wall = self._last_beat_wall

    def frame_time(self) -> float:
        """The newest accepted frame's timestamp (s), 0 before the first."""
        t = self.listener.last_timestamp
        return t if math.isfinite(t) else 0.0

    @property
    def last_beat(self) -> float:
        """Timestamp of the last heartbeat while frame time runs (-inf before)."""
        return self._last_beat_ts

    # -- schedule ------------------------------------------------------------------------
    def bins_closed(self, end: float) -> None:
        """Bins closed up to frame time ``end`` (s): a result round when ``end`` crossed a
        multiple of the period."""
        if end >= self._next_result:
            self._next_result = (math.floor(end / self.period) + 1) * self.period
            self.send_results()

    def beat_due(self) -> float | None:
        """The heartbeat's timestamp when one is due by frame time, else None."""
        t = self.listener.last_timestamp
        return t if t >= self._next_beat and math.isfinite(t) else None

    def wall_tick(self, state: str, outages: int) -> None:
        """Live only: keep the heartbeat going while no new frame has arrived since the
        last beat, or frame time has not moved for a heartbeat period of wall time (the
        frames stopped between two beats). Such a beat is stamped with the last beat's
        timestamp plus the wall time elapsed since (at least the newest frame time, so beat
        timestamps keep increasing in frame time), or with the wall clock before the first
        frame."""
        now = self.wall()
        t = self.listener.last_timestamp
        if t != self._tick_t:  # frame time moved since the last tick
            self._tick_t, self._tick_wall = t, now
        elapsed = now - self._last_beat_wall
        silent = now - self._tick_wall >= self.beat  # frames stopped (maybe mid-period)
        if elapsed >= self.beat and (t <= self._beat_frame_t or silent):
            framed = math.isfinite(t)
            self.heartbeat(max(self._last_beat_ts + elapsed, t) if framed else now, state,
                           outages)

    # -- frames --------------------------------------------------------------------------
    def heartbeat(self, timestamp: float, state: str, outages: int) -> None:
        """The 3-page ``GS_STATUS`` (when configured); logs new rejections."""
        ref = self.cfg.responses.status
        self.beats += 1
        self._last_beat_wall = self.wall()
        self._beat_frame_t = self.listener.last_timestamp
        if math.isfinite(self._beat_frame_t):  # frame time runs: beats a period apart
            self._last_beat_ts = timestamp
            self._next_beat = timestamp + self.beat
        d, b = self.listener.stats(), self.binner.stats()
        self.log_rejections(d, b, timestamp)
        if ref is None:
            return
        self.sink.send(self.encoder.status_frames(
            ref, state, self.beats - 1, bins=b.bins, gaps=b.gaps, decoded=d.decoded,
            rejected=d.rejected_total, bus_errors=d.bus_errors, late=b.late,
            outages=outages, timestamp=timestamp))

    def log_rejections(self, d: DecodeStats, b: Any, t: float, force: bool = False) -> None:
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

    def send_results(self, extra: Mapping[str, list[OnlineEstimate]] | None = None) -> None:
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
                                                     stds, self.rounds, timestamp=ts)
                if g.result.summary is not None:
                    frames.append(self.encoder.summary_frame(
                        g.result.summary, e.identifier, e.status, tr.model.names, e.samples,
                        e.residual_rms, timestamp=ts))
        self.rounds += 1
        if frames:
            self.sink.send(frames)

    def ack(self, ack: Ack) -> None:
        """Send an acknowledgement (when ``responses.ack`` is configured)."""
        ref = self.cfg.responses.ack
        if ref is not None:
            self.sink.send([self.encoder.ack_frame(ref, ack.command, ack.sequence, ack.ok,
                                                   ack.reason, self.cfg.responses.node,
                                                   timestamp=self.frame_time())])

    def stats(self) -> dict[str, Any]:
        """The ``responses`` section of the run's stats."""
        return {"result_rounds": self.rounds, "heartbeats": self.beats,
                "frames_sent": getattr(self.sink, "sent", 0),
                "send_errors": getattr(self.sink, "errors", 0),
                "not_sent_offline": getattr(self.sink, "offline", 0)}
