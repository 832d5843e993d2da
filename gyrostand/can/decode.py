"""The receive path: a :class:`can.Listener` that decodes frames with cantools and appends
decoded samples to one bounded FIFO, counting everything it rejects by reason.

Per frame the work is constant: one dict lookup by frame id (standard and extended ids are
different keys), a length check, one ``Message.decode(decode_choices=False)``, a range and
timestamp check per mapped signal, and an append. Estimation, binning and I/O happen in the
consumer (:meth:`DecodingListener.drain`), never in the Notifier's thread.

Samples are ``(gyro index, channel index, timestamp s, value)`` with channel 0 = drift
(deg/h in our DBC; whatever unit the DBC gives) and 1 = temperature (degC), kept in bus
order across gyros and channels so the binner sees exactly what live or replay delivered.
"""

from __future__ import annotations

import logging
import math
import threading
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import can
from cantools.database.can import Database

from gyrostand.can.dbc import MessageRef, SignalRef, frame_key

__all__ = ["DecodingListener", "DecodeStats", "ChannelMap", "REASONS", "DRIFT", "TEMP",
           "Sample", "Command", "MALFORMED"]

log = logging.getLogger(__name__)

DRIFT, TEMP = 0, 1

#: Rejection reasons, in the order of :attr:`DecodeStats.rejected`.
REASONS = (
    "unknown_id",        # id not in the DBC
    "wrong_dlc",         # payload length differs from the DBC's message length
    "undecodable",       # cantools could not decode (e.g. undefined multiplexer value)
    "out_of_range",      # a mapped value outside the DBC [min|max], or not finite
    "bad_timestamp",     # timestamp not finite
    "non_monotonic",     # timestamp earlier than the previous frame with this id
    "time_jump",         # timestamp more than max_gap after the previous frame
    "error_frame",
    "remote_frame",
    "overflow",          # the sample buffer (or command queue) was full
)
_R = {name: i for i, name in enumerate(REASONS)}
_isfinite = math.isfinite
_NEG_INF = -math.inf

Sample = tuple[int, int, float, float]
Command = tuple[float, dict[str, float]]
#: key of a queued command frame that could not be decoded (value: index in REASONS)
MALFORMED = "__malformed__"


@dataclass(frozen=True)
class ChannelMap:
    """What the listener extracts: ``signals[g][c]`` is the :class:`SignalRef` of channel c
    (0 drift, 1 temperature) of gyro g; ``counters[g][c]`` its rolling counter or None."""

    gyros: tuple[str, ...]
    signals: tuple[tuple[SignalRef, SignalRef], ...]
    counters: tuple[tuple[SignalRef | None, SignalRef | None], ...] = ()

    @classmethod
    def from_config(cls, cfg) -> ChannelMap:  # cfg: gyrostand.config.SessionConfig
        return cls(
            gyros=tuple(g.name for g in cfg.gyros),
            signals=tuple((g.drift.signal, g.temperature.signal) for g in cfg.gyros),
            counters=tuple((g.drift.counter, g.temperature.counter) for g in cfg.gyros),
        )


@dataclass(frozen=True)
class DecodeStats:
    """Snapshot of the listener's counters (cumulative since start or reset)."""

    received: int
    decoded: int
    ignored: int
    samples: int
    commands: int
    counter_jumps: int
    bus_errors: int
    listener_errors: int
    rejected: dict[str, int]

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())


class _Route:
    """Fast-path entry for one frame id."""

    __slots__ = ("message", "decode", "length", "extract", "is_command", "last_t")

    def __init__(self, message, length: int) -> None:
        self.message = message
        # decode(data, decode_choices) -> {signal: value}; cantools' decode without the
        # container dispatch of Message.decode (our routes are plain or multiplexed)
        self.decode = message.decode if message.is_container else message.decode_simple
        self.length = length
        # (gyro, channel, signal name, minimum, maximum, counter signal or None, modulus)
        self.extract: list[tuple[int, int, str, float, float, str | None, int]] = []
        self.is_command = False
        self.last_t = -math.inf


class DecodingListener(can.Listener):
    """Decode frames of the mapped DBC signals into a bounded sample FIFO.

    ``capacity`` bounds the FIFO (samples); when full, new samples are dropped and counted
    as ``overflow`` (the oldest are never overwritten). ``max_gap`` (s) bounds forward
    timestamp jumps per frame id. Frames of ``command`` go, decoded, to a bounded command
    queue read with :meth:`pop_commands`. ``on_message_received`` never raises.
    """

    def __init__(self, db: Database, channels: ChannelMap, *, capacity: int = 65536,
                 command: MessageRef | None = None, max_gap: float = 3600.0,
                 command_capacity: int = 64) -> None:
        self.channels = channels
        self.capacity = int(capacity)
        self.max_gap = float(max_gap)
        self._buf: deque[Sample] = deque()
        self._commands: deque[Command] = deque()
        self._command_capacity = command_capacity
        self._lock = threading.Lock()
        self._routes: dict[int, _Route] = {}
        self._known = {frame_key(m.frame_id, bool(m.is_extended_frame)) for m in db.messages}
        self._last_counter: dict[tuple[int, int], int] = {}
        self._last_t = -math.inf
        self._resynced = False
        for g, pair in enumerate(channels.signals):
            for c, ref in enumerate(pair):
                route = self._route(db, ref.message)
                lo = -math.inf if ref.minimum is None else ref.minimum
                hi = math.inf if ref.maximum is None else ref.maximum
                cnt = channels.counters[g][c] if channels.counters else None
                mod = 256
                if cnt is not None and cnt.maximum is not None:
                    mod = int(cnt.maximum) + 1
                route.extract.append((g, c, ref.name, lo, hi,
                                      cnt.name if cnt else None, mod))
        if command is not None:
            self._route(db, command).is_command = True
        self.reset_counters()

    def _route(self, db: Database, ref: MessageRef) -> _Route:
        if ref.key not in self._routes:
            msg = db.get_message_by_name(ref.name)
            self._routes[ref.key] = _Route(msg, msg.length)
        return self._routes[ref.key]

    def resync(self) -> None:
        """After a bus outage: forget each frame id's last timestamp, so the first frame
        after the outage is neither a ``time_jump`` nor ``non_monotonic`` (the binner
        decides what a jump means for the series). Counters are kept."""
        with self._lock:
            for r in self._routes.values():
                r.last_t = -math.inf
            self._resynced = True
            self._last_counter.clear()

    def reset_counters(self) -> None:
        """Zero every counter (the FIFO and timestamp history are kept)."""
        with self._lock:
            self._n = [0] * 7  # received decoded ignored samples commands counter_jumps bus
            self._listener_errors = 0
            self._rej = [0] * len(REASONS)

    # -- the Notifier's callback -------------------------------------------------------
    def on_message_received(self, msg: can.Message) -> None:
        try:
            with self._lock:
                self._receive(msg)
        except Exception as exc:  # never let the Notifier thread die
            with self._lock:
                self._listener_errors += 1
            log.exception("listener failed on %r: %s", msg, exc)

    def _reject(self, reason: str) -> None:
        self._rej[_R[reason]] += 1

    def _receive(self, msg: can.Message) -> None:
        n = self._n
        n[0] += 1
        if msg.is_error_frame:
            n[6] += 1
            self._reject("error_frame")
            return
        if msg.is_remote_frame:
            self._reject("remote_frame")
            return
        key = msg.arbitration_id | 0x20000000 if msg.is_extended_id else msg.arbitration_id
        route = self._routes.get(key)
        if route is None:
            if key in self._known:
                n[2] += 1
            else:
                self._reject("unknown_id")
            return
        data = msg.data
        if len(data) != route.length:
            self._reject("wrong_dlc")
            if route.is_command:
                self._malformed_command(route, msg, "wrong_dlc")
            return
        t = msg.timestamp
        if not _isfinite(t):
            self._reject("bad_timestamp")
            return
        if t < route.last_t:
            self._reject("non_monotonic")
            return
        if route.last_t > _NEG_INF:
            ref_t = route.last_t
        else:  # first frame of this id (since a resync: no reference at all)
            ref_t = _NEG_INF if self._resynced else self._last_t
        if ref_t > _NEG_INF and t - ref_t > self.max_gap:
            self._reject("time_jump")
            return
        try:
            values = route.decode(data, False)
        except Exception:
            self._reject("undecodable")
            if route.is_command:
                self._malformed_command(route, msg, "undecodable")
            return
        if route.is_command:
            if len(self._commands) >= self._command_capacity:
                self._reject("overflow")
                return
            self._commands.append((t, dict(values)))
            route.last_t = t
            self._last_t = max(self._last_t, t)
            n[1] += 1
            n[4] += 1
            return
        extract = route.extract
        if len(extract) == 1:  # the common case, one mapped signal: same steps, no lists
            g, c, name, lo, hi, cname, mod = extract[0]
            v = values.get(name)
            if v is None:  # multiplexed signal not selected by this frame
                n[2] += 1
                return
            v = float(v)
            if not lo <= v <= hi:  # also false for NaN
                self._reject("out_of_range")
                return
            if len(self._buf) >= self.capacity:
                self._reject("overflow")
                return
            route.last_t = t
            if t > self._last_t:
                self._last_t = t
            if cname is not None:
                cv = values.get(cname)
                if cv is not None:
                    prev = self._last_counter.get((g, c))
                    if prev is not None and (int(cv) - prev) % mod != 1 % mod:
                        n[5] += 1
                    self._last_counter[(g, c)] = int(cv)
            self._buf.append((g, c, t, v))
            n[1] += 1
            n[3] += 1
            return
        out: list[Sample] = []
        counted: list[tuple[int, int, str, int]] = []
        for g, c, name, lo, hi, cname, mod in route.extract:
            v = values.get(name)
            if v is None:  # multiplexed signal not selected by this frame
                continue
            v = float(v)
            if not lo <= v <= hi:  # also false for NaN
                self._reject("out_of_range")
                return
            out.append((g, c, t, v))
            if cname is not None:
                counted.append((g, c, cname, mod))
        if not out:
            n[2] += 1
            return
        if len(self._buf) + len(out) > self.capacity:
            self._reject("overflow")
            return
        route.last_t = t
        if t > self._last_t:
            self._last_t = t
        for g, c, cname, mod in counted:
            cv = values.get(cname)
            if cv is None:
                continue
            prev = self._last_counter.get((g, c))
            if prev is not None and (int(cv) - prev) % mod != 1 % mod:
                n[5] += 1
            self._last_counter[(g, c)] = int(cv)
        self._buf.extend(out)
        n[1] += 1
        n[3] += len(out)

    def _malformed_command(self, route: _Route, msg: can.Message, why: str) -> None:
        """A frame of the command id that cannot be a command (already counted as
        rejected): queue it marked ``MALFORMED`` so the daemon answers with a nack, with
        whatever signals the bytes present still give (to echo Command and Sequence)."""
        if len(self._commands) >= self._command_capacity:
            self._reject("overflow")
            return
        try:
            values = dict(route.message.decode(bytes(msg.data), decode_choices=False,
                                               allow_truncated=True, allow_excess=True))
        except Exception:
            values = {}
        values[MALFORMED] = float(REASONS.index(why))
        t = msg.timestamp if _isfinite(msg.timestamp) else self._last_t
        self._commands.append((t, values))

    def on_error(self, exc: Exception) -> None:
        """Called by the Notifier when the bus (or a listener) raised: count and log; the
        Notifier keeps running because this handler exists."""
        with self._lock:
            self._n[6] += 1
        log.warning("CAN bus error: %s", exc)

    # -- consumer side -----------------------------------------------------------------
    def drain(self, max_items: int | None = None) -> list[Sample]:
        """Pop up to ``max_items`` (all if None) samples in arrival order."""
        buf = self._buf
        k = len(buf) if max_items is None else min(max_items, len(buf))
        popleft = buf.popleft
        return [popleft() for _ in range(k)]

    def pending(self) -> int:
        """Samples waiting in the FIFO."""
        return len(self._buf)

    def pop_commands(self) -> list[Command]:
        """Decoded command frames ``(timestamp, {signal: value})`` received so far."""
        out = []
        while self._commands:
            out.append(self._commands.popleft())
        return out

    def stats(self) -> DecodeStats:
        """A consistent snapshot of every counter (thread-safe)."""
        with self._lock:
            n = list(self._n)
            rej = dict(zip(REASONS, self._rej, strict=True))
            lerr = self._listener_errors
        return DecodeStats(received=n[0], decoded=n[1], ignored=n[2], samples=n[3],
                           commands=n[4], counter_jumps=n[5], bus_errors=n[6],
                           listener_errors=lerr, rejected=rej)

    @property
    def last_timestamp(self) -> float:
        """Timestamp (s) of the newest accepted frame (frame time); -inf before the first."""
        return self._last_t

    @property
    def gyro_names(self) -> Sequence[str]:
        return self.channels.gyros
