"""Precompiled signal extractors: ``decode(data) -> {signal: value}`` for the few signals
of a DBC message that a session maps, at a per-frame cost that does not depend on the
DBC's byte order or signal widths.

cantools decodes a frame by unpacking *every* signal of the message with bitstruct (two
format strings, big- and little-endian, the payload reversed for the second) and then
scaling each one. A replay maps one or two signals per message, and a big-endian layout
of odd widths costs ~3x our own little-endian one in bitstruct. Here every mapped
signal becomes one shift and one mask of the payload read as one integer:

    N    = int.from_bytes(data, "little")           Intel signal, start bit s, length L
    raw  = (N >> s) & (2^L - 1)

    N    = int.from_bytes(data, "big")              Motorola signal, network start bit n
    raw  = (N >> (8·len(data) - n - L)) & (2^L - 1)   (n = cantools' ``start_bit``)

then ``raw - 2^L`` when signed and ``raw ≥ 2^(L-1)``, the bits read as an IEEE float for
a float signal, and ``raw * scale + offset`` with cantools' own conversion objects (the
same Python arithmetic cantools runs, so the values are identical to the last bit;
:func:`extractor` checks that on probe and random payloads and otherwise declines).
Multiplexed messages and containers are declined (``None``): the caller keeps cantools.
"""

from __future__ import annotations

import random
import struct
from collections.abc import Callable, Sequence
from typing import Any

__all__ = ["extractor", "agrees_with_cantools", "array_extractor", "agrees_with_cantools_arrays"]

#: random payloads checked against cantools when an extractor is built (plus 3 probes)
CHECKS = 64

Decode = Callable[[bytes | bytearray], dict]


def _start_bit(signal) -> int:
    """cantools' network bit number of a signal's first bit (``utils.start_bit``)."""
    if signal.byte_order == "big_endian":
        return 8 * (signal.start // 8) + (7 - (signal.start % 8))
    return signal.start


def _signal_source(i: int, signal, nbytes: int) -> tuple[list[str], str] | None:
    """Lines computing ``v{i}`` from ``nl``/``nb`` (payload as little/big-endian int), or
    None when the signal is outside this scheme."""
    L = int(signal.length)
    if L <= 0 or signal.multiplexer_ids or signal.is_multiplexer:
        return None
    conv = signal.conversion
    if conv is None:
        return None
    if signal.byte_order == "little_endian":
        shift, src = int(signal.start), "nl"
    else:
        shift, src = 8 * nbytes - _start_bit(signal) - L, "nb"
    if shift < 0 or shift + L > 8 * nbytes:
        return None
    mask = (1 << L) - 1
    expr = f"({src} >> {shift}) & {mask:#x}" if shift else f"{src} & {mask:#x}"
    lines = [f"r{i} = {expr}"]
    if getattr(conv, "is_float", False):
        if L not in (32, 64):
            return None
        lines.append(f"r{i} = _unpack_{L}(r{i}.to_bytes({L // 8}, 'big'))[0]")
    elif signal.is_signed:
        lines.append(f"if r{i} >> {L - 1}: r{i} -= {1 << L:#x}")
    kind = type(conv).__name__
    if kind == "IdentityConversion":
        value = f"r{i}"
    elif kind in ("LinearIntegerConversion", "LinearConversion"):
        value = f"r{i} * _s{i} + _o{i}"
    elif kind == "NamedSignalConversion":  # decode_choices=False: its linear part
        value = f"_c{i}(r{i}, False)"
    else:
        return None
    return lines, value


def extractor(message, names: Sequence[str]) -> Decode | None:
    """``decode(data) -> {name: value}`` of the signals ``names`` of a cantools
    ``message``, equal to ``message.decode_simple(data, False)`` restricted to them, or
    None when a signal is multiplexed, of an unsupported kind, or the compiled extractor
    disagrees with cantools on a check payload. The payload length is the caller's
    check (the route rejects a wrong DLC before decoding)."""
    if getattr(message, "is_container", False) or message.is_multiplexed() or not names:
        return None  # cantools decides which frames of a multiplexed message decode
    nbytes = int(message.length)
    by_name = {s.name: s for s in message.signals}
    env: dict[str, Any] = {"_fb": int.from_bytes, "_unpack_32": struct.Struct(">f").unpack,
                           "_unpack_64": struct.Struct(">d").unpack}
    body: list[str] = []
    items: list[str] = []
    uses: set[str] = set()
    for i, name in enumerate(dict.fromkeys(names)):
        sig = by_name.get(name)
        if sig is None:
            return None
        got = _signal_source(i, sig, nbytes)
        if got is None:
            return None
        lines, value = got
        body += lines
        uses.add("nl" if sig.byte_order == "little_endian" else "nb")
        conv = sig.conversion
        env[f"_s{i}"] = getattr(conv, "scale", 1)
        env[f"_o{i}"] = getattr(conv, "offset", 0)
        env[f"_c{i}"] = conv.raw_to_scaled
        items.append(f"{name!r}: {value}")
    head = []
    if "nl" in uses:
        head.append("nl = _fb(data, 'little')")
    if "nb" in uses:
        head.append("nb = _fb(data, 'big')")
    src = ("def decode(data):\n" + "".join(f"    {ln}\n" for ln in head + body)
           + "    return {" + ", ".join(items) + "}\n")
    exec(compile(src, f"<gyrostand extractor {message.name}>", "exec"), env)
    decode: Decode = env["decode"]
    decode.__doc__ = src
    if not agrees_with_cantools(message, decode, names):
        return None
    return decode


def agrees_with_cantools(message, decode: Decode, names: Sequence[str],
                         n: int = CHECKS, seed: int = 0x6A5) -> bool:
    """True when ``decode`` gives cantools' values (same type, same bits) for ``names``
    on the all-0, all-1 and counting payloads and on ``n`` random ones."""
    rng = random.Random(seed)
    length = int(message.length)
    probes = [bytes(length), b"\xff" * length, bytes(range(1, length + 1))]
    probes += [bytes(rng.getrandbits(8) for _ in range(length)) for _ in range(n)]
    for data in probes:
        try:
            want = message.decode_simple(data, False)
        except Exception:
            continue  # e.g. a payload cantools refuses: not a comparison
        got = decode(data)
        for name in names:
            a, b = got.get(name), want.get(name)
            if type(a) is not type(b) or not (a == b or (a != a and b != b)):
                return False
    return True


# -- the same extractors on arrays of payloads (the vectorized replay path) -------------

ArrayDecode = Callable[[Any], dict]


def _array_signal(signal, nbytes: int, as_int: bool):
    """``f(nl, nb) -> array`` of one signal from the payloads as uint64 arrays (little-
    and big-endian integers of the ``nbytes`` bytes): float64 values as ``float(v)`` of
    cantools' ``v`` would be, or int64 ``int(v)`` (``as_int``, integer conversions only);
    None when the signal is outside this scheme."""
    import numpy as np

    L = int(signal.length)
    if L <= 0 or L > 64 or signal.multiplexer_ids or signal.is_multiplexer:
        return None
    conv = signal.conversion
    if type(conv).__name__ == "NamedSignalConversion":  # decode_choices=False: its linear part
        conv = getattr(conv, "_conversion", None)
    kind = type(conv).__name__
    if kind not in ("IdentityConversion", "LinearIntegerConversion", "LinearConversion"):
        return None
    is_float = bool(getattr(conv, "is_float", False))
    if is_float and L not in (32, 64):
        return None
    if signal.byte_order == "little_endian":
        shift, big = int(signal.start), False
    else:
        shift, big = 8 * nbytes - _start_bit(signal) - L, True
    if shift < 0 or shift + L > 8 * nbytes:
        return None
    scale, offset = getattr(conv, "scale", 1), getattr(conv, "offset", 0)
    if kind == "IdentityConversion":
        scale, offset = 1, 0
    int_scale = isinstance(scale, int) and not is_float
    if as_int and not (int_scale and isinstance(offset, int)):
        return None  # int() of a float value: left to cantools
    signed = bool(signal.is_signed) and not is_float
    if not is_float and L == 64 and not signed:
        return None  # a uint64 beyond int64: left to the per-frame extractor
    if int_scale:  # raw * scale (+ offset) in exact integers: they must fit in int64
        top = (1 << (L - 1 if signed else L)) * abs(scale) + abs(int(offset))
        if top >= 1 << 62:
            return None
    mask = np.uint64((1 << L) - 1) if L < 64 else np.uint64(0xFFFFFFFFFFFFFFFF)
    sh = np.uint64(shift)

    def f(nl, nb):
        raw = ((nb if big else nl) >> sh) & mask
        if is_float:
            x = (raw.astype(np.uint32).view(np.float32).astype(np.float64) if L == 32
                 else raw.view(np.float64))
            x = x * scale + offset if kind != "IdentityConversion" else x
            return x.astype(np.int64) if as_int else x
        r = raw.astype(np.int64) if L < 64 else raw.view(np.int64)
        if signed and L < 64:
            r = np.where(r >> (L - 1), r - (1 << L), r)
        if int_scale:
            y = r * scale if scale != 1 else r
            if isinstance(offset, int):
                y = y + offset if offset else y
                return y if as_int else y.astype(np.float64)
            return y.astype(np.float64) + offset
        return r.astype(np.float64) * scale + offset

    return f


def array_extractor(message, names: Sequence[str], ints: Sequence[str] = ()
                    ) -> ArrayDecode | None:
    """``decode(data) -> {name: array}`` of the signals ``names`` of a cantools
    ``message`` for an ``n x w`` uint8 array of payloads of the message's length (w >=
    length, bytes past the length zero): float64 ``float(v)`` of each cantools value
    ``v``, or int64 ``int(v)`` for the names in ``ints`` (rolling counters). None when a
    signal is outside the scheme (multiplexed, wider than 64 bits, a float counter...) or
    the result differs from cantools on a check payload (:func:`agrees_with_cantools_arrays`)."""
    import numpy as np

    if getattr(message, "is_container", False) or message.is_multiplexed() or not names:
        return None
    nbytes = int(message.length)
    if not 0 < nbytes <= 8:
        return None
    by_name = {s.name: s for s in message.signals}
    fns = {}
    for name in dict.fromkeys(names):
        sig = by_name.get(name)
        if sig is None:
            return None
        fn = _array_signal(sig, nbytes, name in ints)
        if fn is None:
            return None
        fns[name] = fn
    down = np.uint64(8 * (8 - nbytes))
    # the big-endian integer only when a Motorola signal reads it
    big = any(by_name[name].byte_order != "little_endian" for name in fns)

    def decode(data):
        d = np.ascontiguousarray(data[:, :8])
        if d.shape[1] < 8:
            d = np.pad(d, ((0, 0), (0, 8 - d.shape[1])))
        nl = d.view("<u8").ravel()
        nb = nl.byteswap() >> down if big else nl
        return {name: fn(nl, nb) for name, fn in fns.items()}

    if not agrees_with_cantools_arrays(message, decode, list(fns), set(ints)):
        return None
    return decode


def agrees_with_cantools_arrays(message, decode: ArrayDecode, names: Sequence[str],
                                ints: set[str] | frozenset[str] = frozenset(),
                                n: int = CHECKS, seed: int = 0x6A5) -> bool:
    """True when ``decode`` gives, for every name, ``float(v)`` (``int(v)`` for ``ints``)
    of cantools' value ``v``, to the bit, on the all-0, all-1 and counting payloads and
    on ``n`` random ones (as :func:`agrees_with_cantools` for the per-frame extractors)."""
    import numpy as np

    rng = random.Random(seed)
    length = int(message.length)
    probes = [bytes(length), b"\xff" * length, bytes(range(1, length + 1))]
    probes += [bytes(rng.getrandbits(8) for _ in range(length)) for _ in range(n)]
    wants, kept = [], []
    for data in probes:
        try:
            wants.append(message.decode_simple(data, False))
        except Exception:
            continue  # e.g. a payload cantools refuses: not a comparison
        kept.append(data)
    if not kept:
        return False
    arr = np.frombuffer(b"".join(p.ljust(8, b"\0") for p in kept),
                        dtype=np.uint8).reshape(len(kept), -1)
    got = decode(arr)
    for name in names:
        col = got[name]
        for i, want in enumerate(wants):
            w = want.get(name)
            if w is None:
                return False
            if name in ints:
                if col.dtype != np.int64 or int(col[i]) != int(w):
                    return False
            else:
                a, b = float(col[i]), float(w)
                if col.dtype != np.float64 or struct.pack("<d", a) != struct.pack("<d", b):
                    return False
    return True
