"""The receive path's listener: a :class:`can.Listener` that decodes frames with cantools
and appends decoded samples to one bounded FIFO, counting everything it rejects by reason.

Estimation, binning and I/O happen in the consumer (:meth:`DecodingListener.drain`),
never in the Notifier's thread. Samples are ``(gyro index, channel index, timestamp s,
value)`` with channel 0 = drift (deg/h in our DBC; whatever unit the DBC gives) and
1 = temperature (degC), kept in bus order across gyros and channels so the binner sees
exactly what live or replay delivered.

The listener is assembled from the receive path's parts: the shared state
(:mod:`~gyrostand.can.receive.state`), the timing rule
(:mod:`~gyrostand.can.receive.timing`), the command queue
(:mod:`~gyrostand.can.receive.commands`), the per-frame path
(:mod:`~gyrostand.can.receive.frames`) and the array path
(:mod:`~gyrostand.can.receive.arrays`); its counters are named fields
(:mod:`~gyrostand.can.receive.counts`).
"""

from __future__ import annotations

import logging
import math
import threading
from collections import deque
from collections.abc import Sequence

import can
from cantools.database.can import Database

from gyrostand.can.dbc import EXTENDED_KEY_BIT, MessageRef, frame_key, j1939_pgn
from gyrostand.can.logs.frames import frame_fields
from gyrostand.can.receive.arrays import ArrayPath
from gyrostand.can.receive.counts import COUNT_FIELDS, REASONS, Counts, DecodeStats, Rejections
from gyrostand.can.receive.extract import array_extractor, extractor
from gyrostand.can.receive.state import UNRANGED_LIMIT, Held, Sample
from gyrostand.can.routes import ChannelMap, Route, checked_decoder, decoder
from gyrostand.can.validity import code_values

__all__ = ["DecodingListener"]

log = logging.getLogger(__name__)


class DecodingListener(ArrayPath, can.Listener):
    """Decode frames of the mapped DBC signals into a bounded sample FIFO.

    ``capacity`` bounds the FIFO (samples); when full, new samples are dropped and counted
    as ``overflow`` (the oldest are never overwritten). Frame timing (:meth:`_timed`):
    a timestamp within ``window`` s (default ``2·dt``) of the newest accepted one is
    taken at once; one further away waits for a second frame to confirm it, so an
    isolated outlier costs one frame, a pause of up to ``max_gap`` s gives gap bins, and
    a clock step (back, or forward by more than ``max_gap``) re-anchors the frames after
    it ``dt``-aligned past the bins before it. Frames of ``command`` go, decoded, to a
    bounded command queue read with :meth:`pop_commands`, whatever their timestamp.
    A mapped signal whose DBC gives no range accepts finite values with
    ``|v| <= UNRANGED_LIMIT``. ``on_message_received`` never raises.
    """

    def __init__(self, db: Database, channels: ChannelMap, *, capacity: int = 65536,
                 command: MessageRef | None = None, max_gap: float = 3600.0,
                 command_capacity: int = 64, dt: float = 1.0,
                 window: float | None = None) -> None:
        self.channels = channels
        self.capacity = int(capacity)
        self.max_gap = float(max_gap)
        self.dt = float(dt)
        self.window = 2.0 * self.dt if window is None else float(window)
        self.confirm = 2  # frames that agree on a new time (the first one included)
        self._anchor = -math.inf  # newest accepted timestamp since the last clock step
        self._offset = 0.0  # s added to timestamps since the last clock step (k·dt)
        self._held: list[Held] = []
        self._steps = 0
        self._outliers_logged = 0
        self._buf: list[Sample] = []
        # the array path's samples, after _buf's: (gyro, channel, t, value) arrays each
        self._chunks: list[tuple] = []
        self._nchunked = 0
        self._commands = deque()
        self._command_capacity = command_capacity
        self._lock = threading.Lock()
        self._routes: dict[int, Route] = {}
        self._known = {frame_key(m.frame_id, bool(m.is_extended_frame)) for m in db.messages}
        self._last_counter: dict[tuple[int, int], int] = {}
        self._pinned: dict[int, tuple[int, int]] = {}  # route key -> (PGN, source address)
        self._map_signals(db, channels)
        # J1939: PGN -> route of the messages matched by PGN (any source address; the first
        # one seen is taken, _first_sa), or {source address: route} where the session maps
        # each address; an extended id of such a PGN is looked up once, then cached in
        # _routes under its own key; an id of another address is named once (_foreign)
        self._by_pgn: dict[int, Route | dict[int, Route]] = {}
        for k, r in self._routes.items():
            if k in self._pinned:
                pgn, sa = self._pinned[k]
                by_sa = self._by_pgn.setdefault(pgn, {})
                assert isinstance(by_sa, dict)
                by_sa[sa] = r
            elif k in channels.pgn:
                self._by_pgn[j1939_pgn(k & ~EXTENDED_KEY_BIT)] = r
        self._first_sa: dict[int, int] = {}
        self._foreign: dict[int, bool] = {}
        # the other extended mapped messages by PGN, to say once when frames of their PGN
        # arrive from another source address (matching on the full id drops them)
        self._pgn_hint = {j1939_pgn(k & ~EXTENDED_KEY_BIT): r.message.name
                          for k, r in self._routes.items()
                          if k & EXTENDED_KEY_BIT and k not in channels.pgn
                          and k not in self._pinned}
        self._hinted: set[int] = set()
        if command is not None:  # a command is read whole, by cantools
            route = self._route(db, command)
            route.is_command = True
            route.decode = decoder(route.message)
        # the array path (receive_arrays): per data route, its mapped signals and
        # counters extracted from arrays of payloads (None: decoded frame by frame with
        # the route's own decoder, e.g. a multiplexed message)
        self._array_decode: dict[int, object] = {}
        for route in self._routes.values():
            if route.is_command:
                continue
            cnames = [x[5] for x in route.extract if x[5]]
            self._array_decode[id(route)] = array_extractor(
                route.message, [x[2] for x in route.extract] + cnames
                + [v[0] for v in route.valid], ints=cnames)
        # a PGN matched from any address is routed through _pgn_route, its DBC id too
        # (the first source address seen is the device's)
        for k in [k for k in self._routes if k in channels.pgn and k not in self._pinned]:
            del self._routes[k]
        self._table = None
        self._committing = False
        self.reset_counters()

    def _map_signals(self, db: Database, channels: ChannelMap) -> None:
        """A route per mapped message, with what it extracts per mapped signal (range,
        rolling counter and its modulus) and a decoder of those signals only."""
        codes: dict[int, dict[str, frozenset]] = {}
        valid: dict[int, dict[str, tuple[str, frozenset, bool]]] = {}
        for g, pair in enumerate(channels.signals):
            for c, ref in enumerate(pair):
                sa = channels.sources[g][c] if channels.sources else None
                key = ref.message.key
                if sa is not None:  # the device at this J1939 source address only
                    key = (key & ~0xFF) | sa
                    self._pinned[key] = (j1939_pgn(key & ~EXTENDED_KEY_BIT), sa)
                route = self._route(db, ref.message, key)
                lo = -UNRANGED_LIMIT if ref.minimum is None else ref.minimum
                hi = UNRANGED_LIMIT if ref.maximum is None else ref.maximum
                conv = channels.convert[g][c] if channels.convert else None
                if conv is not None:  # the range check runs on the converted value
                    lo, hi = sorted((conv(lo), conv(hi)))
                    route.convert[ref.name] = (conv.scale, conv.offset)
                cnt = channels.counters[g][c] if channels.counters else None
                mod = 256
                if cnt is not None and cnt.maximum is not None:
                    mod = int(cnt.maximum) + 1
                route.extract.append((g, c, ref.name, lo, hi,
                                      cnt.name if cnt else None, mod, (g, c)))
                bad = code_values(route.message.get_signal_by_name(ref.name))
                if bad:
                    codes.setdefault(id(route), {})[ref.name] = bad
                v = channels.valid[g][c] if channels.valid else None
                if v is not None:
                    valid.setdefault(id(route), {})[v[0]] = v
        for route in self._routes.values():  # the mapped signals only, layout-blind
            vs = list(valid.get(id(route), {}).values())
            needed = ([x[2] for x in route.extract] + [x[5] for x in route.extract if x[5]]
                      + [v[0] for v in vs])
            route.decode = extractor(route.message, needed) or route.decode
            cs = codes.get(id(route), {})
            route.codes, route.valid = cs, vs
            route.checked = bool(cs or vs)
            if route.checked or route.convert:  # decoded, checked and converted per frame
                route.decode = checked_decoder(route.decode, [x[2] for x in route.extract],
                                               cs, vs, route.convert, self._count_codes)

    def _count_codes(self, k: int) -> None:
        """``k`` mapped values were value-table codes (the lock is held: per-frame path)."""
        self._n.not_available += k

    def _route(self, db: Database, ref: MessageRef, key: int | None = None) -> Route:
        key = ref.key if key is None else key
        if key not in self._routes:
            msg = db.get_message_by_name(ref.name)
            self._routes[key] = Route(msg, msg.length)
        return self._routes[key]

    def resync(self) -> None:
        """After a bus outage: forget the rolling counters' last values (frames were lost).
        Time references are kept: the frames after the outage are timed as in a replay
        of the raw log, which knows nothing of the outage (:meth:`_timed`)."""
        with self._lock:
            self._last_counter.clear()

    def resume_after(self, t: float) -> None:
        """A resumed run: frame time ``t`` (s, the start of the last kept bin) stands for
        the newest accepted frame, so the next frames are timed as if they followed it:
        later ones within ``max_gap`` are a pause, earlier ones (a stand clock that went
        back) a clock step re-anchored into the bins after it, never late."""
        with self._lock:
            self._anchor = float(t)

    def reset_counters(self) -> None:
        """Zero every counter (the FIFO and timestamp history are kept)."""
        with self._lock:
            self._n = Counts()
            self._rej = Rejections()
            self._unknown = {}

    # -- the Notifier's callbacks ------------------------------------------------------
    def on_message_received(self, msg: can.Message) -> None:
        try:
            f = frame_fields(msg)
        except Exception as exc:  # not a frame at all: received, and failed
            with self._lock:
                self._n.received += 1
                self._n.listener_errors += 1
            log.exception("listener failed on %r: %s", msg, exc)
            return
        try:
            with self._lock:
                self._receive((f,))
        except Exception as exc:  # never let the Notifier thread die
            with self._lock:
                self._n.listener_errors += 1
            log.exception("listener failed on %r: %s", msg, exc)

    def on_error(self, exc: Exception) -> None:
        """Called by the Notifier when the bus (or a listener) raised: count and log; the
        Notifier keeps running because this handler exists."""
        with self._lock:
            self._n.bus_errors += 1
        log.warning("CAN bus error: %s", exc)

    # -- consumer side -----------------------------------------------------------------
    def drain_chunks(self) -> tuple[list[Sample], list[tuple]]:
        """Pop every sample, in arrival order: the tuples, then the array path's
        ``(gyro, channel, t, value)`` arrays (:meth:`Binner.add_arrays
        <gyrostand.can.binning.Binner.add_arrays>` takes them as they are)."""
        with self._lock:
            buf, chunks = self._buf, self._chunks
            self._buf, self._chunks, self._nchunked = [], [], 0
            return buf, chunks

    def drain(self, max_items: int | None = None) -> list[Sample]:
        """Pop up to ``max_items`` (all if None) samples in arrival order."""
        with self._lock:
            self._unchunk()
            buf = self._buf
            if max_items is None or max_items >= len(buf):
                self._buf = []
                return buf
            out = buf[:max_items]
            del buf[:max_items]
            return out

    def frames_that_fit(self) -> int:
        """How many frames an empty FIFO always takes without an overflow (each gives at
        most one sample per mapped signal of its id, and up to ``confirm`` held frames
        may be released with it): a replay pumps at least this often (back-pressure)."""
        per = max((len(r.extract) for r in self._routes.values()), default=1) or 1
        return max(1, self.capacity // per - self.confirm)

    def pending(self) -> int:
        """Samples waiting in the FIFO."""
        return len(self._buf) + self._nchunked

    def stats(self) -> DecodeStats:
        """A consistent snapshot of every counter (thread-safe)."""
        with self._lock:  # flat int fields: what dataclasses.asdict gave, without its
            n, r = self._n, self._rej  # deep copy (a heartbeat asks at every beat)
            counts = {k: getattr(n, k) for k in COUNT_FIELDS}
            rej = {k: getattr(r, k) for k in REASONS}
            steps, held = self._steps, len(self._held)
        return DecodeStats(**counts, rejected=rej, clock_steps=steps, held=held)

    def unknown_ids(self, n: int = 10) -> list[tuple[int, bool, int]]:
        """The ``n`` ids not in the DBC seen most often since the counters were zeroed, as
        ``(arbitration id, extended, frames)``, most frames first (then by id)."""
        with self._lock:
            items = list(self._unknown.items())
        items.sort(key=lambda kv: (-kv[1], kv[0]))
        return [(k & ~EXTENDED_KEY_BIT, bool(k & EXTENDED_KEY_BIT), c) for k, c in items[:n]]

    @property
    def gyro_names(self) -> Sequence[str]:
        return self.channels.gyros
