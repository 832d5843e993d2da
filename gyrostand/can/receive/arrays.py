"""The array receive path: the per-frame path's rules computed on arrays of frames.

:meth:`ArrayPath.receive_arrays` takes :class:`~gyrostand.can.logs.blfarray.FrameArrays`
(a BLF's containers parsed whole) and gives the counts, rejections and samples the
per-frame path (:mod:`~gyrostand.can.receive.frames`) gives for the same frames. The
array path decides the frames up to the first one it cannot decide alone (a frame to
hold or reject by time, a command, a J1939 id to route or name); that frame and a few
after it go through the per-frame code, then the array path takes over again from the
state the per-frame code left.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any, NamedTuple

from gyrostand.can.dbc import EXTENDED_KEY_BIT, j1939_pgn
from gyrostand.can.logs.frames import ERROR_FRAME
from gyrostand.can.receive.frames import FramePath
from gyrostand.can.routes import Route

if TYPE_CHECKING:
    from gyrostand.can.logs.blfarray import FrameArrays

__all__ = ["ArrayPath"]

log = logging.getLogger(__name__)

# codes of a frame on the array path (>= 0: the index of its data route)
_IGNORED = -1  # an id of the DBC that is not mapped
_NOT_HERE = -2  # a route the array path does not take (a command)
_UNKNOWN = -3  # an id not in the DBC
_FLAGGED = -4  # an error or remote frame
_OTHER_SOURCE = -5  # a mapped PGN from a source address no channel maps (ignored)
_SECOND_SOURCE = -6  # a mapped PGN from a second source address (rejected)


class _Lookup(NamedTuple):
    """Frame keys (sorted) and their codes; the data routes by index; how many routes
    the listener had when this table was built."""

    keys: Any
    code: Any
    routes: list[Route]
    nroutes: int
    nforeign: int


class _Decoded(NamedTuple):
    """Per frame of a batch: ``undec`` did not decode, ``oor`` a value out of range,
    ``nsamp`` its samples; per data route index: its frames and per mapped signal
    (present, value, counter present, counter) (``per_route``), and whether that is one
    signal present in every frame (``single``); ``value1`` that one signal's value."""

    undec: Any
    oor: Any
    inval: Any  # the validity signal marked the frame invalid
    na: Any  # every mapped value a VAL_ code
    nadrop: Any  # mapped values dropped as codes, per frame
    nsamp: Any
    per_route: dict[int, tuple]
    single: dict[int, bool]
    value1: Any


class ArrayPath(FramePath):
    """:meth:`receive_arrays` and the array path's steps (the caller holds the lock)."""

    def receive_arrays(self, frames: FrameArrays) -> None:
        """Receive frames given as :class:`~gyrostand.can.logs.blfarray.FrameArrays`, in
        order, under one lock, with the counts, rejections and samples
        :meth:`receive_frames` gives for the same frames: the per-frame fast path's rules
        computed on arrays (:meth:`_receive_arrays`) up to the first frame that leaves it
        (a frame to hold or reject by time, a command, a multiplexed or J1939-matched
        id...); that frame and the next few (16, more when the array path keeps stopping
        soon) go through the per-frame code, then the array path takes over again from
        the state the per-frame code left."""
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

    def _lookup(self) -> _Lookup:
        """(sorted keys, code per key, routes): code >= 0 the route's index,
        ``_IGNORED`` a DBC id not mapped, ``_NOT_HERE`` a route the array path does not
        take (a command). Rebuilt when routes were added (J1939 ids cached by
        :meth:`_pgn_route`)."""
        if (self._table is not None and self._table[3] == len(self._routes)
                and self._table[4] == len(self._foreign)):
            return self._table  # type: ignore[return-value]
        import numpy as np

        routes: list[Route] = []
        codes: dict[int, int] = {k: _IGNORED for k in self._known}
        for k, r in self._routes.items():
            if r.is_command or (r.checked and self._array_decode.get(id(r)) is None):
                codes[k] = _NOT_HERE
            else:
                if r not in routes:
                    routes.append(r)
                codes[k] = routes.index(r)
        for k, pinned in self._foreign.items():
            codes[k] = _OTHER_SOURCE if pinned else _SECOND_SOURCE
        keys = np.array(sorted(codes), dtype=np.int64)
        code = np.array([codes[k] for k in sorted(codes)], dtype=np.int64)
        self._table = _Lookup(keys, code, routes, len(self._routes), len(self._foreign))
        return self._table

    def _route_values(self, r: Route, data, np) -> tuple:  # noqa: C901
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
            # the DBC's verdicts, as checked_decoder gives them frame by frame
            inval = np.zeros(n, bool)
            for vname, codes, accept in r.valid:
                inval |= np.isin(got[vname], np.array(sorted(codes), float)) != accept
            for _, _, name, _, _, cname, _, _ in r.extract:
                present = yes
                if name in r.codes:
                    present = ~np.isin(got[name], np.array(sorted(r.codes[name]), float))
                if name in r.convert:  # into the channel's unit, as checked_decoder does
                    s, o = r.convert[name]
                    got[name] = got[name] * s + o
                out.append((present & ~inval, got[name], yes if cname else ~yes,
                            got[cname] if cname else np.zeros(n, np.int64)))
            return out, ~yes, inval
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
        return out, undec, np.zeros(n, bool)

    def _codes(self, fa: FrameArrays, table: _Lookup, np) -> Any:
        """The code of each frame (see :meth:`_lookup`; ``_UNKNOWN`` an id not in the
        DBC, ``_FLAGGED`` an error or remote frame)."""
        keys, code = table.keys, table.code
        key, m = fa.key, len(fa.t)
        if len(keys):
            at = np.minimum(np.searchsorted(keys, key), len(keys) - 1)
            c = np.where(keys[at] == key, code[at], _UNKNOWN)
        else:
            c = np.full(m, _UNKNOWN, np.int64)
        return np.where(fa.flags != 0, _FLAGGED, c)

    def _j1939_hints(self, odd_keys: list[int]) -> list[int]:
        """Of the extended ids not routed (``odd_keys``, in order): route those matched by
        PGN (cached in ``_routes``), and return those the per-frame code must see: ids
        routed but not cached (``MAX_ROUTES``) and ids a hint would name (logged once
        per id, in order, by the per-frame code)."""
        hint: list[int] = []
        for k in odd_keys:
            pgn = j1939_pgn(k & ~EXTENDED_KEY_BIT)
            if pgn in self._by_pgn:
                if self._pgn_route(k) is not None and k not in self._routes:
                    hint.append(k)  # routed but not cached (MAX_ROUTES)

            elif (k not in self._known and pgn in self._pgn_hint
                  and k not in self._hinted and len(self._hinted) < 64):
                hint.append(k)
        return hint

    def _decode_routes(self, fa: FrameArrays, c, cand, routes: list[Route], np
                       ) -> _Decoded:
        """Decode and range-check the candidate frames (``cand``) route by route."""
        m = len(c)
        undec = np.zeros(m, bool)
        oor = np.zeros(m, bool)
        inval = np.zeros(m, bool)
        na = np.zeros(m, bool)
        nadrop = np.zeros(m, np.int64)
        nsamp = np.zeros(m, np.int64)
        # per route: its frames, and per mapped signal (present, value, counter...)
        per_route: dict[int, tuple] = {}
        single_routes: dict[int, bool] = {}
        value1 = np.zeros(m)
        for i, r in enumerate(routes):
            sel = np.flatnonzero(cand & (c == i))
            if not len(sel):
                continue
            cols, und, inv = self._route_values(r, fa.data[sel], np)
            undec[sel] = und
            inval[sel] = inv
            bad_v = np.zeros(len(sel), bool)
            ns = np.zeros(len(sel), np.int64)
            drop = np.zeros(len(sel), np.int64)
            for (present, value, _, _), x in zip(cols, r.extract, strict=True):
                lo, hi = x[3], x[4]
                bad_v |= present & ~((lo <= value) & (value <= hi))  # NaN: out of range
                ns += present
                if x[2] in r.codes:
                    drop += ~present & ~inv
            nadrop[sel] = drop
            na[sel] = (drop > 0) & (ns == 0) & ~inv
            oor[sel] = bad_v & ~und
            nsamp[sel] = ns
            per_route[i] = (sel, cols)
            # one mapped signal, present in every frame: its value per frame
            single_routes[i] = len(cols) == 1 and bool(cols[0][0].all())
            if single_routes[i]:
                value1[sel] = cols[0][1]
        return _Decoded(undec, oor, inval, na, nadrop, nsamp, per_route, single_routes,
                        value1)

    def _in_time(self, t, c, ia, nsamp, routes: list[Route], np) -> Any:
        """Per decoded, in-range frame ``ia`` (in order): whether the fast path accepts
        it: within ``window`` of the anchor before it (the running maximum of accepted
        timestamps), at or after its id's previous frame, nothing held, its samples
        fitting in the FIFO."""
        ta = t[ia]
        prev_max = np.maximum.accumulate(np.concatenate(([self._anchor], ta)))[:-1]
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
        return ok

    def _count_decided(self, fa: FrameArrays, stop: int, c, ok_len, finite, ign,
                       dec: _Decoded, np) -> None:
        """Count the frames before ``stop`` as the per-frame path counts them (received,
        error and remote frames, ignored, unknown ids, wrong lengths, non-finite
        timestamps, undecodable, out of range)."""
        cs = c[:stop]
        n, rej = self._n, self._rej
        n.received += stop
        fl = fa.flags[:stop]
        nerr = int(np.count_nonzero(fl & ERROR_FRAME))
        n.bus_errors += nerr
        rej.error_frame += nerr
        rej.remote_frame += int(np.count_nonzero(fl != 0)) - nerr
        other = int(np.count_nonzero(cs == _OTHER_SOURCE))
        n.ignored += (int(np.count_nonzero(cs == _IGNORED))
                      + int(np.count_nonzero(ign[:stop]))) + other
        n.other_source += other
        rej.second_source += int(np.count_nonzero(cs == _SECOND_SOURCE))
        unknown = cs == _UNKNOWN
        nunk = int(np.count_nonzero(unknown))
        rej.unknown_id += nunk
        if nunk:
            ids, per = np.unique(fa.key[:stop][unknown], return_counts=True)
            for key, k in zip(ids.tolist(), per.tolist(), strict=True):
                self._count_unknown(key, k)
        rt = cs >= 0
        rej.wrong_dlc += int(np.count_nonzero(rt & ~ok_len[:stop]))
        rej.bad_timestamp += int(np.count_nonzero(rt & ok_len[:stop] & ~finite[:stop]))
        rej.undecodable += int(np.count_nonzero(dec.undec[:stop]))
        rej.out_of_range += int(np.count_nonzero(dec.oor[:stop]))
        rej.invalid += int(np.count_nonzero(dec.inval[:stop]))
        rej.not_available += int(np.count_nonzero(dec.na[:stop]))
        n.not_available += int(dec.nadrop[:stop].sum())

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

        table = self._lookup()
        routes = table.routes
        t, key, length = fa.t, fa.key, fa.length
        m = len(t)
        c = self._codes(fa, table, np)
        stop = m
        # frames the array path cannot decide: commands, and extended ids not routed that
        # a hint would name (logged once per id, in order, by the per-frame code)
        bad = c == _NOT_HERE
        if self._by_pgn or self._pgn_hint:
            ext = (key & EXTENDED_KEY_BIT) != 0
            odd = ((c == _UNKNOWN) | (c == _IGNORED)) & ext
            if odd.any():
                routed_now = len(self._routes), len(self._foreign)
                # in order of first appearance: the first source address seen is the
                # device's (what the per-frame path decides)
                uk, first = np.unique(key[odd], return_index=True)
                hint = self._j1939_hints(uk[np.argsort(first)].tolist())
                if (len(self._routes), len(self._foreign)) != routed_now:  # look up again
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
        dec = self._decode_routes(fa, c, cand, routes, np)
        ign = cand & ~dec.undec & ~dec.oor & ~dec.inval & ~dec.na & (dec.nsamp == 0)
        acc = cand & ~dec.undec & ~dec.oor & (dec.nsamp > 0)
        # timing, in order: the anchor before each accepted frame is the running maximum
        ia = np.flatnonzero(acc)
        if len(ia):
            fail = np.flatnonzero(~self._in_time(t, c, ia, dec.nsamp, routes, np))
            if len(fail):
                stop = min(stop, int(ia[fail[0]]))
                ia = ia[:fail[0]]
        # everything before ``stop`` is decided here
        self._committing = True
        self._count_decided(fa, stop, c, ok_len, finite, ign, dec, np)
        if len(ia):
            self._commit(t, c, ia, routes, dec, np)
        return stop

    def _commit(self, t, c, ia, routes: list[Route], dec: _Decoded, np) -> None:
        """The accepted frames ``ia``: per-id last times, the anchor, rolling counters,
        and their samples in frame order (one chunk of arrays for the FIFO)."""
        n = self._n
        m = len(t)
        a0 = self._anchor
        taken = np.zeros(m, bool)
        taken[ia] = True
        offset = self._offset
        pos_l, ent_l, g_l, c_l, v_l = [], [], [], [], []
        single = all(one for one in dec.single.values())
        for i, (sel, cols) in dec.per_route.items():
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
                    self._count_array(ckey, cnt[mine][pm & cp[mine]], mod, np)
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
            chunk = (gt[ra], ct[ra], t[ia] + offset, dec.value1[ia])
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

    def _count_array(self, ckey: tuple[int, int], cv, mod: int, np) -> None:
        """:meth:`_count` for the counter values ``cv`` of one signal, in order."""
        if not len(cv):
            return
        prev = self._last_counter.get(ckey)
        # np.diff(cv[, prepend=prev]), without its generic set-up
        steps = cv[1:] - cv[:-1] if prev is None else \
            cv - np.concatenate(([prev], cv[:-1]))
        self._n.counter_jumps += int(np.count_nonzero(steps % mod != 1 % mod))
        self._last_counter[ckey] = int(cv[-1])
