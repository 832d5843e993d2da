"""Frames from a 1-s truth: the stand's electronics, simulated for any DBC layout.

Input per gyro: arrays ``t`` (s, from 0, step Δt), ``drift`` (the drift signal's unit,
deg/h in our DBC) and ``temp`` (degC), e.g. from ``gyrostand.core.simulation``. Output: a
time-ordered iterator of :class:`can.Message`, encoded by cantools.

Channels that the mapping puts in the same message and multiplexer value form one
*stream* (one frame carries all of them); each stream sends at the highest rate of its
channels. Frame j of a stream has timestamp ``start + (j + 0.5)/rate + u_j`` with
``u_j ~ U(-jitter, +jitter)`` (``jitter < 0.5/rate`` keeps frames inside their slots and
in order), and carries the truth at that time, held from the last 1-s point (``hold``: the
mean of a bin then equals the truth point, up to quantization) or linearly interpolated
(``linear``). Each value is rounded to the sensor's quantization step, saturated to the
DBC range, and encoded (which rounds to the DBC resolution). Each frame is dropped with
probability ``drop`` (its rolling counter still advances, as on a real bus). Streams are
merged by timestamp. Everything is seeded; nothing reads the wall clock.

:class:`BadFrameInjector` adds deterministic bad frames for tests, each of a kind the
decoder must reject for a known reason.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import can
import numpy as np
from cantools.database.can import Database, Signal
from cantools.database.can import Message as CanMessage

from gyrostand.can.dbc import SignalRef, frame_key
from gyrostand.can.routes import ChannelMap
from gyrostand.errors import BusUnavailableError, CanEdgeError

__all__ = ["Truth", "FrameSimOptions", "generate_frames", "send_frames", "write_log",
           "BadFrameInjector", "BAD_KINDS"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Truth:
    """1-s truth of one gyro: ``t`` (s, shape (n,), increasing, shared by all gyros),
    ``drift`` and ``temp`` of the same shape."""

    t: np.ndarray
    drift: np.ndarray
    temp: np.ndarray

    def __post_init__(self) -> None:
        for name in ("t", "drift", "temp"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=float))
        if not (self.t.ndim == 1 and self.t.shape == self.drift.shape == self.temp.shape):
            raise ValueError("t, drift and temp must be 1-D arrays of one length")
        if self.t.size < 1 or np.any(np.diff(self.t) <= 0):
            raise ValueError("t must be non-empty and strictly increasing")


@dataclass(frozen=True)
class FrameSimOptions:
    """Rates (Hz) of the drift and temperature channels; ``jitter`` half-width (s);
    ``drop`` probability; sensor quantization steps (physical units, 0 = none);
    ``start`` timestamp (s) of truth t = 0; ``seed`` of the generator.

    The one owner of these fields: a session's ``simulate:`` section
    (:class:`gyrostand.config.SimulateConfig`) is these options and the truth."""

    drift_rate: float = 100.0
    temperature_rate: float = 10.0
    interpolation: str = "hold"
    jitter: float = 0.0
    drop: float = 0.0
    drift_quantization: float = 0.0
    temperature_quantization: float = 0.0
    start: float = 1_700_000_000.0
    seed: int = 0

    def __post_init__(self) -> None:
        for r in (self.drift_rate, self.temperature_rate):
            if not 0 < r <= 100_000:
                raise ValueError(f"frame rate {r!r} Hz out of range")
        if self.interpolation not in ("hold", "linear"):
            raise ValueError(f"interpolation must be 'hold' or 'linear', not "
                             f"{self.interpolation!r}")
        if not 0 <= self.jitter < 0.5 / max(self.drift_rate, self.temperature_rate):
            raise ValueError("jitter must be in [0, half the shortest frame period)")
        if not 0 <= self.drop < 1:
            raise ValueError("drop must be in [0, 1)")

    @classmethod
    def from_config(cls, sim: FrameSimOptions) -> FrameSimOptions:
        """The frame options alone of ``sim`` (a :class:`gyrostand.config.SimulateConfig`,
        which extends these options with the truth)."""
        return cls(**{f.name: getattr(sim, f.name) for f in fields(cls)})


@dataclass
class _Stream:
    ref: SignalRef
    rate: float
    members: list[tuple[int, int, SignalRef]] = field(default_factory=list)
    counters: list[SignalRef] = field(default_factory=list)


def _streams(channels: ChannelMap, opts: FrameSimOptions) -> list[_Stream]:
    streams: dict[tuple[int, int | None], _Stream] = {}
    for g, pair in enumerate(channels.signals):
        for c, ref in enumerate(pair):
            rate = opts.drift_rate if c == 0 else opts.temperature_rate
            mux = ref.multiplexer_ids[0] if ref.multiplexer_ids else None
            key = (ref.message.key, mux)
            st = streams.setdefault(key, _Stream(ref, rate))
            st.rate = max(st.rate, rate)
            st.members.append((g, c, ref))
            cnt = channels.counters[g][c] if channels.counters else None
            if cnt is not None and all(x.name != cnt.name for x in st.counters):
                st.counters.append(cnt)
    return list(streams.values())


def _values(truth: Truth, channel: int, tf: np.ndarray, opts: FrameSimOptions,
            ref: SignalRef, conv=None) -> np.ndarray:
    y = truth.drift if channel == 0 else truth.temp
    if opts.interpolation == "hold":
        idx = np.clip(np.searchsorted(truth.t, tf, side="right") - 1, 0, y.size - 1)
        v = y[idx]
    else:
        v = np.interp(tf, truth.t, y)
    q = opts.drift_quantization if channel == 0 else opts.temperature_quantization
    if q > 0:
        v = np.round(v / q) * q
    if conv is not None:  # the truth is in the session's units, the DBC in its own
        v = (v - conv.offset) / conv.scale
    lo = -np.inf if ref.minimum is None else ref.minimum
    hi = np.inf if ref.maximum is None else ref.maximum
    out = (v < lo) | (v > hi)
    if out.any():  # never silently: the simulated stand saturates what the DBC cannot carry
        log.warning("simulated %s.%s: %d of %d values outside its DBC range [%g, %g] "
                    "(%g .. %g), saturated", ref.message.name, ref.name,
                    int(out.sum()), v.size, lo, hi, float(np.nanmin(v)), float(np.nanmax(v)))
    return np.clip(v, lo, hi)


def generate_frames(db: Database, channels: ChannelMap, truths: Sequence[Truth],
                    opts: FrameSimOptions = FrameSimOptions()) -> Iterator[can.Message]:
    """Frames for every mapped channel of every gyro, merged in timestamp order.

    ``truths[g]`` belongs to ``channels.gyros[g]``; all share one time grid.
    """
    if len(truths) != len(channels.gyros):
        raise ValueError(f"{len(truths)} truths for {len(channels.gyros)} gyros")
    t = truths[0].t
    if any(tr.t.shape != t.shape or np.any(tr.t != t) for tr in truths):
        raise ValueError("all truths must share one time grid")
    step = float(t[1] - t[0]) if t.size > 1 else 1.0
    span = float(t[-1] - t[0]) + step
    from gyrostand.can.bus import FrameEncoder  # here: the options load light (the config's)

    rng = np.random.default_rng(opts.seed)
    enc = FrameEncoder(db)
    streams = _streams(channels, opts)
    times, sid, idx, payload_rows = [], [], [], []
    for s, st in enumerate(streams):
        n = int(math.floor(span * st.rate + 1e-9))
        j = np.arange(n)
        tf = float(t[0]) + (j + 0.5) / st.rate
        if opts.jitter > 0:
            tf = tf + rng.uniform(-opts.jitter, opts.jitter, n)
        keep = rng.random(n) >= opts.drop if opts.drop > 0 else np.ones(n, bool)
        cols = [_values(truths[g], c, tf, opts, ref,
                        channels.convert[g][c] if channels.convert else None).tolist()
                for g, c, ref in st.members]
        payload_rows.append((cols, j))
        times.append(tf[keep])
        sid.append(np.full(int(keep.sum()), s, dtype=np.int32))
        idx.append(j[keep])
    if not times:
        return
    all_t = np.concatenate(times)
    order = np.argsort(all_t, kind="stable")
    all_t = (all_t[order] + opts.start).tolist()
    all_s = np.concatenate(sid)[order].tolist()
    all_j = np.concatenate(idx)[order].tolist()
    prepared = []
    for st, (cols, _) in zip(streams, payload_rows, strict=True):
        first = {ref.name: cols[m][0] for m, (_, _, ref) in enumerate(st.members)}
        msg, template = enc.signal_values(st.ref.message, {
            **({st.ref.multiplexer: st.ref.multiplexer_ids[0]} if st.ref.multiplexer else {}),
            **first})
        names = [ref.name for _, _, ref in st.members]
        mods = [(cn.name, int(cn.maximum) + 1 if cn.maximum is not None else 256)
                for cn in st.counters]
        prepared.append((msg, template, names, cols, mods, msg.frame_id,
                         bool(msg.is_extended_frame)))
    for ts, s, j in zip(all_t, all_s, all_j, strict=True):
        msg, template, names, cols, mods, fid, ext = prepared[s]
        data = dict(template)
        for name, col in zip(names, cols, strict=True):
            data[name] = col[j]
        for cname, mod in mods:
            data[cname] = j % mod
        yield can.Message(timestamp=ts, arbitration_id=fid, is_extended_id=ext,
                          data=msg.encode(data, strict=False), is_rx=False)


def send_frames(bus: can.BusABC, frames: Iterable[can.Message], realtime: bool = False,
                speed: float = 1.0, timeout: float | None = 5.0) -> int:
    """Send frames on ``bus`` (paced to their timestamps when ``realtime``); returns the
    count. With a ``virtual`` bus, open the sender with ``preserve_timestamps=True`` so the
    receivers see the simulated timestamps."""
    if realtime:
        from gyrostand.can.replay import paced

        frames = paced(frames, speed)
    n = 0
    for f in frames:
        try:
            bus.send(f, timeout=timeout)
        except Exception as exc:
            raise BusUnavailableError(f"cannot send simulated frame on {bus.channel_info}: "
                                      f"{exc}") from exc
        n += 1
    return n


def write_log(path: str | Path, frames: Iterable[can.Message]) -> int:
    """Write frames to a log file; the suffix picks the python-can writer (.blf, .asc,
    .log, .csv, ...). Frames with a non-finite timestamp cannot be stored and are skipped.
    Returns the count written."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        writer = can.Logger(path)
    except Exception as exc:
        raise CanEdgeError(f"{path}: cannot write CAN log: {exc}") from exc
    n = 0
    try:
        for f in frames:
            if math.isfinite(f.timestamp):
                writer.on_message_received(f)
                n += 1
    finally:
        writer.stop()
    return n


#: Kinds of bad frame and the decoder's rejection reason for each.
BAD_KINDS = {
    "wrong_dlc": "wrong_dlc",
    "unknown_id": "unknown_id",
    "out_of_range": "out_of_range",
    "bad_mux": "undecodable",
    "error_frame": "error_frame",
    "remote_frame": "remote_frame",
    "non_monotonic": "non_monotonic",
    "bad_timestamp": "bad_timestamp",
}


class BadFrameInjector:
    """After every ``every``-th frame, insert one bad frame derived from it, cycling
    through ``kinds`` (keys of :data:`BAD_KINDS`); kinds that cannot be made from a frame
    (``bad_mux`` of a plain message, ``out_of_range`` of a signal whose raw range fits the
    DBC range) are skipped for that frame. :attr:`expected` counts, by decoder reason, the
    rejections the inserted frames must cause."""

    def __init__(self, db: Database, channels: ChannelMap, every: int = 50,
                 kinds: Sequence[str] = tuple(BAD_KINDS)) -> None:
        unknown = [k for k in kinds if k not in BAD_KINDS]
        if unknown:
            raise ValueError(f"unknown bad-frame kinds {unknown}")
        self.db, self.every, self.kinds = db, int(every), tuple(kinds)
        self.expected: Counter[str] = Counter()
        keys = {frame_key(m.frame_id, bool(m.is_extended_frame)) for m in db.messages}
        self._unknown_id = next(i for i in range(0x7FF, -1, -1) if i not in keys)
        self._mapped: dict[int, list[SignalRef]] = {}
        for pair in channels.signals:
            for ref in pair:
                self._mapped.setdefault(ref.message.key, []).append(ref)
        self._by_key = {frame_key(m.frame_id, bool(m.is_extended_frame)): m
                        for m in db.messages}

    def __call__(self, frames: Iterable[can.Message]) -> Iterator[can.Message]:
        k = 0
        for n, f in enumerate(frames, 1):
            yield f
            if n % self.every:
                continue
            for _ in range(len(self.kinds)):
                kind = self.kinds[k % len(self.kinds)]
                k += 1
                bad = self._make(kind, f)
                if bad is not None:
                    self.expected[BAD_KINDS[kind]] += 1
                    yield bad
                    break

    def _make(self, kind: str, f: can.Message) -> can.Message | None:
        def copy(**kw) -> can.Message:
            base: dict[str, Any] = dict(
                timestamp=f.timestamp, arbitration_id=f.arbitration_id,
                is_extended_id=f.is_extended_id, data=bytes(f.data), is_rx=f.is_rx)
            base.update(kw)
            return can.Message(**base)

        key = frame_key(f.arbitration_id, f.is_extended_id)
        msg = self._by_key.get(key)
        if kind == "wrong_dlc":
            d = bytes(f.data)
            return copy(data=d[:-1] if len(d) > 1 else d + b"\0")
        if kind == "unknown_id":
            return copy(arbitration_id=self._unknown_id, is_extended_id=False)
        if kind == "error_frame":
            return can.Message(timestamp=f.timestamp, is_error_frame=True)
        if kind == "remote_frame":
            return copy(is_remote_frame=True, data=None, dlc=len(f.data))
        if kind == "non_monotonic":
            return copy(timestamp=f.timestamp - 1e-3)
        if kind == "bad_timestamp":
            return copy(timestamp=math.nan)
        if msg is None or key not in self._mapped:
            return None
        raw: dict[str, Any] = dict(
            msg.decode(bytes(f.data), decode_choices=False, scaling=False))  # type: ignore[arg-type]
        if kind == "bad_mux":
            mux = next((s for s in msg.signals if s.is_multiplexer), None)
            if mux is None:
                return None
            used = {i for s in msg.signals for i in (s.multiplexer_ids or ())}
            free = [v for v in range(1 << mux.length) if v not in used]
            if not free:
                return None
            # a one-signal cantools message packs the undefined multiplexer value
            lone = CanMessage(frame_id=msg.frame_id, name="BAD_MUX", length=msg.length,
                              signals=[Signal(mux.name, mux.start, mux.length,
                                              mux.byte_order, mux.is_signed)],
                              is_extended_frame=msg.is_extended_frame, strict=False)
            return copy(data=self._encode_raw(lone, {mux.name: free[0]}))
        if kind == "out_of_range":
            for ref in self._mapped[key]:
                if ref.name not in raw:
                    continue
                sig = msg.get_signal_by_name(ref.name)
                if sig.is_float:
                    raw[ref.name] = math.inf
                    return copy(data=self._encode_raw(msg, raw))
                lo_raw = -(1 << (sig.length - 1)) if sig.is_signed else 0
                hi_raw = (1 << (sig.length - 1)) - 1 if sig.is_signed else (1 << sig.length) - 1
                for r in (hi_raw, lo_raw):
                    phys = r * sig.scale + sig.offset
                    if not ref.in_range(phys):
                        raw[ref.name] = r
                        return copy(data=self._encode_raw(msg, raw))
            return None
        return None

    @staticmethod
    def _encode_raw(msg, raw: dict) -> bytes:
        return msg.encode(raw, scaling=False, strict=False)
