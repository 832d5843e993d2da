"""The per-frame receive path: route, length check, decode, range check, time, append.

Per frame the work is constant: one dict lookup by frame key (standard and extended ids
are different keys), a length check, one decode of the mapped signals (a precompiled
extractor, :mod:`gyrostand.can.receive.extract`, whatever the DBC's byte order and
widths; cantools for multiplexed signals and commands), a range and timestamp check per
mapped signal, and an append. The common case (one mapped signal, a timestamp within the
window of the anchor, nothing held) is accepted inline; every other data frame goes to
the timing rule (:mod:`~gyrostand.can.receive.timing`), command frames to the command
queue (:mod:`~gyrostand.can.receive.commands`). Everything rejected is counted by reason.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Sequence

from gyrostand.can.logs.frames import ERROR_FRAME, Frame
from gyrostand.can.receive.commands import CommandQueue
from gyrostand.can.receive.state import Sample
from gyrostand.can.receive.timing import FrameTiming
from gyrostand.can.routes import Dropped, Invalid

__all__ = ["FramePath"]

log = logging.getLogger(__name__)

_isfinite = math.isfinite

#: what a decoded frame gives: its samples and its rolling counters (key, value, modulus)
_Decided = tuple[list[Sample], list[tuple[tuple[int, int], int, int]]]


def _several(extract: Sequence[tuple], values: dict, t: float) -> _Decided | None:
    """The samples and counters of a frame that carries several mapped signals, in the
    route's extract order (a multiplexed signal not selected by the frame is left out);
    None when a value is out of its range (also NaN and +-inf)."""
    out: list[Sample] = []
    counted: list[tuple[tuple[int, int], int, int]] = []
    for g, c, name, lo, hi, cname, mod, ckey in extract:
        v = values.get(name)
        if v is None:  # multiplexed signal not selected by this frame
            continue
        v = float(v)
        if not lo <= v <= hi:  # also false for NaN and +-inf
            return None
        out.append((g, c, t, v))
        if cname is not None and values.get(cname) is not None:
            counted.append((ckey, int(values[cname]), mod))
    return out, counted


class FramePath(FrameTiming, CommandQueue):
    """:meth:`_receive`, the receive path for one frame or a batch of frames, and
    :meth:`receive_frames`, its entry for batches."""

    def receive_frames(self, frames: Iterable[Frame]) -> None:
        """Receive frames given as :func:`~gyrostand.can.logs.frames.frame_fields` tuples,
        in order, under one lock: the very steps ``on_message_received`` runs per frame
        (replay's reader process delivers frames this way). Never raises on a bad frame."""
        with self._lock:
            self._receive(frames)

    def _flagged(self, flags: int) -> None:
        """Count an error or remote frame."""
        if flags & ERROR_FRAME:
            self._n.bus_errors += 1
            self._rej.error_frame += 1
        else:
            self._rej.remote_frame += 1

    def _unrouted(self, key: int) -> None:
        """Count a frame whose key has no route: a DBC id not mapped (ignored) or an id
        not in the DBC (rejected; an extended one of a mapped PGN is named once)."""
        pinned = self._foreign.get(key)
        if pinned is not None:  # a mapped PGN from a source address not taken
            if pinned:
                self._n.ignored += 1
                self._n.other_source += 1
            else:
                self._rej.second_source += 1
        elif key in self._known:
            self._n.ignored += 1
        else:
            self._rej.unknown_id += 1
            self._count_unknown(key)
            if self._pgn_hint:
                self._unmatched(key)

    def _receive(self, frames: Iterable[Frame]) -> None:
        """The receive path, for one frame or a batch (the caller holds the lock). State
        used per frame is held in locals for the batch and written back at its end.

        A data frame is decoded and range-checked, then timed (see :meth:`_timed`): in
        the common case its timestamp lies within ``window`` s of the anchor (the newest
        accepted frame) and at or after its id's previous frame, and it is accepted at
        once; anything else goes through :meth:`_timed`, which holds or rejects it.

        The loop is one function on purpose: it runs once per frame, and the common
        case is kept inline (no call per frame); the rare branches are methods."""
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
                        self._flagged(flags)
                        continue
                    route = routes.get(key)
                    if route is None and self._by_pgn:
                        route = self._pgn_route(key)
                    if route is None:
                        self._unrouted(key)
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
                    except Dropped as why:  # the DBC says: no measurement in this frame
                        if isinstance(why, Invalid):
                            rej.invalid += 1
                        else:
                            rej.not_available += 1
                        continue
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
                        got = _several(extract, values, t)
                        if got is None:
                            rej.out_of_range += 1
                            continue
                        out, counted = got
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
