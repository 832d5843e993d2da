"""Opening the bus, and building/sending the daemon's frames by DBC message name.

Every payload is encoded by cantools from signal values; nothing is hand-packed. The frame
layouts are described in ``dbc/README.md``; a user DBC that carries messages with the same
signal names works the same way (the session loader checks the signals exist). Code numbers
(identifier, status, state, command, ack result and reason) are the DBC's own, read from
its value tables (:mod:`gyrostand.can.codes`): a DBC with another numbering is encoded with
its numbers, and one lacking a name is refused when its message is first used (the
session loader checks this at load).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import can
from cantools.database.can import Database, Message

from gyrostand.can.codes import (
    ACK_REASON_NAMES,
    COMMAND_NAMES,
    STATES,
    STATUSES,
    ValueCodes,
    check_width,
    role_codes,
)
from gyrostand.can.dbc import MessageRef, find_message
from gyrostand.can.pack import packer
from gyrostand.core.terms.builtin import VOCABULARY, summary_bits
from gyrostand.errors import BusUnavailableError, CanEdgeError

__all__ = [
    "open_bus",
    "FrameEncoder",
    "MODEL_TERM_BITS",
    "IDENTIFIER_CODES",
    "STATE_CODES",
    "STATUS_CODES",
    "ACK_REASONS",
    "COMMANDS",
    "model_terms_mask",
]

log = logging.getLogger(__name__)

#: Bit i of ``ModelTerms`` in GS_SUMMARY = term i (PRODUCT.md's vocabulary order); a plugin
#: term's bit follows the built-ins' (its ``Term.bit``, :func:`model_terms_mask`).
MODEL_TERM_BITS = VOCABULARY

#: The numbering of the project's ``dbc/gyrostand.dbc`` (what dbc/generate.py writes; a
#: test checks they agree), for tools and files that speak the project's numbering. The
#: encoder does not use them: frames carry the codes of the DBC they are encoded with.
STATE_CODES = {name: i for i, name in enumerate(STATES)}
STATUS_CODES = {name: i for i, name in enumerate(STATUSES)}
ACK_REASONS = {name: i for i, name in enumerate(ACK_REASON_NAMES)}
COMMANDS = {i: name for i, name in enumerate(COMMAND_NAMES, start=1)}


def _identifier_codes() -> dict[str, int]:
    from gyrostand.core.registry import names

    return {name: i for i, name in enumerate(names())}


IDENTIFIER_CODES = _identifier_codes()


def model_terms_mask(terms: Sequence[str], width: int | None = None) -> int:
    """``ModelTerms`` bitmask of a model's term names: bit ``Term.bit`` of each (the
    built-ins in vocabulary order, plugins after them). An unknown term, or one whose bit
    does not fit a signal of ``width`` bits, is a CanEdgeError naming it."""
    bits = summary_bits()
    mask = 0
    for t in terms:
        if t not in bits:
            raise CanEdgeError(f"ModelTerms: unknown model term {t!r}")
        if width is not None and bits[t] >= width:
            raise CanEdgeError(f"ModelTerms: term {t!r} has summary bit {bits[t]}, beyond "
                               f"the {width}-bit ModelTerms signal of the DBC; widen it")
        mask |= 1 << bits[t]
    return mask


def open_bus(bus_cfg: Mapping[str, Any]) -> can.BusABC:
    """``can.Bus(**bus_cfg)``, with failures as :class:`CanEdgeError` naming the bus."""
    where = f"interface={bus_cfg.get('interface')!r} channel={bus_cfg.get('channel')!r}"
    try:
        return can.Bus(**dict(bus_cfg))
    except (can.CanInterfaceNotImplementedError, ImportError, TypeError, ValueError) as exc:
        # an unknown interface, a driver not installed, bad arguments: the configuration
        raise CanEdgeError(f"cannot open CAN bus ({where}): {exc}") from exc
    except Exception as exc:  # CanError, OSError...: the bus is not there (now)
        raise BusUnavailableError(f"cannot open CAN bus ({where}): {exc}") from exc



class _Layout:
    """What :meth:`FrameEncoder.signal_values` reads of one cantools message, read once:
    per signal (in the message's order) its value when not given (the DBC initial value or
    0), its range as floats, whether it is a float, its scale and offset, and its
    multiplexer signal and ids; the same numbers the encoder read from the signals at
    every frame before."""

    __slots__ = ("msg", "names", "specs", "values", "_pack")

    def __init__(self, msg: Message) -> None:
        self.msg = msg
        self.names = frozenset(s.name for s in msg.signals)
        self.specs: dict[str, tuple[Any, float | None, float | None, bool, Any, Any,
                                    str | None, Any]] = {}
        for s in msg.signals:  # a repeated name: the first signal, as before
            self.specs.setdefault(s.name, (
                s.initial if s.initial is not None else 0,
                None if s.minimum is None else float(s.minimum),
                None if s.maximum is None else float(s.maximum),
                bool(s.is_float), s.scale, s.offset, s.multiplexer_signal,
                s.multiplexer_ids))
        self.values: Callable[[Mapping[str, float]], dict[str, float]] = \
            _compile_values(msg.name, self.specs)
        self._pack: Any = False  # not built yet

    def packer(self) -> Any:
        """The message's payload packer (:func:`gyrostand.can.pack.packer`: cantools' bit
        layout, checked against cantools when built), or None: cantools packs."""
        if self._pack is False:
            self._pack = packer(self.msg)
        return self._pack


def _compile_values(message: str, specs: dict[str, tuple]) -> Callable:
    """``values(signals) -> {signal: value}`` of :meth:`FrameEncoder.signal_values`,
    compiled once per message: per signal in the message's order, whether it is active
    (its multiplexer active and holding one of its ids), then its value (given, else its
    default; as a float; clamped into its range unless NaN; an integer signal rounded to
    its scale's grid, NaN refused), each value computed once, when first needed, as the
    per-frame closures did (the same operations on the same numbers, in the same order:
    the same values, and the same first error)."""
    env: dict[str, Any] = {"_U": object(), "_Err": CanEdgeError}
    idx = {name: i for i, name in enumerate(specs)}
    lines = ["def values(signals):", "    get = signals.get"]
    lines += [f"    v{i} = _U" for i in range(len(specs))]

    def ensure(name: str, ind: str) -> list[str]:
        i = idx[name]
        default, lo, hi, is_float, scale, offset, _, _ = specs[name]
        env.update({f"_d{i}": default, f"_lo{i}": lo, f"_hi{i}": hi, f"_s{i}": scale,
                    f"_o{i}": offset})
        body = [f"x = get({name!r})", f"if x is None: x = _d{i}", "x = float(x)"]
        clamp = ([f"    x = max(x, _lo{i})"] if lo is not None else []) + \
            ([f"    x = min(x, _hi{i})"] if hi is not None else [])
        if clamp:
            body += ["if x == x:"] + clamp
        if not is_float:
            err = f"{message}.{name}: NaN in an integer signal"
            body += [f"if x != x: raise _Err({err!r})",
                     f"x = int(round((x - _o{i}) / _s{i})) * _s{i} + _o{i}"]
        body.append(f"v{i} = x")
        return [f"{ind}if v{i} is _U:"] + [f"{ind}    {b}" for b in body]

    def active(name: str, out: str, ind: str) -> list[str]:
        """Lines setting ``out`` to whether ``name`` is active."""
        _, _, _, _, _, _, mux, ids = specs[name]
        if not ids:
            return [f"{ind}{out} = True"]
        i = idx[name]
        env[f"_ids{i}"] = ids
        return active(mux, out, ind) + [f"{ind}if {out}:"] + ensure(mux, ind + "    ") + \
            [f"{ind}    {out} = int(v{idx[mux]}) in _ids{i}"]

    for name in specs:
        i = idx[name]
        if specs[name][7]:
            lines += active(name, "a", "    ") + ["    if a:"] + ensure(name, "        ") + \
                [f"        out[{name!r}] = v{i}"]
        else:
            lines += ensure(name, "    ") + [f"    out[{name!r}] = v{i}"]
    lines.insert(2, "    out = {}")
    lines.append("    return out")
    exec(compile("\n".join(lines) + "\n", f"<gyrostand signal values {message}>", "exec"), env)
    fn: Callable = env["values"]
    return fn


def _wrap(value: int, sig) -> int:
    """Cumulative counts wrap modulo the signal's range (documented in dbc/README.md)."""
    top = int(sig.maximum) if sig.maximum is not None else (1 << sig.length) - 1
    return int(value) % (top + 1)


class FrameEncoder:
    """Encode (and optionally send) frames of ``db`` by message name or :class:`MessageRef`.

    Values are saturated into the DBC range (NaN is kept for float signals); signals not
    given get their DBC initial value or 0; a multiplexed message gets exactly the signals
    its multiplexer values select.
    """

    def __init__(self, db: Database, bus: can.BusABC | None = None) -> None:
        self.db = db
        self.bus = bus
        self._codes: dict[tuple[str, str], dict[str, ValueCodes]] = {}
        self._messages: dict[Any, Message] = {}
        self._layouts: dict[str, _Layout] = {}

    def _message(self, ref: str | int | MessageRef) -> Message:
        """The cantools message of ``ref``, looked up once per reference (a lookup that
        fails is not kept: it raises again)."""
        if isinstance(ref, MessageRef):
            key: Any = ref
        elif type(ref) in (str, int):
            key = (type(ref), ref)  # 1 and "1" stay apart
        else:  # not a reference: find_message says what is wrong with it
            return find_message(self.db, ref)[1]
        msg = self._messages.get(key)
        if msg is None:
            if isinstance(ref, MessageRef):
                msg = self.db.get_message_by_name(ref.name)
            else:
                msg = find_message(self.db, ref)[1]
            self._messages[key] = msg
        return msg

    def _layout(self, msg: Message) -> _Layout:
        layout = self._layouts.get(msg.name)
        if layout is None or layout.msg is not msg:
            layout = self._layouts[msg.name] = _Layout(msg)
        return layout

    def codes(self, ref: str | int | MessageRef, role: str) -> dict[str, ValueCodes]:
        """The checked value tables of message ``ref`` in ``role`` (``result``,
        ``summary``, ``status``, ``command``, ``ack``) by signal name, read once."""
        msg = self._message(ref)
        key = (msg.name, role)
        if key not in self._codes:
            self._codes[key] = role_codes(msg, role)
        return self._codes[key]

    def _code(self, msg: Message, table: ValueCodes, name: str) -> float:
        """The physical value carrying ``name``'s raw code."""
        sig = msg.get_signal_by_name(table.signal)
        return table.code(name) * sig.scale + sig.offset

    def command_name(self, ref: str | int | MessageRef, code: float) -> str | None:
        """The command (``start``, ``stop``, ...) that the decoded ``Command`` value
        ``code`` of message ``ref`` means in its value table; None for a number it does not
        list."""
        msg = self._message(ref)
        sig = msg.get_signal_by_name("Command")
        raw = round((float(code) - sig.offset) / sig.scale)
        return self.codes(ref, "command")["Command"].name(raw)

    def encode(self, ref: str | int | MessageRef, signals: Mapping[str, float], *,
               timestamp: float = 0.0) -> can.Message:
        """One frame of message ``ref`` carrying ``signals`` (physical values)."""
        msg, data = self.signal_values(ref, signals)
        pack = self._layout(msg).packer()
        payload = None
        if pack is not None:  # cantools' bytes (checked), or None: cantools decides
            try:
                payload = pack(data)
            except Exception:  # noqa: BLE001 - cantools raises its own error below
                payload = None
        if payload is None:
            try:
                payload = msg.encode(data, strict=False)
            except Exception as exc:
                raise CanEdgeError(f"cannot encode {msg.name} from {data}: {exc}") from exc
        return can.Message(arbitration_id=msg.frame_id, is_extended_id=msg.is_extended_frame,
                           data=payload, timestamp=timestamp, is_fd=bool(msg.is_fd),
                           is_rx=False)

    def signal_values(self, ref: str | int | MessageRef,
                      signals: Mapping[str, float]) -> tuple[Message, dict[str, float]]:
        """The cantools message and the complete, saturated signal dict that
        :meth:`encode` would encode (defaults filled, inactive multiplexed signals left out).
        """
        msg = self._message(ref)
        layout = self._layout(msg)
        if not layout.names.issuperset(signals):
            unknown = set(signals) - layout.names
            raise CanEdgeError(f"message {msg.name} has no signal(s) {sorted(unknown)}")
        return msg, layout.values(signals)

    def send(self, frames: can.Message | Sequence[can.Message],
             timeout: float | None = 1.0) -> None:
        """Send frames on :attr:`bus`, wrapping failures in :class:`CanEdgeError`."""
        if self.bus is None:
            raise CanEdgeError("FrameEncoder has no bus to send on")
        if isinstance(frames, can.Message):
            frames = [frames]
        for f in frames:
            try:
                self.bus.send(f, timeout=timeout)
            except Exception as exc:
                raise BusUnavailableError(f"cannot send frame 0x{f.arbitration_id:X} on "
                                          f"{self.bus.channel_info}: {exc}") from exc

    # -- the daemon's frames -------------------------------------------------------------
    def result_frames(self, ref: str | MessageRef, identifier: str, values: Sequence[float],
                      stds: Sequence[float], counter: int, *,
                      timestamp: float = 0.0) -> list[can.Message]:
        """Two frames per parameter i: Kind 0 with the estimate, Kind 1 with its std."""
        if len(values) != len(stds):
            raise CanEdgeError(f"{len(values)} values but {len(stds)} standard deviations")
        msg = self._message(ref)
        code = self._code(msg, self.codes(ref, "result")["Identifier"], identifier)
        out = []
        for i, (v, s) in enumerate(zip(values, stds, strict=True)):
            common = {"Identifier": code, "Param": i, "NParams": len(values),
                      "Counter": counter % 256}
            out.append(self.encode(ref, {"Kind": 0, "Value": v, **common}, timestamp=timestamp))
            out.append(self.encode(ref, {"Kind": 1, "Std": s, **common}, timestamp=timestamp))
        return out

    def summary_frame(self, ref: str | MessageRef, identifier: str, status: str,
                      model_terms: Sequence[str], samples: int, residual_rms: float, *,
                      timestamp: float = 0.0) -> can.Message:
        """Fit summary; Samples and ResidualRms saturate at the DBC maximum; a
        ``ModelTerms`` mask wider than its signal is an error (never saturated)."""
        msg = self._message(ref)
        codes = self.codes(ref, "summary")
        mask = model_terms_mask(model_terms)
        check_width(msg, "ModelTerms", mask, f"the model {', '.join(model_terms)}")
        return self.encode(ref, {
            "Identifier": self._code(msg, codes["Identifier"], identifier),
            "Status": self._code(msg, codes["Status"], status),
            "ModelTerms": mask, "Samples": samples,
            "ResidualRms": residual_rms if math.isfinite(residual_rms) else 0.0,
        }, timestamp=timestamp)

    def status_frames(self, ref: str | MessageRef, state: str, counter: int, *, bins: int,
                      gaps: int, decoded: int, rejected: int, bus_errors: int, late: int,
                      outages: int = 0, timestamp: float = 0.0) -> list[can.Message]:
        """The heartbeat: pages 0, 1, 2 with one Counter; counts wrap (see README).
        ``outages`` goes into page 2's ``Outages`` where the DBC has that signal."""
        msg = self._message(ref)
        s = {x.name: x for x in msg.signals}
        c = counter % 16
        pages = (
            {"Page": 0, "State": self._code(msg, self.codes(ref, "status")["State"], state),
             "Bins": _wrap(bins, s["Bins"]),
             "Gaps": _wrap(gaps, s["Gaps"])},
            {"Page": 1, "FramesDecoded": _wrap(decoded, s["FramesDecoded"]),
             "FramesRejected": _wrap(rejected, s["FramesRejected"])},
            {"Page": 2, "BusErrors": _wrap(bus_errors, s["BusErrors"]),
             "LateFrames": _wrap(late, s["LateFrames"]),
             **({"Outages": _wrap(outages, s["Outages"])} if "Outages" in s else {})},
        )
        return [self.encode(ref, {"Counter": c, **p}, timestamp=timestamp) for p in pages]

    def ack_frame(self, ref: str | MessageRef, command: int, sequence: int, ok: bool,
                  reason: str = "ok", node: int = 1, *, timestamp: float = 0.0) -> can.Message:
        """Acknowledge (``ok``) or refuse a command, echoing its Command and Sequence."""
        msg = self._message(ref)
        codes = self.codes(ref, "ack")
        data = {"Command": command, "Sequence": sequence,
                "Result": self._code(msg, codes["Result"], "ack" if ok else "nack"),
                "Reason": self._code(msg, codes["Reason"], reason)}
        if "Node" in {x.name for x in msg.signals}:
            data["Node"] = node
        return self.encode(ref, data, timestamp=timestamp)

    def command_frame(self, ref: str | MessageRef, command: str | int, sequence: int,
                      target: int = 255, *, timestamp: float = 0.0) -> can.Message:
        """A command (for tests and tools that drive a daemon)."""
        msg = self._message(ref)
        code = command if isinstance(command, int) else \
            self._code(msg, self.codes(ref, "command")["Command"], command)
        sigs = {x.name for x in msg.signals}
        data = {"Command": code, "Sequence": sequence % 256}
        if "Target" in sigs:
            data["Target"] = target
        return self.encode(ref, data, timestamp=timestamp)
