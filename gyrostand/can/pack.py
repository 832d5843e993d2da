"""Payload packers for the daemon's frames: cantools' bit layout, built once per message.

cantools encodes a frame by converting every signal to its raw value and packing them
with bitstruct twice (a big-endian and a little-endian format string), through a few
layers of Python per call. The daemon encodes a few message types thousands of times (a
replay of a 6-h log: ~10,000 result, summary and status frames). Here each signal's raw
value still comes from cantools' own conversion (``numeric_scaled_to_raw``: the same
scaling and rounding), and only the bit placement is ours, the inverse of
:mod:`gyrostand.can.receive.extract`'s extractors:

    Intel signal, start bit s, length L:     N_little |= (raw & (2^L − 1)) << s
    Motorola signal, network start bit n:    N_big    |= (raw & (2^L − 1)) << (8·len − n − L)

with a float signal's raw being the bits of its IEEE value, and the payload the two
integers' bytes OR-ed. A raw value outside its field (where bitstruct raises), a float
beyond float32 (where bitstruct stores inf), a multiplexer value the message does not
list, or anything else outside this scheme returns None, and the caller encodes with
cantools (which raises or packs as it always did). :func:`packer` checks the packer on
random values of every signal against ``Message.encode`` when it is built and declines
(None: cantools for every frame of that message) on any difference.
"""

from __future__ import annotations

import random
import struct
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["packer", "draws"]

#: random value sets checked against cantools when a packer is built
CHECKS = 32

Pack = Callable[[Mapping[str, float]], "bytes | None"]

_F32 = struct.Struct(">f").pack
_F64 = struct.Struct(">d").pack


def _start_bit(signal: Any) -> int:
    """cantools' network bit number of a signal's first bit (``utils.start_bit``)."""
    if signal.byte_order == "big_endian":
        return 8 * (signal.start // 8) + (7 - (signal.start % 8))
    return int(signal.start)


def _field(signal: Any, nbytes: int) -> tuple | None:
    """(little, shift, mask, lo, hi, float bytes packer or None, to_raw) of a signal, or
    None outside this scheme."""
    L = int(signal.length)
    conv = signal.conversion
    if L <= 0 or conv is None:
        return None
    little = signal.byte_order == "little_endian"
    shift = int(signal.start) if little else 8 * nbytes - _start_bit(signal) - L
    if shift < 0 or shift + L > 8 * nbytes:
        return None
    fbytes = None
    if conv.is_float:
        if L not in (32, 64):
            return None
        fbytes = _F32 if L == 32 else _F64
        lo = hi = 0
    elif signal.is_signed:
        lo, hi = -(1 << (L - 1)), (1 << (L - 1)) - 1
    else:
        lo, hi = 0, (1 << L) - 1
    return little, shift, (1 << L) - 1, lo, hi, fbytes, conv.numeric_scaled_to_raw


def _build(message: Any) -> Pack | None:
    if getattr(message, "is_container", False):
        return None
    nbytes = int(message.length)
    fields: dict[str, tuple] = {}
    mux_ids: dict[str, set[int]] = {}
    for s in message.signals:
        if s.name in fields:
            return None
        f = _field(s, nbytes)
        if f is None:
            return None
        fields[s.name] = f
        if s.multiplexer_ids:
            mux_ids.setdefault(s.multiplexer_signal, set()).update(s.multiplexer_ids)
    muxes = tuple(mux_ids.items())
    by_name = {s.name: s for s in message.signals}
    branches: dict[tuple[int, ...], frozenset[str]] = {}

    def branch(key: tuple[int, ...]) -> frozenset[str]:
        """The signals cantools encodes when the multiplexers hold ``key``."""
        sel = dict(zip(mux_ids, key, strict=True))

        def active(s: Any) -> bool:
            return not s.multiplexer_ids or (active(by_name[s.multiplexer_signal])
                                             and sel[s.multiplexer_signal]
                                             in s.multiplexer_ids)
        return frozenset(s.name for s in message.signals if active(s))

    def pack(values: Mapping[str, float]) -> bytes | None:
        if muxes:
            for name, ids in muxes:  # cantools refuses a value that selects no branch
                if name not in values or int(values[name]) not in ids:
                    return None
            key = tuple(int(values[name]) for name, _ in muxes)
            want = branches.get(key)
            if want is None:
                want = branches[key] = branch(key)
            if values.keys() != want:  # cantools needs exactly these (or raises)
                return None
        elif len(values) != len(fields):
            return None
        nl = nb = 0
        for name, v in values.items():
            f = fields.get(name)
            if f is None:
                return None
            little, shift, mask, lo, hi, fbytes, to_raw = f
            raw = to_raw(v)
            if fbytes is not None:
                try:
                    bits = int.from_bytes(fbytes(raw), "big")
                except (OverflowError, struct.error):
                    return None
            elif type(raw) is int and lo <= raw <= hi:
                bits = raw & mask
            else:
                return None
            if little:
                nl |= bits << shift
            else:
                nb |= bits << shift
        if nl:
            nb |= int.from_bytes(nl.to_bytes(nbytes, "little"), "big")
        return nb.to_bytes(nbytes, "big")

    return pack


def draws(message: Any, rng: random.Random, n: int) -> list[dict[str, float]]:
    """``n`` random signal-value dicts of ``message`` as :meth:`FrameEncoder.signal_values`
    gives them: every signal of the branch a random multiplexer value selects, each a
    value its field holds (integer signals on their scale's grid, floats any float32)."""
    by_name = {s.name: s for s in message.signals}
    return [_draw(message, by_name, rng) for _ in range(n)]


def _draw(message: Any, by_name: dict[str, Any], rng: random.Random) -> dict[str, float]:
    values: dict[str, float] = {}

    def value(s: Any) -> float:
        if s.name not in values:
            L = int(s.length)
            if s.conversion.is_float:
                x: float = struct.unpack(">f", _F32(rng.uniform(-1e6, 1e6)))[0]
                if rng.random() < 0.1:
                    x = rng.choice((0.0, -0.0, float("nan"), float("inf")))
                values[s.name] = x
                return x
            ids = sorted({i for t in message.signals if t.multiplexer_signal == s.name
                          for i in (t.multiplexer_ids or ())})
            if s.is_multiplexer and ids:
                r = rng.choice(ids)
            elif s.is_signed:
                r = rng.randint(-(1 << (L - 1)), (1 << (L - 1)) - 1)
            else:
                r = rng.randint(0, (1 << L) - 1)
            values[s.name] = r * s.scale + s.offset
        return values[s.name]

    def active(s: Any) -> bool:
        if not s.multiplexer_ids:
            return True
        mux = by_name[s.multiplexer_signal]
        return active(mux) and int(value(mux)) in s.multiplexer_ids

    return {s.name: value(s) for s in message.signals if active(s)}


def agrees_with_cantools(message: Any, pack: Pack, rng: random.Random, n: int) -> bool:
    """Whether ``pack`` gives cantools' ``encode(values, strict=False)`` bytes on ``n``
    random value sets (those it declines, None, count as agreeing: cantools packs them)."""
    for values in draws(message, rng, n):
        try:
            want = bytes(message.encode(values, strict=False))
        except Exception:  # noqa: BLE001 - cantools refuses: ours must decline too
            want = None
        try:
            got = pack(values)
        except Exception:  # noqa: BLE001
            return False
        if got is not None and got != want:
            return False
    return True


def packer(message: Any) -> Pack | None:
    """``pack(values) -> payload`` of a cantools ``message`` (a dict of every active signal's
    physical value, as :meth:`~gyrostand.can.bus.FrameEncoder.signal_values` gives), equal
    to ``message.encode(values, strict=False)``, or None for a value set it leaves to
    cantools; None (no packer) for a container, a signal of an unsupported kind, or a
    packer that disagrees with cantools on a random check."""
    pack = _build(message)
    if pack is None:
        return None
    if not agrees_with_cantools(message, pack, random.Random(message.frame_id), CHECKS):
        return None
    return pack
