"""What the listener extracts and how each frame id is decoded: the channel map (which
DBC signal is which gyro's drift or temperature), and the route of one frame id with its
decoder (cantools' own fast entry, or a precompiled extractor set by the listener)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any

from gyrostand.can.dbc import SignalRef

try:
    from cantools.database.utils import decode_data as _cantools_decode_data
except ImportError:  # another cantools: decode_simple is used
    _cantools_decode_data = None  # type: ignore[assignment]
_decode_data: Callable[..., dict] | None = _cantools_decode_data


__all__ = ["ChannelMap", "Route", "decoder", "checked_decoder", "Dropped", "NotAvailable",
           "Invalid"]


@dataclass(frozen=True)
class ChannelMap:
    """What the listener extracts: ``signals[g][c]`` is the :class:`SignalRef` of channel c
    (0 drift, 1 temperature) of gyro g; ``counters[g][c]`` its rolling counter or None;
    ``pgn`` the frame keys of the messages matched by J1939 PGN (any priority and source
    address) instead of by their full id."""

    gyros: tuple[str, ...]
    signals: tuple[tuple[SignalRef, SignalRef], ...]
    counters: tuple[tuple[SignalRef | None, SignalRef | None], ...] = ()
    pgn: frozenset[int] = frozenset()
    #: per gyro and channel: the unit conversion (``Conversion`` or None), the validity
    #: signal ``(name, values, accept)`` or None, the J1939 source address or None
    convert: tuple[tuple[Any, Any], ...] = ()
    valid: tuple[tuple[Any, Any], ...] = ()
    sources: tuple[tuple[int | None, int | None], ...] = ()

    @classmethod
    def from_config(cls, cfg) -> ChannelMap:  # cfg: gyrostand.config.SessionConfig
        pair = [(g.drift, g.temperature) for g in cfg.gyros]
        return cls(
            gyros=tuple(g.name for g in cfg.gyros),
            signals=tuple((d.signal, t.signal) for d, t in pair),
            counters=tuple((d.counter, t.counter) for d, t in pair),
            pgn=frozenset(c.signal.message.key for p in pair for c in p if c.match == "pgn"),
            convert=tuple((getattr(d, "convert", None), getattr(t, "convert", None))
                          for d, t in pair),
            valid=tuple((getattr(d, "valid", None), getattr(t, "valid", None))
                        for d, t in pair),
            sources=tuple((getattr(d, "source_address", None),
                           getattr(t, "source_address", None)) for d, t in pair),
        )


class Dropped(Exception):  # noqa: N818 (a verdict on a frame, not an error)
    """A frame the DBC itself says carries no measurement (raised by a checked decoder)."""


class NotAvailable(Dropped):
    """Every mapped value of the frame is a value-table code (not available, error...)."""


class Invalid(Dropped):
    """The frame's validity signal marks it invalid."""


class Route:
    """The receive path's entry for one frame id: its DBC message, decoder, payload
    length, what it extracts per mapped signal, whether it is the command message, and
    the timestamp of its last accepted frame (s)."""

    __slots__ = ("message", "decode", "length", "extract", "is_command", "last_t",
                 "convert", "checked", "codes", "valid")

    def __init__(self, message, length: int) -> None:
        self.message = message
        self.decode = decoder(message)
        self.length = length
        # (gyro, channel, signal name, minimum, maximum, counter signal or None, modulus,
        #  (gyro, channel) as the counter's key)
        self.extract: list[tuple[int, int, str, float, float, str | None, int,
                                 tuple[int, int]]] = []
        self.is_command = False
        self.last_t = -math.inf
        #: signal name -> (scale, offset) into the channel's unit (the array path's too)
        self.convert: dict[str, tuple[float, float]] = {}
        #: codes or a validity signal to check (checked_decoder; the array path too)
        self.checked = False
        #: mapped signal name -> its VAL_ codes (decoded values); validity signals
        self.codes: dict[str, frozenset] = {}
        self.valid: list[tuple[str, frozenset, bool]] = []


def checked_decoder(base: Callable[[bytes | bytearray], dict], mapped: list[str],
                    codes: dict[str, frozenset], valid: list[tuple[str, frozenset, bool]],
                    convert: dict[str, tuple[float, float]],
                    dropped: Callable[[int], None]) -> Callable[[bytes | bytearray], dict]:
    """``base`` with the DBC's verdicts and the units applied: raises :class:`Invalid`
    when a validity signal ``(name, values, accept)`` says so (its value in ``values``
    when ``accept`` is False, not in them when True); drops each mapped value that is a
    code of ``codes`` (calling ``dropped(k)``) and raises :class:`NotAvailable` when no
    mapped value is left; converts the rest by ``convert`` (``v·scale + offset``).
    Constant work per frame: one set lookup per code-checked value."""
    code_items = list(codes.items())
    conv_items = [(n, s, o) for n, (s, o) in convert.items()]

    def decode(data):
        values = base(data)
        for name, vals, accept in valid:
            x = values.get(name)
            if x is not None and (x in vals) is not accept:
                raise Invalid
        if code_items:
            k = 0
            for name, bad in code_items:
                x = values.get(name)
                if x is not None and x in bad:
                    del values[name]
                    k += 1
            if k:
                dropped(k)
                if all(values.get(n) is None for n in mapped):
                    raise NotAvailable
        for name, s, o in conv_items:
            x = values.get(name)
            if x is not None:
                values[name] = x * s + o
        return values

    return decode


def decoder(message) -> Callable[[bytes | bytearray], dict]:
    """``decode(data) -> {signal: value}`` of a DBC message: cantools' decoding, scaled,
    without choice names (what ``Message.decode_simple(data, decode_choices=False)``
    returns).

    ``decode_simple`` checks per call that the message is no container, then walks its
    codec tree: cantools' ``decode_data`` on the top level, then each selected multiplexed
    level. The route checks the payload length before decoding, so here the walk is
    entered directly: ``decode_data`` with the message's own codec for a plain message
    (0.75 vs 0.95 µs per frame), ``Message._decode`` for a multiplexed one. Either is
    used only if it gives what ``decode_simple`` gives on probe payloads; otherwise
    (another cantools) ``decode_simple`` itself is used; ``decode`` for a container.
    """
    if message.is_container:
        return partial(message.decode, decode_choices=False)

    def public(data):
        return message.decode_simple(data, False)

    codecs: Any = getattr(message, "_codecs", None)
    entry = getattr(message, "_decode", None)
    fast = public
    plain = _decode_data
    try:
        if not codecs["multiplexers"] and plain is not None:
            length, signals, formats = message.length, codecs["signals"], codecs["formats"]

            def fast(data):
                return plain(data, length, signals, formats, False, True, False, True)
        elif callable(entry):
            def fast(data):
                return entry(codecs, data, False, True, False, True)
    except (TypeError, KeyError):
        return public
    for probe in (bytes(message.length), b"\xff" * message.length,
                  bytes(range(1, message.length + 1))):
        try:
            want = public(probe)
        except Exception:
            continue  # e.g. a multiplexer value the DBC does not define
        try:
            if fast(probe) != want:
                return public
        except Exception:
            return public
    return fast
