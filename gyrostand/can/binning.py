"""Bins of Δt from frame timestamps (the numerics; ``samples.csv`` is written and read by
:mod:`gyrostand.runfolder`).

Bin k covers ``[t0 + k·Δt, t0 + (k+1)·Δt)``; ``t0`` is the configured epoch, or else the
first timestamp seen (any gyro) floored to a multiple of Δt, so every gyro shares one grid.
Each gyro's series starts at the bin of its own first sample. A bin holds the mean and the
count of each channel; it closes when a sample of that gyro with a later bin index arrives,
or on :meth:`Binner.flush`. Bins skipped over are emitted as gaps (NaN mean, count 0): data
are never invented. A sample whose bin is already closed is *late*: counted and dropped,
so each gyro's series is strictly increasing in k and closed bins never change.

A record's ``t`` is the **start** of its bin, ``t0 + k·Δt`` (s), and ``drift``/``temp`` are
the plain means of the samples in ``[t, t + Δt)``.

Work per sample is constant; closing bins costs one record per bin (gaps included), and a
forward jump of more than ``max_gap`` seconds is refused (counted as ``jumps``) so a wild
timestamp cannot emit millions of gap rows.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

__all__ = ["Bin", "Binner", "BinStats"]

log = logging.getLogger(__name__)


class Bin(NamedTuple):
    """One closed bin of one gyro. ``t`` start of the bin (s), ``k`` its index on the grid,
    ``drift`` mean drift (DBC unit, deg/h) and ``temp`` mean temperature (degC), NaN when
    the matching count is 0."""

    gyro: str
    t: float
    k: int
    drift: float
    temp: float
    n_drift: int
    n_temp: int

    @property
    def is_gap(self) -> bool:
        return self.n_drift == 0 or self.n_temp == 0


@dataclass(frozen=True)
class BinStats:
    """``bins`` closed (gaps included), ``gaps`` bins with an empty channel, ``late``
    samples dropped because their bin was closed, ``jumps`` samples refused for a forward
    jump beyond ``max_gap``."""

    bins: int
    gaps: int
    late: int
    jumps: int


class _Open:
    __slots__ = ("k", "s0", "n0", "s1", "n1")

    def __init__(self, k: int) -> None:
        self.k = k
        self.s0 = self.s1 = 0.0
        self.n0 = self.n1 = 0


class Binner:
    """Bin decoded samples ``(gyro index, channel, t, value)`` of ``gyros`` at ``dt`` s."""

    def __init__(self, gyros: Sequence[str], dt: float = 1.0, epoch: float | None = None,
                 max_gap: float = 3600.0) -> None:
        if not dt > 0:
            raise ValueError(f"dt must be > 0, got {dt!r}")
        self.gyros = tuple(gyros)
        self.dt = float(dt)
        self.t0: float | None = None if epoch is None else float(epoch)
        self.max_gap_bins = max(1, int(max_gap / dt))
        self._open: list[_Open | None] = [None] * len(self.gyros)
        self._floor: list[int | None] = [None] * len(self.gyros)
        self._rebase = [False] * len(self.gyros)
        self._bins = self._gaps = self._late = self._jumps = 0

    def resume_after(self, t0: float, last_k: dict[str, int]) -> None:
        """Continue a series already written (a resumed run): ``t0`` the grid origin (s),
        ``last_k[gyro]`` the index of its last written bin. A later sample of that gyro at
        or before that bin is late; the first one after it emits the bins in between as
        gaps (when no more than ``max_gap`` apart; else the series jumps)."""
        self.t0 = float(t0)
        for g, name in enumerate(self.gyros):
            if name in last_k and self._open[g] is None:
                self._floor[g] = int(last_k[name])

    def rebase(self) -> None:
        """After a bus outage: the next sample of each gyro may jump forward further than
        ``max_gap`` (the bins up to the jump are closed, the series continues after it;
        a shorter outage shows as gap bins as usual)."""
        self._rebase = [True] * len(self.gyros)

    def _close(self, g: int, b: _Open) -> Bin:
        d = b.s0 / b.n0 if b.n0 else math.nan
        tm = b.s1 / b.n1 if b.n1 else math.nan
        self._bins += 1
        if not (b.n0 and b.n1):
            self._gaps += 1
        t0 = self.t0 if self.t0 is not None else 0.0  # set by the first add()
        return Bin(self.gyros[g], t0 + b.k * self.dt, b.k, d, tm, b.n0, b.n1)

    def add(self, g: int, channel: int, t: float, value: float, out: list[Bin]) -> None:
        """Add one sample; bins it closes are appended to ``out`` in time order."""
        if self.t0 is None:
            self.t0 = math.floor(t / self.dt) * self.dt
        k = math.floor((t - self.t0) / self.dt)
        b = self._open[g]
        if b is None:
            fl = self._floor[g]
            if fl is not None:  # resumed: continue after the last written bin
                if k <= fl:
                    self._late += 1
                    return
                self._floor[g] = None
                if k - fl - 1 <= self.max_gap_bins:
                    for kk in range(fl + 1, k):
                        out.append(self._close(g, _Open(kk)))
            b = self._open[g] = _Open(k)
        elif k != b.k:
            if k < b.k:
                self._late += 1
                return
            if k - b.k > self.max_gap_bins:
                if not self._rebase[g]:
                    self._jumps += 1
                    return
                out.append(self._close(g, b))  # after an outage: the series jumps
                b = self._open[g] = _Open(k)
            else:
                out.append(self._close(g, b))
                for kk in range(b.k + 1, k):
                    out.append(self._close(g, _Open(kk)))
                b = self._open[g] = _Open(k)
            self._rebase[g] = False
        if channel == 0:
            b.s0 += value
            b.n0 += 1
        else:
            b.s1 += value
            b.n1 += 1

    def add_many(self, samples: Iterable[tuple[int, int, float, float]]) -> list[Bin]:
        """Add samples (e.g. :meth:`DecodingListener.drain` output); return closed bins."""
        out: list[Bin] = []
        add, opened, floor, dt = self.add, self._open, math.floor, self.dt
        t0 = self.t0
        for g, c, t, v in samples:
            # add()'s common case inlined (the sample falls in its gyro's open bin): the
            # same bin index expression, the same sums
            if t0 is not None:
                b = opened[g]
                if b is not None and floor((t - t0) / dt) == b.k:
                    if c == 0:
                        b.s0 += v
                        b.n0 += 1
                    else:
                        b.s1 += v
                        b.n1 += 1
                    continue
            add(g, c, t, v, out)
            t0 = self.t0
        return out

    def add_arrays(self, g: Any, c: Any, t: Any, v: Any) -> list[Bin]:
        """:meth:`add_many` of the samples ``zip(g, c, t, v)`` given as numpy arrays (in
        arrival order): the same bins, counts and sums, bit for bit.

        Per gyro, a sample whose bin index differs from its previous sample's (or its
        gyro's first here) is an *event* and goes through :meth:`add`, in arrival order
        (only events close or open bins). The samples after an event up to the gyro's
        next one share its index: when the event left its gyro's open bin at that index,
        they fall in it and are summed into it in order (``cumsum`` adds one after the
        other, as ``+=`` does); else (a late or refused event) each goes through
        :meth:`add` too."""
        import numpy as np

        out: list[Bin] = []
        n = len(t)
        if n and self.t0 is None:  # the first sample sets the grid
            self.add(int(g[0]), int(c[0]), float(t[0]), float(v[0]), out)
            g, c, t, v = g[1:], c[1:], t[1:], v[1:]
            n -= 1
        if not n:
            return out
        k = np.floor((t - self.t0) / self.dt)
        events: list[tuple[int, int, Any]] = []  # (position, gyro, the run after it)
        for gi in np.unique(g).tolist():
            idx = np.flatnonzero(g == gi)
            kg = k[idx]
            starts = np.flatnonzero(np.concatenate(([True], kg[1:] != kg[:-1]))).tolist()
            ends = starts[1:] + [len(idx)]
            events += [(int(idx[a]), gi, idx[a + 1:b]) for a, b in zip(starts, ends,
                                                                       strict=True)]
        events.sort(key=lambda e: e[0])
        add, opened = self.add, self._open
        for i, gi, run in events:
            add(gi, int(c[i]), float(t[i]), float(v[i]), out)
            if not len(run):
                continue
            b = opened[gi]
            if b is not None and b.k == int(k[i]):
                cr, vr = c[run], v[run]
                zero = cr == 0
                v0, v1 = vr[zero], vr[~zero]
                if len(v0):
                    b.s0 = float(np.concatenate(([b.s0], v0)).cumsum()[-1])
                    b.n0 += len(v0)
                if len(v1):
                    b.s1 = float(np.concatenate(([b.s1], v1)).cumsum()[-1])
                    b.n1 += len(v1)
            else:
                for j in run.tolist():
                    add(gi, int(c[j]), float(t[j]), float(v[j]), out)
        return out

    def flush(self, until_t: float | None = None) -> list[Bin]:
        """Close bins that end at or before ``until_t`` (s; gaps up to it for every gyro
        that has started), or, with None, every open bin (end of run)."""
        out: list[Bin] = []
        if self.t0 is None:
            return out
        for g, b in enumerate(self._open):
            if b is None:
                continue
            if until_t is None:
                out.append(self._close(g, b))
                self._open[g] = _Open(b.k + 1)
                continue
            k_end = math.floor((until_t - self.t0) / self.dt)  # bin containing until_t
            if k_end <= b.k:
                continue
            k_end = min(k_end, b.k + self.max_gap_bins)
            out.append(self._close(g, b))
            for kk in range(b.k + 1, k_end):
                out.append(self._close(g, _Open(kk)))
            self._open[g] = _Open(k_end)
        out.sort(key=lambda r: r.k)
        return out

    def stats(self) -> BinStats:
        return BinStats(self._bins, self._gaps, self._late, self._jumps)
