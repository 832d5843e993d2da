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
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import can
from cantools.database.can import Database

from gyrostand.can.dbc import MessageRef, SignalRef, frame_key
from gyrostand.can.logread import ERROR_FRAME, Frame, frame_fields

try:
    from cantools.database.utils import decode_data as _cantools_decode_data
except ImportError:  # another cantools: decode_simple is used
    _cantools_decode_data = None  # type: ignore[assignment]
_decode_data: Callable[..., dict] | None = _cantools_decode_data

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
(_UNKNOWN_ID, _WRONG_DLC, _UNDECODABLE, _OUT_OF_RANGE, _BAD_TIMESTAMP, _NON_MONOTONIC,
 _TIME_JUMP, _ERROR_FRAME, _REMOTE_FRAME, _OVERFLOW) = range(len(REASONS))
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
        self.decode = _decoder(message)
        self.length = length
        # (gyro, channel, signal name, minimum, maximum, counter signal or None, modulus,
        #  (gyro, channel) as the counter's key)
        self.extract: list[tuple[int, int, str, float, float, str | None, int,
                                 tuple[int, int]]] = []
        self.is_command = False
        self.last_t = -math.inf


def _decoder(message) -> Callable[[bytes | bytearray], dict]:
    """``decode(data) -> {signal: value}`` of a DBC message: cantools' decoding, scaled,
    without choice names (what ``Message.decode_simple(data, decode_choices=False)``
    returns).

    ``decode_simple`` checks per call that the message is no container, then walks its
    codec tree: cantools' ``decode_data`` on the top level, then each selected multiplexed
    level. The route checks the payload length before decoding, so here the walk is
    entered directly: ``decode_data`` with the message's own codec for a plain message
    (0.75 vs 0.95 µs per frame), ``Message._decode`` for a multiplexed one. Either is
    used only if it gives what ``decode_simple`` gives on probe payloads; otherwise
    (another cantools) ``decode_simple`` itself is used; ``decode`` for a container.
    """
    if message.is_container:
        return partial(message.decode, decode_choices=False)

    def public(data):
        return message.decode_simple(data, False)

    codecs: Any = getattr(message, "_codecs", None)
    entry = getattr(message, "_decode", None)
    fast = public
    plain = _decode_data
    try:
        if not codecs["multiplexers"] and plain is not None:
            length, signals, formats = message.length, codecs["signals"], codecs["formats"]

            def fast(data):
                return plain(data, length, signals, formats, False, True, False, True)
        elif callable(entry):
            def fast(data):
                return entry(codecs, data, False, True, False, True)
    except (TypeError, KeyError):
        return public
    for probe in (bytes(message.length), b"\xff" * message.length,
                  bytes(range(1, message.length + 1))):
        try:
            want = public(probe)
        except Exception:
            continue  # e.g. a multiplexer value the DBC does not define
        try:
            if fast(probe) != want:
                return public
        except Exception:
            return public
    return fast


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
        self._buf: list[Sample] = []
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
                                      cnt.name if cnt else None, mod, (g, c)))
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
            f = frame_fields(msg)
        except Exception as exc:  # not a frame at all: received, and failed
            with self._lock:
                self._n[0] += 1
                self._listener_errors += 1
            log.exception("listener failed on %r: %s", msg, exc)
            return
        try:
            with self._lock:
                self._receive((f,))
        except Exception as exc:  # never let the Notifier thread die
            with self._lock:
                self._listener_errors += 1
            log.exception("listener failed on %r: %s", msg, exc)

    def receive_frames(self, frames: Iterable[Frame]) -> None:
        """Receive frames given as :func:`~gyrostand.can.logread.frame_fields` tuples, in
        order, under one lock: the very steps :meth:`on_message_received` runs per frame
        (replay's reader process delivers frames this way). Never raises on a bad frame."""
        with self._lock:
            self._receive(frames)

    def _receive(self, frames: Iterable[Frame]) -> None:
        """The receive path, for one frame or a batch (the caller holds the lock). State
        used per frame is held in locals for the batch and written back at its end."""
        n, rej, routes, buf = self._n, self._rej, self._routes, self._buf
        cap, max_gap, last_counter = self.capacity, self.max_gap, self._last_counter
        last_t = self._last_t
        it = iter(frames)
        while True:
            try:
                for t, key, flags, data in it:
                    n[0] += 1
                    if flags:
                        if flags & ERROR_FRAME:
                            n[6] += 1
                            rej[_ERROR_FRAME] += 1
                        else:
                            rej[_REMOTE_FRAME] += 1
                        continue
                    route = routes.get(key)
                    if route is None:
                        if key in self._known:
                            n[2] += 1
                        else:
                            rej[_UNKNOWN_ID] += 1
                        continue
                    if len(data) != route.length:
                        rej[_WRONG_DLC] += 1
                        if route.is_command:
                            self._malformed_command(route, t, data, "wrong_dlc", last_t)
                        continue
                    if not _isfinite(t):
                        rej[_BAD_TIMESTAMP] += 1
                        continue
                    ref_t = route.last_t
                    if t < ref_t:
                        rej[_NON_MONOTONIC] += 1
                        continue
                    if ref_t == _NEG_INF:  # first frame of this id (after a resync: no
                        ref_t = _NEG_INF if self._resynced else last_t  # reference)
                    if ref_t > _NEG_INF and t - ref_t > max_gap:
                        rej[_TIME_JUMP] += 1
                        continue
                    try:
                        values = route.decode(data)
                    except Exception:
                        rej[_UNDECODABLE] += 1
                        if route.is_command:
                            self._malformed_command(route, t, data, "undecodable", last_t)
                        continue
                    if route.is_command:
                        if len(self._commands) >= self._command_capacity:
                            rej[_OVERFLOW] += 1
                            continue
                        self._commands.append((t, dict(values)))
                        route.last_t = t
                        if t > last_t:
                            last_t = t
                        n[1] += 1
                        n[4] += 1
                        continue
                    extract = route.extract
                    if len(extract) == 1:  # the common case, one mapped signal: no lists
                        g, c, name, lo, hi, cname, mod, ckey = extract[0]
                        v = values.get(name)
                        if v is None:  # multiplexed signal not selected by this frame
                            n[2] += 1
                            continue
                        v = float(v)
                        if not lo <= v <= hi:  # also false for NaN
                            rej[_OUT_OF_RANGE] += 1
                            continue
                        if len(buf) >= cap:
                            rej[_OVERFLOW] += 1
                            continue
                        route.last_t = t
                        if t > last_t:
                            last_t = t
                        if cname is not None:
                            cv = values.get(cname)
                            if cv is not None:
                                cv = int(cv)
                                prev = last_counter.get(ckey)
                                if prev is not None and (cv - prev) % mod != 1 % mod:
                                    n[5] += 1
                                last_counter[ckey] = cv
                        buf.append((g, c, t, v))
                        n[1] += 1
                        n[3] += 1
                        continue
                    out: list[Sample] = []
                    counted: list[tuple[tuple[int, int], str, int]] = []
                    bad = False
                    for g, c, name, lo, hi, cname, mod, ckey in extract:
                        v = values.get(name)
                        if v is None:  # multiplexed signal not selected by this frame
                            continue
                        v = float(v)
                        if not lo <= v <= hi:  # also false for NaN
                            bad = True
                            break
                        out.append((g, c, t, v))
                        if cname is not None:
                            counted.append((ckey, cname, mod))
                    if bad:
                        rej[_OUT_OF_RANGE] += 1
                        continue
                    if not out:
                        n[2] += 1
                        continue
                    if len(buf) + len(out) > cap:
                        rej[_OVERFLOW] += 1
                        continue
                    route.last_t = t
                    if t > last_t:
                        last_t = t
                    for ckey, cname, mod in counted:
                        cv = values.get(cname)
                        if cv is None:
                            continue
                        cv = int(cv)
                        prev = last_counter.get(ckey)
                        if prev is not None and (cv - prev) % mod != 1 % mod:
                            n[5] += 1
                        last_counter[ckey] = cv
                    buf.extend(out)
                    n[1] += 1
                    n[3] += len(out)
                break  # every frame received
            except Exception as exc:  # one bad frame: count it, go on with the next
                self._listener_errors += 1
                log.exception("listener failed on a frame: %s", exc)
            finally:
                self._last_t = last_t

    def _malformed_command(self, route: _Route, t: float, data: bytes | bytearray,
                           why: str, last_t: float) -> None:
        """A frame of the command id that cannot be a command (already counted as
        rejected): queue it marked ``MALFORMED`` so the daemon answers with a nack, with
        whatever signals the bytes present still give (to echo Command and Sequence)."""
        if len(self._commands) >= self._command_capacity:
            self._rej[_OVERFLOW] += 1
            return
        try:
            values = dict(route.message.decode(bytes(data), decode_choices=False,
                                               allow_truncated=True, allow_excess=True))
        except Exception:
            values = {}
        values[MALFORMED] = float(REASONS.index(why))
        self._commands.append((t if _isfinite(t) else last_t, values))

    def on_error(self, exc: Exception) -> None:
        """Called by the Notifier when the bus (or a listener) raised: count and log; the
        Notifier keeps running because this handler exists."""
        with self._lock:
            self._n[6] += 1
        log.warning("CAN bus error: %s", exc)

    # -- consumer side -----------------------------------------------------------------
    def drain(self, max_items: int | None = None) -> list[Sample]:
        """Pop up to ``max_items`` (all if None) samples in arrival order."""
        with self._lock:
            buf = self._buf
            if max_items is None or max_items >= len(buf):
                self._buf = []
                return buf
            out = buf[:max_items]
            del buf[:max_items]
            return out

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
