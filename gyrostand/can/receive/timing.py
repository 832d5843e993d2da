"""The timing rule of data frames: accept, hold, confirm or reject by frame timestamp.

Timing comes from the frames' own timestamps, never from the wall clock. With A the
anchor (the newest accepted timestamp) and W the window (default ``2·dt``), a frame
within ``[A - W, A + W]`` is taken at once; one further away waits for a second frame
to confirm it (:meth:`FrameTiming._timed`), so an isolated outlier costs one frame, a
pause of up to ``max_gap`` s gives gap bins, and a clock step (back, or forward by more
than ``max_gap``) re-anchors the frames after it ``dt``-aligned past the bins before it.
The per-frame path (:mod:`~gyrostand.can.receive.frames`) accepts the common case
inline and hands every other data frame here.
"""

from __future__ import annotations

import logging
import math

from gyrostand.can.receive.state import Held, ReceiveState

__all__ = ["FrameTiming"]

log = logging.getLogger(__name__)

_NEG_INF = -math.inf


class FrameTiming(ReceiveState):
    """The timing rule (:meth:`_timed`) and the acceptance of a timed frame into the
    FIFO; :meth:`settle` at the end of the frames. The caller holds the lock, except
    for :meth:`settle`, which takes it."""

    def _timed(self, frame: Held) -> None:
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

    def _accept(self, frame: Held) -> None:
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
