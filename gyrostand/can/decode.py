"""The receive path: a :class:`can.Listener` that decodes frames with cantools and appends
decoded samples to one bounded FIFO, counting everything it rejects by reason.

Per frame the work is constant: one dict lookup by frame id (standard and extended ids are
different keys), a length check, one decode of the mapped signals (a precompiled
extractor, :mod:`gyrostand.can.extract`, whatever the DBC's byte order and widths;
cantools for multiplexed signals and commands), a range and
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
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

import can
from cantools.database.can import Database

from gyrostand.can.dbc import EXTENDED_KEY_BIT, MessageRef, frame_key, j1939_pgn
from gyrostand.can.extract import array_extractor, extractor
from gyrostand.can.logread import ERROR_FRAME, Frame, frame_fields

if TYPE_CHECKING:
    from gyrostand.can.blfarray import FrameArrays
from gyrostand.can.routes import ChannelMap, _decoder, _Route
from gyrostand.can.rxstats import COUNT_FIELDS, REASONS, Counts, DecodeStats, Rejections

__all__ = ["DecodingListener", "DecodeStats", "ChannelMap", "REASONS", "DRIFT", "TEMP",
           "Sample", "Command", "MALFORMED", "UNRANGED_LIMIT", "Counts", "Rejections"]

log = logging.getLogger(__name__)

DRIFT, TEMP = 0, 1

_isfinite = math.isfinite
_NEG_INF = -math.inf

Sample = tuple[int, int, float, float]
#: a data frame waiting for its time to be confirmed: (timestamp, route, samples with the
#: frame's own timestamp, rolling counters (key, value, modulus))
_Held = tuple[float, "_Route", list[Sample], list[tuple[tuple[int, int], int, int]]]
#: the largest |value| of a mapped signal whose DBC gives no range (a payload beyond it is
#: garbage, e.g. a float32 near its 3.4e38 limit; it would overflow the estimators)
UNRANGED_LIMIT = 1e12
#: routes at most (ids cached for `match: pgn`: 8 priorities x 256 source addresses each)
MAX_ROUTES = 65536
Command = tuple[float, dict[str, float]]
#: key of a queued command frame that could not be decoded (value: index in REASONS)
MALFORMED = "__malformed__"


class DecodingListener(can.Listener):
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
        self._held: list[_Held] = []
        self._steps = 0
        self._outliers_logged = 0
        self._buf: list[Sample] = []
        # the array path's samples, after _buf's: (gyro, channel, t, value) arrays each
        self._chunks: list[tuple] = []
        self._nchunked = 0
        self._commands: deque[Command] = deque()
        self._command_capacity = command_capacity
        self._lock = threading.Lock()
        self._routes: dict[int, _Route] = {}
        self._known = {frame_key(m.frame_id, bool(m.is_extended_frame)) for m in db.messages}
        self._last_counter: dict[tuple[int, int], int] = {}
        for g, pair in enumerate(channels.signals):
            for c, ref in enumerate(pair):
                route = self._route(db, ref.message)
                lo = -UNRANGED_LIMIT if ref.minimum is None else ref.minimum
                hi = UNRANGED_LIMIT if ref.maximum is None else ref.maximum
                cnt = channels.counters[g][c] if channels.counters else None
                mod = 256
                if cnt is not None and cnt.maximum is not None:
                    mod = int(cnt.maximum) + 1
                route.extract.append((g, c, ref.name, lo, hi,
                                      cnt.name if cnt else None, mod, (g, c)))
        for route in self._routes.values():  # the mapped signals only, layout-blind
            needed = [x[2] for x in route.extract] + [x[5] for x in route.extract if x[5]]
            route.decode = extractor(route.message, needed) or route.decode
        # J1939: PGN -> route of the messages matched by PGN; an extended id of such a PGN
        # is looked up once and then cached in _routes under its own key
        self._by_pgn = {j1939_pgn(k & ~EXTENDED_KEY_BIT): r for k, r in self._routes.items()
                        if k in channels.pgn}
        # the other extended mapped messages by PGN, to say once when frames of their PGN
        # arrive from another source address (matching on the full id drops them)
        self._pgn_hint = {j1939_pgn(k & ~EXTENDED_KEY_BIT): r.message.name
                          for k, r in self._routes.items()
                          if k & EXTENDED_KEY_BIT and k not in channels.pgn}
        self._hinted: set[int] = set()
        if command is not None:  # a command is read whole, by cantools
            route = self._route(db, command)
            route.is_command = True
            route.decode = _decoder(route.message)
        # the array path (receive_arrays): per data route, its mapped signals and
        # counters extracted from arrays of payloads (None: decoded frame by frame with
        # the route's own decoder, e.g. a multiplexed message)
        self._array_decode: dict[int, object] = {}
        for route in self._routes.values():
            if route.is_command:
                continue
            cnames = [x[5] for x in route.extract if x[5]]
            self._array_decode[id(route)] = array_extractor(
                route.message, [x[2] for x in route.extract] + cnames, ints=cnames)
        self._table: tuple | None = None
        self._committing = False
        self.reset_counters()

    def _route(self, db: Database, ref: MessageRef) -> _Route:
        if ref.key not in self._routes:
            msg = db.get_message_by_name(ref.name)
            self._routes[ref.key] = _Route(msg, msg.length)
        return self._routes[ref.key]

    def _pgn_route(self, key: int) -> _Route | None:
        """The route of an extended id by its J1939 PGN (``match: pgn``), cached under the
        id; None for a standard id or another PGN."""
        if not key & EXTENDED_KEY_BIT:
            return None
        route = self._by_pgn.get(j1939_pgn(key & ~EXTENDED_KEY_BIT))
        if route is not None and len(self._routes) < MAX_ROUTES:
            self._routes[key] = route
        return route

    def _unmatched(self, key: int) -> None:
        """Log once per id an extended frame whose PGN is a mapped message's (another
        priority or source address: it decodes with ``match: pgn``)."""
        if not key & EXTENDED_KEY_BIT or key in self._hinted or len(self._hinted) >= 64:
            return
        name = self._pgn_hint.get(j1939_pgn(key & ~EXTENDED_KEY_BIT))
        if name is not None:
            self._hinted.add(key)
            log.warning("frames 0x%X carry the J1939 PGN of mapped message %s but another "
                        "priority or source address; they are not decoded (unknown_id). "
                        "Set `match: pgn` on its channels to take them.",
                        key & ~EXTENDED_KEY_BIT, name)

    def resync(self) -> None:
        """After a bus outage: forget the rolling counters' last values (frames were lost).
        Time references are kept: the frames after the outage are timed as in a replay
        of the raw log, which knows nothing of the outage (:meth:`_timed`)."""
        with self._lock:
            self._last_counter.clear()

    def reset_counters(self) -> None:
        """Zero every counter (the FIFO and timestamp history are kept)."""
        with self._lock:
            self._n = Counts()
            self._rej = Rejections()

    # -- the Notifier's callback -------------------------------------------------------
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

    def receive_frames(self, frames: Iterable[Frame]) -> None:
        """Receive frames given as :func:`~gyrostand.can.logread.frame_fields` tuples, in
        order, under one lock: the very steps :meth:`on_message_received` runs per frame
        (replay's reader process delivers frames this way). Never raises on a bad frame."""
        with self._lock:
            self._receive(frames)

    def receive_arrays(self, frames: FrameArrays) -> None:
        """Receive frames given as :class:`~gyrostand.can.blfarray.FrameArrays`, in order,
        under one lock, with the counts, rejections and samples :meth:`receive_frames`
        gives for the same frames: the per-frame fast path's rules computed on arrays
        (:meth:`_receive_arrays`) up to the first frame that leaves it (a frame to hold
        or reject by time, a command, a multiplexed or J1939-matched id...); that frame
        and the next few (16, more when the array path keeps stopping soon) go through
        the per-frame code, then the array path takes over again from the state the
        per-frame code left."""
        m = len(frames)
        pos, per = 0, 16
        with self._lock:
            while pos < m:
                self._committing = False
                try:
                    done = self._receive_arrays(frames[pos:] if pos else frames)
                except Exception as exc:  # a defect here: the per-frame path decides
                    if self._committing:  # counts already changed: no second go
                        raise
                    log.exception("array receive path failed (%s): the batch goes "
                                  "frame by frame", exc)
                    self._receive(frames.frames(pos))
                    return
                pos += done
                if pos >= m:
                    return
                # the frame that left the array path, and a few after it, frame by frame;
                # then the array path again (state is written back after each step)
                end = min(m, pos + per)
                self._receive(frames.frames(pos, end))
                pos = end
                if done < per:  # the array path does not pay off here: longer steps
                    per *= 4

    def _lookup(self) -> tuple:
        """(sorted keys, code per key, routes): code >= 0 the route's index, -1 a DBC id not
        mapped (ignored), -2 a route the array path does not take (a command). Rebuilt
        when routes were added (J1939 ids cached by :meth:`_pgn_route`)."""
        if self._table is not None and self._table[3] == len(self._routes):
            return self._table
        import numpy as np

        routes: list[_Route] = []
        codes: dict[int, int] = {k: -1 for k in self._known}
        for k, r in self._routes.items():
            if r.is_command:
                codes[k] = -2
            else:
                if r not in routes:
                    routes.append(r)
                codes[k] = routes.index(r)
        keys = np.array(sorted(codes), dtype=np.int64)
        code = np.array([codes[k] for k in sorted(codes)], dtype=np.int64)
        self._table = (keys, code, routes, len(self._routes))
        return self._table

    def _route_values(self, r: _Route, data, np) -> tuple:
        """Per mapped signal of route ``r`` (in its extract order), for payloads ``data``
        (n x w): (present, value, counter present, counter), and the frames that did not
        decode. Array-extracted when the route has an array extractor, else decoded
        frame by frame by the route's decoder (what the per-frame path runs)."""
        n = len(data)
        dec = self._array_decode.get(id(r))
        out = []
        if dec is not None:
            got = dec(data)  # type: ignore[operator]
            yes = np.ones(n, bool)
            for _, _, name, _, _, cname, _, _ in r.extract:
                out.append((yes, got[name], yes if cname else ~yes,
                            got[cname] if cname else np.zeros(n, np.int64)))
            return out, ~yes
        raw = np.ascontiguousarray(data[:, :r.length]).tobytes()
        length, decode = r.length, r.decode
        rows = []
        undec = np.zeros(n, bool)
        for j in range(n):
            try:
                rows.append(decode(raw[j * length:(j + 1) * length]))
            except Exception:
                rows.append({})
                undec[j] = True
        for _, _, name, _, _, cname, _, _ in r.extract:
            vals = [row.get(name) for row in rows]
            present = np.array([v is not None for v in vals], bool)
            value = np.array([float(v) if v is not None else 0.0 for v in vals])
            cvs = [row.get(cname) if cname else None for row in rows]
            cp = np.array([v is not None for v in cvs], bool)
            cnt = np.array([int(v) if v is not None else 0 for v in cvs], np.int64)
            out.append((present, value, cp, cnt))
        return out, undec

    def _receive_arrays(self, fa: FrameArrays) -> int:
        """The per-frame path of :meth:`_receive` on arrays, for the frames before the
        first one it cannot decide alone; returns how many frames it took (the caller
        gives the next ones to :meth:`_receive`). Counted as there: error and remote
        frames, unknown and ignored ids, wrong lengths, non-finite timestamps,
        undecodable payloads, out-of-range values, frames without a selected signal;
        accepted as there: a decoded, in-range frame within ``window`` of the anchor
        (the running maximum of accepted timestamps), at or after its id's previous
        frame, nothing held, its samples fitting in the FIFO."""
        import numpy as np

        keys, code, routes, _ = self._lookup()
        t, key, flags, length = fa.t, fa.key, fa.flags, fa.length
        m = len(t)
        if len(keys):
            at = np.minimum(np.searchsorted(keys, key), len(keys) - 1)
            c = np.where(keys[at] == key, code[at], -3)  # -3: an id not in the DBC
        else:
            c = np.full(m, -3, np.int64)
        c = np.where(flags != 0, -4, c)  # -4: error / remote frame (counted only)
        stop = m
        # frames the array path cannot decide: commands, and extended ids not routed that
        # a hint would name (logged once per id, in order, by the per-frame code)
        bad = c == -2
        if self._by_pgn or self._pgn_hint:
            ext = (key & EXTENDED_KEY_BIT) != 0
            odd = ((c == -3) | (c == -1)) & ext
            if odd.any():
                routed_now = len(self._routes)
                hint: list[int] = []
                for k in np.unique(key[odd]).tolist():
                    pgn = j1939_pgn(k & ~EXTENDED_KEY_BIT)
                    if pgn in self._by_pgn:
                        if self._pgn_route(k) is not None and k not in self._routes:
                            hint.append(k)  # routed but not cached (MAX_ROUTES)
                    elif (k not in self._known and pgn in self._pgn_hint
                          and k not in self._hinted and len(self._hinted) < 64):
                        hint.append(k)
                if len(self._routes) != routed_now:  # J1939 ids routed: look up again
                    return self._receive_arrays(fa)
                if hint:
                    bad |= np.isin(key, hint)
        nz = np.flatnonzero(bad)
        if len(nz):
            stop = int(nz[0])
        routed = c >= 0
        rl = np.array([r.length for r in routes], dtype=np.int64)
        ok_len = np.zeros(m, bool)
        ok_len[routed] = length[routed] == rl[c[routed]]
        finite = np.isfinite(t)
        cand = routed & ok_len & finite
        cand[stop:] = False
        undec = np.zeros(m, bool)
        oor = np.zeros(m, bool)
        nsamp = np.zeros(m, np.int64)
        # per route: its frames, and per mapped signal (present, value, counter...)
        per_route: dict[int, tuple] = {}
        single_routes: dict[int, bool] = {}
        value1 = np.zeros(m)
        for i, r in enumerate(routes):
            sel = np.flatnonzero(cand & (c == i))
            if not len(sel):
                continue
            cols, und = self._route_values(r, fa.data[sel], np)
            undec[sel] = und
            bad_v = np.zeros(len(sel), bool)
            ns = np.zeros(len(sel), np.int64)
            for (present, value, _, _), x in zip(cols, r.extract, strict=True):
                lo, hi = x[3], x[4]
                bad_v |= present & ~((lo <= value) & (value <= hi))  # NaN: out of range
                ns += present
            oor[sel] = bad_v & ~und
            nsamp[sel] = ns
            per_route[i] = (sel, cols)
            # one mapped signal, present in every frame: its value per frame
            single_routes[i] = len(cols) == 1 and bool(cols[0][0].all())
            if single_routes[i]:
                value1[sel] = cols[0][1]
        ign = cand & ~undec & ~oor & (nsamp == 0)
        acc = cand & ~undec & ~oor & (nsamp > 0)
        # timing, in order: the anchor before each accepted frame is the running maximum
        ia = np.flatnonzero(acc)
        a0 = self._anchor
        if len(ia):
            ta = t[ia]
            prev_max = np.maximum.accumulate(np.concatenate(([a0], ta)))[:-1]
            w = self.window
            ok = (prev_max - w <= ta) & (ta <= prev_max + w)
            ra = c[ia]
            order = np.argsort(ra, kind="stable")
            rs, ts = ra[order], ta[order]
            first = np.ones(len(rs), bool)
            first[1:] = rs[1:] != rs[:-1]
            prev_t = np.empty(len(rs))
            prev_t[1:] = ts[:-1]
            last = np.array([r.last_t for r in routes])
            prev_t[first] = last[rs[first]]
            mono = np.empty(len(rs), bool)
            mono[order] = ts >= prev_t
            ok &= mono
            ok &= len(self._buf) + self._nchunked + np.cumsum(nsamp[ia]) <= self.capacity
            if self._held:
                ok[:] = False
            fail = np.flatnonzero(~ok)
            if len(fail):
                stop = min(stop, int(ia[fail[0]]))
                ia = ia[:fail[0]]
        # everything before ``stop`` is decided here
        self._committing = True
        cs = c[:stop]
        n, rej = self._n, self._rej
        n.received += stop
        fl = flags[:stop]
        nerr = int(np.count_nonzero(fl & ERROR_FRAME))
        n.bus_errors += nerr
        rej.error_frame += nerr
        rej.remote_frame += int(np.count_nonzero(fl != 0)) - nerr
        n.ignored += int(np.count_nonzero(cs == -1)) + int(np.count_nonzero(ign[:stop]))
        rej.unknown_id += int(np.count_nonzero(cs == -3))
        rt = cs >= 0
        rej.wrong_dlc += int(np.count_nonzero(rt & ~ok_len[:stop]))
        rej.bad_timestamp += int(np.count_nonzero(rt & ok_len[:stop] & ~finite[:stop]))
        rej.undecodable += int(np.count_nonzero(undec[:stop]))
        rej.out_of_range += int(np.count_nonzero(oor[:stop]))
        if not len(ia):
            return stop
        # accepted: per-id last times, the anchor, rolling counters, samples in order
        taken = np.zeros(m, bool)
        taken[ia] = True
        offset = self._offset
        pos_l, ent_l, g_l, c_l, v_l = [], [], [], [], []
        single = all(one for one in single_routes.values())
        for i, (sel, cols) in per_route.items():
            mine = taken[sel]
            if not mine.any():
                continue
            r = routes[i]
            fr = sel[mine]
            r.last_t = float(t[fr[-1]])
            for e, ((present, value, cp, cnt), x) in enumerate(
                    zip(cols, r.extract, strict=True)):
                g, ch, _, _, _, cname, mod, ckey = x
                pm = present[mine]
                if cname:
                    use = pm & cp[mine]
                    cv = cnt[mine][use]
                    if len(cv):
                        prev = self._last_counter.get(ckey)
                        # np.diff(cv[, prepend=prev]), without its generic set-up
                        steps = cv[1:] - cv[:-1] if prev is None else \
                            cv - np.concatenate(([prev], cv[:-1]))
                        n.counter_jumps += int(np.count_nonzero(steps % mod != 1 % mod))
                        self._last_counter[ckey] = int(cv[-1])
                if single:
                    continue
                pos_l.append(fr[pm])
                ent_l.append(np.full(int(pm.sum()), e))
                g_l.append(np.full(int(pm.sum()), g))
                c_l.append(np.full(int(pm.sum()), ch))
                v_l.append(value[mine][pm])
        self._anchor = max(a0, float(t[ia].max()))
        if single:  # one sample per accepted frame: frame order as it is
            ra = c[ia]
            gt = np.array([r.extract[0][0] for r in routes], np.int64)
            ct = np.array([r.extract[0][1] for r in routes], np.int64)
            chunk = (gt[ra], ct[ra], t[ia] + offset, value1[ia])
            count = len(ia)
        else:
            pos, ent = np.concatenate(pos_l), np.concatenate(ent_l)
            order = np.lexsort((ent, pos))  # frame order, then the route's extract order
            pos = pos[order]
            chunk = (np.concatenate(g_l)[order], np.concatenate(c_l)[order], t[pos] + offset,
                     np.concatenate(v_l)[order])
            count = len(pos)
        self._chunks.append(chunk)  # as arrays: the binner takes them so (Ingest.pump)
        self._nchunked += count
        n.decoded += len(ia)
        n.samples += count
        return stop

    def _receive(self, frames: Iterable[Frame]) -> None:
        """The receive path, for one frame or a batch (the caller holds the lock). State
        used per frame is held in locals for the batch and written back at its end.

        A data frame is decoded and range-checked, then timed (see :meth:`_timed`): in
        the common case its timestamp lies within ``window`` s of the anchor (the newest
        accepted frame) and at or after its id's previous frame, and it is accepted at
        once; anything else goes through :meth:`_timed`, which holds or rejects it."""
        self._unchunk()
        n, rej, routes, buf = self._n, self._rej, self._routes, self._buf
        cap, last_counter = self.capacity, self._last_counter
        window, offset, a, held = self.window, self._offset, self._anchor, bool(self._held)
        it = iter(frames)
        while True:
            try:
                for t, key, flags, data in it:
                    n.received += 1
                    if flags:
                        if flags & ERROR_FRAME:
                            n.bus_errors += 1
                            rej.error_frame += 1
                        else:
                            rej.remote_frame += 1
                        continue
                    route = routes.get(key)
                    if route is None and self._by_pgn:
                        route = self._pgn_route(key)
                    if route is None:
                        if key in self._known:
                            n.ignored += 1
                        else:
                            rej.unknown_id += 1
                            if self._pgn_hint:
                                self._unmatched(key)
                        continue
                    if len(data) != route.length:
                        rej.wrong_dlc += 1
                        if route.is_command:
                            self._malformed_command(route, t, data, "wrong_dlc")
                        continue
                    if route.is_command:  # never subject to the data channel's time checks
                        self._command(route, t, data)
                        continue
                    if not _isfinite(t):
                        rej.bad_timestamp += 1
                        continue
                    try:
                        values = route.decode(data)
                    except Exception:
                        rej.undecodable += 1
                        continue
                    extract = route.extract
                    if len(extract) == 1:  # the common case, one mapped signal: no lists
                        g, c, name, lo, hi, cname, mod, ckey = extract[0]
                        v = values.get(name)
                        if v is None:  # multiplexed signal not selected by this frame
                            n.ignored += 1
                            continue
                        v = float(v)
                        if not lo <= v <= hi:  # also false for NaN and +-inf
                            rej.out_of_range += 1
                            continue
                        if (a - window <= t <= a + window and t >= route.last_t
                                and not held and len(buf) < cap):
                            route.last_t = t
                            if t > a:
                                a = t
                            if cname is not None:  # _count, inlined on the fast path
                                cv = values.get(cname)
                                if cv is not None:
                                    cv = int(cv)
                                    prev = last_counter.get(ckey)
                                    if prev is not None and (cv - prev) % mod != 1 % mod:
                                        n.counter_jumps += 1
                                    last_counter[ckey] = cv
                            buf.append((g, c, t + offset, v))
                            n.decoded += 1
                            n.samples += 1
                            continue
                        out = [(g, c, t, v)]
                        counted = []
                        if cname is not None and values.get(cname) is not None:
                            counted.append((ckey, int(values[cname]), mod))
                    else:
                        out, counted = [], []
                        bad = False
                        for g, c, name, lo, hi, cname, mod, ckey in extract:
                            v = values.get(name)
                            if v is None:  # multiplexed signal not selected by this frame
                                continue
                            v = float(v)
                            if not lo <= v <= hi:  # also false for NaN and +-inf
                                bad = True
                                break
                            out.append((g, c, t, v))
                            if cname is not None and values.get(cname) is not None:
                                counted.append((ckey, int(values[cname]), mod))
                        if bad:
                            rej.out_of_range += 1
                            continue
                        if not out:
                            n.ignored += 1
                            continue
                    self._anchor = a
                    try:
                        self._timed((t, route, out, counted))
                    finally:  # the state _timed left, even if it failed
                        offset, a, held = self._offset, self._anchor, bool(self._held)
                break  # every frame received
            except Exception as exc:  # one bad frame: count it, go on with the next
                n.listener_errors += 1
                log.exception("listener failed on a frame: %s", exc)
            finally:
                self._anchor = a

    # -- timing of data frames -----------------------------------------------------------
    def _timed(self, frame: _Held) -> None:
        """Time a decoded, in-range data frame ``(t, route, samples, counters)`` that the
        fast path did not accept. With A the anchor (newest accepted timestamp) and W the
        window:

        * ``A - W <= t <= A + W``: accepted if at or after its id's previous frame
          (else ``non_monotonic``); a frame held meanwhile was an outlier (rejected);
        * otherwise it is *held*, with the frames that agree with it (each within
          ``[C - W, C + max_gap]`` of the newest held one, C): the second such frame
          confirms the new time. A forward move of at most ``max_gap`` s is a pause
          (the bins between are gaps); a move back, or forward by more, is a clock
          step: counted, logged, and the frames after it are shifted by a whole number
          of bins (``offset``) so they start in a bin after every bin before it: the two
          sides are never merged and no bin is invented. A held frame that a frame near
          A contradicts, or that a frame agreeing with neither replaces, is rejected
          (``time_jump`` ahead of A, ``non_monotonic`` behind it).
        """
        t = frame[0]
        a, w, held = self._anchor, self.window, self._held
        if a - w <= t <= a + w:
            if held:
                self._reject_held("contradicted by the next frame")
            self._accept(frame)
            return
        if held:
            c = held[-1][0]
            if c - w <= t <= c + self.max_gap:
                held.append(frame)
                self._confirm()
                return
            self._reject_held("replaced by a frame that agrees with neither")
        self._held.append(frame)  # waits for a second frame to confirm its time

    def _confirm(self) -> None:
        held, a = self._held, self._anchor
        if len(held) < self.confirm:
            return
        first = held[0][0]
        if a > _NEG_INF and not (a < first <= a + self.max_gap):
            # a clock step: shift the new side past the last bin of the old one
            mapped = a + self._offset
            bins = math.ceil((a - first) / self.dt) + 1
            self._offset += bins * self.dt
            self._steps += 1
            for r in self._routes.values():
                r.last_t = _NEG_INF
            self._anchor = _NEG_INF
            log.warning("clock step of %+.3f s at frame time %.3f (id references "
                        "re-anchored after %d agreeing frames): later frames shifted by "
                        "%+.3f s, into bins after %.3f", first - a, mapped, len(held),
                        self._offset, mapped)
        self._held = []
        for f in held:
            self._accept(f)

    def _accept(self, frame: _Held) -> None:
        t, route, out, counted = frame
        self._unchunk()
        rej, n, buf = self._rej, self._n, self._buf
        if t < route.last_t:
            rej.non_monotonic += 1
            return
        if len(buf) + len(out) > self.capacity:
            rej.overflow += 1
            return
        route.last_t = t
        if t > self._anchor:
            self._anchor = t
        for ckey, cv, mod in counted:
            self._count(ckey, cv, mod)
        offset = self._offset
        buf.extend([(g, c, tt + offset, v) for g, c, tt, v in out])
        n.decoded += 1
        n.samples += len(out)

    def _count(self, ckey: tuple[int, int], cv: int, mod: int) -> None:
        prev = self._last_counter.get(ckey)
        if prev is not None and (cv - prev) % mod != 1 % mod:
            self._n.counter_jumps += 1
        self._last_counter[ckey] = cv

    def _reject_held(self, why: str) -> None:
        a = self._anchor
        rej = self._rej
        for t, *_ in self._held:
            if t > a:
                rej.time_jump += 1
            else:
                rej.non_monotonic += 1
        if self._outliers_logged < 20 or self._outliers_logged % 1000 == 0:
            log.warning("%d frame(s) at t=%.3f rejected, %+.3f s from the bus's time "
                        "%.3f (%s)", len(self._held), self._held[0][0],
                        self._held[0][0] - a, a + self._offset, why)
        self._outliers_logged += 1
        self._held = []

    def settle(self) -> None:
        """End of the frames (end of run or of a log): frames still held are accepted
        when nothing was accepted before them (a log of one frame), else rejected as
        unconfirmed."""
        with self._lock:
            if not self._held:
                return
            if self._anchor == _NEG_INF and self._offset == 0.0:
                held, self._held = self._held, []
                for f in held:
                    self._accept(f)
            else:
                self._reject_held("not confirmed before the end")

    def _command(self, route: _Route, t: float, data: bytes | bytearray) -> None:
        """Queue a command frame (decoded; a payload that cannot be decoded is queued
        ``MALFORMED``). Its timestamp is only used to rate-limit commands (a timestamp
        that is not finite becomes the newest frame time)."""
        rej, n = self._rej, self._n
        try:
            values = route.decode(data)
        except Exception:
            rej.undecodable += 1
            self._malformed_command(route, t, data, "undecodable")
            return
        if len(self._commands) >= self._command_capacity:
            rej.overflow += 1
            return
        self._commands.append((t if _isfinite(t) else self.last_timestamp, dict(values)))
        n.decoded += 1
        n.commands += 1

    def _malformed_command(self, route: _Route, t: float, data: bytes | bytearray,
                           why: str) -> None:
        """A frame of the command id that cannot be a command (already counted as
        rejected): queue it marked ``MALFORMED`` so the daemon answers with a nack, with
        whatever signals the bytes present still give (to echo Command and Sequence)."""
        if len(self._commands) >= self._command_capacity:
            self._rej.overflow += 1
            return
        try:
            values = dict(route.message.decode(bytes(data), decode_choices=False,
                                               allow_truncated=True, allow_excess=True))
        except Exception:
            values = {}
        values[MALFORMED] = float(REASONS.index(why))
        self._commands.append((t if _isfinite(t) else self.last_timestamp, values))

    def on_error(self, exc: Exception) -> None:
        """Called by the Notifier when the bus (or a listener) raised: count and log; the
        Notifier keeps running because this handler exists."""
        with self._lock:
            self._n.bus_errors += 1
        log.warning("CAN bus error: %s", exc)

    # -- consumer side -----------------------------------------------------------------
    def _unchunk(self) -> None:
        """The array path's samples into the FIFO as tuples (before a frame-by-frame
        sample follows them, or for a consumer of tuples); the caller holds the lock."""
        if self._chunks:
            for g, c, t, v in self._chunks:
                self._buf.extend(zip(g.tolist(), c.tolist(), t.tolist(), v.tolist(),
                                     strict=True))
            self._chunks, self._nchunked = [], 0

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

    def pop_commands(self) -> list[Command]:
        """Decoded command frames ``(timestamp, {signal: value})`` received so far."""
        out = []
        while self._commands:
            out.append(self._commands.popleft())
        return out

    def stats(self) -> DecodeStats:
        """A consistent snapshot of every counter (thread-safe)."""
        with self._lock:  # flat int fields: what dataclasses.asdict gave, without its
            n, r = self._n, self._rej  # deep copy (a heartbeat asks at every beat)
            counts = {k: getattr(n, k) for k in COUNT_FIELDS}
            rej = {k: getattr(r, k) for k in REASONS}
            steps, held = self._steps, len(self._held)
        return DecodeStats(**counts, rejected=rej, clock_steps=steps, held=held)

    @property
    def last_timestamp(self) -> float:
        """Frame time (s): the newest accepted data frame's timestamp, shifted as the
        samples are after a clock step (so it never moves back); -inf before the first."""
        return self._anchor + self._offset

    @property
    def gyro_names(self) -> Sequence[str]:
        return self.channels.gyros
