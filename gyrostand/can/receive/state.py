"""What the receive path's parts share: the listener's state, named and typed once.

:class:`ReceiveState` declares every attribute the parts of
:class:`~gyrostand.can.receive.listener.DecodingListener` read and write (its
constructor sets them), and owns the routing of a frame key to its
:class:`~gyrostand.can.routes.Route` (J1939 PGN matching and its one-time hint). The
parts (:mod:`~gyrostand.can.receive.timing`, :mod:`~gyrostand.can.receive.commands`,
:mod:`~gyrostand.can.receive.frames`, :mod:`~gyrostand.can.receive.arrays`) extend it,
each with one concern; the lock is the caller's: every method here runs with it held.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from typing import TYPE_CHECKING

from gyrostand.can.dbc import EXTENDED_KEY_BIT, j1939_pgn
from gyrostand.can.receive.counts import Counts, Rejections

if TYPE_CHECKING:
    from gyrostand.can.routes import ChannelMap, Route

__all__ = ["ReceiveState", "Sample", "Held", "UNRANGED_LIMIT", "MAX_ROUTES", "MAX_UNKNOWN_IDS",
           "DRIFT", "TEMP"]

log = logging.getLogger(__name__)

DRIFT, TEMP = 0, 1

#: a decoded sample: (gyro index, channel index, timestamp s, value)
Sample = tuple[int, int, float, float]
#: a data frame waiting for its time to be confirmed: (timestamp, route, samples with the
#: frame's own timestamp, rolling counters (key, value, modulus))
Held = tuple[float, "Route", list[Sample], list[tuple[tuple[int, int], int, int]]]
#: the largest |value| of a mapped signal whose DBC gives no range (a payload beyond it is
#: garbage, e.g. a float32 near its 3.4e38 limit; it would overflow the estimators)
UNRANGED_LIMIT = 1e12
#: routes at most (ids cached for `match: pgn`: 8 priorities x 256 source addresses each)
MAX_ROUTES = 65536
#: distinct ids not in the DBC counted one by one (the ones past it only in ``unknown_id``)
MAX_UNKNOWN_IDS = 1024


class ReceiveState:
    """The decoding listener's state (set by its constructor; guarded by ``_lock``).

    Configuration: ``channels``, ``capacity`` (samples), ``max_gap``, ``dt`` and
    ``window`` (s), ``confirm`` (frames that agree on a new time). Timing: ``_anchor``
    (newest accepted timestamp since the last clock step), ``_offset`` (s added to
    timestamps since then, k·dt), ``_held`` (frames waiting for confirmation),
    ``_steps`` (clock steps). FIFO: ``_buf`` (sample tuples), then ``_chunks`` (the array
    path's ``(gyro, channel, t, value)`` arrays, ``_nchunked`` samples in them).
    Counters by name: ``_n`` (:class:`Counts`), ``_rej`` (:class:`Rejections`).
    Routing: ``_routes`` (frame key -> route), ``_known`` (every key of the DBC),
    ``_by_pgn`` / ``_pgn_hint`` (J1939), ``_last_counter`` (rolling counter per
    (gyro, channel)), ``_unknown`` (frames per key not in the DBC, at most
    :data:`MAX_UNKNOWN_IDS` keys).
    """

    channels: ChannelMap
    capacity: int
    max_gap: float
    dt: float
    window: float
    confirm: int
    _anchor: float
    _offset: float
    _held: list[Held]
    _steps: int
    _outliers_logged: int
    _buf: list[Sample]
    _chunks: list[tuple]
    _nchunked: int
    _commands: deque
    _command_capacity: int
    _lock: threading.Lock
    _routes: dict[int, Route]
    _known: set[int]
    _last_counter: dict[tuple[int, int], int]
    _by_pgn: dict[int, Route | dict[int, Route]]
    _first_sa: dict[int, int]
    _foreign: dict[int, bool]
    _pinned: dict[int, tuple[int, int]]
    _pgn_hint: dict[int, str]
    _hinted: set[int]
    _unknown: dict[int, int]
    _array_decode: dict[int, object]
    _table: tuple | None
    _committing: bool
    _n: Counts
    _rej: Rejections

    @property
    def last_timestamp(self) -> float:
        """Frame time (s): the newest accepted data frame's timestamp, shifted as the
        samples are after a clock step (so it never moves back); -inf before the first."""
        return self._anchor + self._offset

    def _pgn_route(self, key: int) -> Route | None:
        """The route of an extended id by its J1939 PGN (``match: pgn``), cached under the
        id; None for a standard id or another PGN."""
        if not key & EXTENDED_KEY_BIT or key in self._foreign:
            return None
        fid = key & ~EXTENDED_KEY_BIT
        pgn, sa = j1939_pgn(fid), fid & 0xFF
        entry = self._by_pgn.get(pgn)
        if entry is None:
            return None
        if isinstance(entry, dict):  # the session maps each source address
            route = entry.get(sa)
            if route is None:
                self._foreign_source(key, pgn, sa, None)
                return None
        else:
            route = entry
            first = self._first_sa.setdefault(pgn, sa)
            if first != sa:  # a second device on one mapping: never merged
                self._foreign_source(key, pgn, sa, first)
                return None
        if len(self._routes) < MAX_ROUTES:
            self._routes[key] = route
        return route

    def _foreign_source(self, key: int, pgn: int, sa: int, first: int | None) -> None:
        """Name once an id of a mapped PGN from a source address the session does not
        take: ``first`` None, the session maps other addresses (``source_address``):
        ignored, counted ``other_source``; else a second device on a mapping of any
        address, whose first device sent from ``first``: ``rejected.second_source``."""
        if len(self._foreign) >= MAX_UNKNOWN_IDS:
            return
        self._foreign[key] = first is None
        if first is None:
            log.warning("frames 0x%X: J1939 PGN 0x%X from source address 0x%02X, which no "
                        "channel maps (source_address): ignored (other_source)",
                        key & ~EXTENDED_KEY_BIT, pgn, sa)
        else:
            log.warning("frames 0x%X: J1939 PGN 0x%X from a second source address 0x%02X "
                        "(the first was 0x%02X): two devices on one `match: pgn` mapping; "
                        "only 0x%02X is decoded, these are rejected (second_source). Map "
                        "each address with source_address:", key & ~EXTENDED_KEY_BIT, pgn,
                        sa, first, first)

    def _count_unknown(self, key: int, n: int = 1) -> None:
        """Count ``n`` frames of ``key``, an id not in the DBC (by id while fewer than
        :data:`MAX_UNKNOWN_IDS` ids are counted)."""
        u = self._unknown
        if key in u:
            u[key] += n
        elif len(u) < MAX_UNKNOWN_IDS:
            u[key] = n

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

    def _unchunk(self) -> None:
        """The array path's samples into the FIFO as tuples (before a frame-by-frame
        sample follows them, or for a consumer of tuples); the caller holds the lock."""
        if self._chunks:
            for g, c, t, v in self._chunks:
                self._buf.extend(zip(g.tolist(), c.tolist(), t.tolist(), v.tolist(),
                                     strict=True))
            self._chunks, self._nchunked = [], 0

