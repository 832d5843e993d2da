"""The daemon's code numbers, read from the DBC's value tables (``VAL_``, cantools ``choices``).

What the daemon sends and obeys carries names: an identifier (``lkf``), a fit status
(``insufficient_data``), a state (``running``), a command (``stop``), an ack result and
reason (``nack``, ``wrong_state``). Their *numbers* are the DBC's: the signal's value
table maps each number to its name, so a user DBC with another numbering is encoded (and
its commands decoded) with its own numbers. A value table lacking a name the daemon needs,
or giving it a number outside the signal's range (the encoder would saturate it into
another code), is an error at load naming the message, the signal and the entries.

>>> import cantools
>>> db = cantools.database.load_file("dbc/gyrostand.dbc")
>>> codes = ValueCodes.of(db.get_message_by_name("GS_ACK"), "Reason", ACK_REASON_NAMES)
>>> codes.code("wrong_state"), codes.name(2)
(2, 'wrong_state')
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType

from cantools.database.can import Message

from gyrostand.errors import CanEdgeError

__all__ = ["ValueCodes", "STATES", "STATUSES", "COMMAND_NAMES", "ACK_RESULTS",
           "ACK_REASON_NAMES", "SIGNAL_NAMES", "role_codes", "check_width"]

#: the daemon's states (GS_STATUS ``State``)
STATES: tuple[str, ...] = ("idle", "running", "stopping", "stopped", "fault")
#: statuses of an estimate (GS_SUMMARY ``Status``)
STATUSES: tuple[str, ...] = ("ok", "warning", "not_converged", "failed", "insufficient_data")
#: commands the daemon obeys (GS_COMMAND ``Command``)
COMMAND_NAMES: tuple[str, ...] = ("start", "stop", "reset", "snapshot")
#: GS_ACK ``Result``: acknowledged, refused
ACK_RESULTS: tuple[str, ...] = ("ack", "nack")
#: why a command was refused (GS_ACK ``Reason``; ``ok`` for an acknowledgement)
ACK_REASON_NAMES: tuple[str, ...] = ("ok", "unknown_command", "wrong_state", "busy",
                                     "malformed", "not_for_me", "rate_limited")


def _identifier_names() -> tuple[str, ...]:
    from gyrostand.core.registry import names  # the identifiers' one registry (pure Python)

    return names()


#: the value-table signals of each role of the daemon's messages, and the names each needs
#: (a callable: the identifiers are the registry's)
SIGNAL_NAMES: Mapping[str, Mapping[str, object]] = MappingProxyType({
    "result": {"Identifier": _identifier_names},
    "summary": {"Identifier": _identifier_names, "Status": STATUSES},
    "status": {"State": STATES},
    "command": {"Command": COMMAND_NAMES},
    "ack": {"Result": ACK_RESULTS, "Reason": ACK_REASON_NAMES},
})


@dataclass(frozen=True)
class ValueCodes:
    """Name ↔ number of one signal's value table (``message``.``signal``)."""

    message: str
    signal: str
    numbers: Mapping[str, int]

    @classmethod
    def of(cls, msg: Message, signal: str, needed: Sequence[str],
           source: str = "DBC") -> ValueCodes:
        """The value table of ``msg.signal``; raises :class:`CanEdgeError` naming the
        message, signal and every entry of ``needed`` it lacks, or whose number lies
        outside the signal's range."""
        try:
            sig = msg.get_signal_by_name(signal)
        except KeyError:
            raise CanEdgeError(f"{source}: message {msg.name} has no signal {signal}") from None
        numbers: dict[str, int] = {}
        for number, name in (sig.choices or {}).items():
            numbers.setdefault(str(name), int(number))
        where = f"{source}: message {msg.name} signal {signal}"
        missing = [n for n in needed if n not in numbers]
        if missing:
            have = ", ".join(f"{v} {k!r}" for k, v in numbers.items()) or "none"
            raise CanEdgeError(f"{where}: its value table (VAL_) lacks {', '.join(missing)} "
                               f"(it has: {have}); add an entry for each (see dbc/README.md)")
        lo = sig.minimum if sig.minimum is not None else -(1 << (sig.length - 1)) \
            if sig.is_signed else 0
        hi = sig.maximum if sig.maximum is not None else \
            (1 << (sig.length - (1 if sig.is_signed else 0))) - 1
        outside = [f"{n} = {numbers[n]}" for n in needed
                   if not lo <= numbers[n] * sig.scale + sig.offset <= hi]
        if outside:
            raise CanEdgeError(f"{where}: value(s) {', '.join(outside)} outside the signal's "
                               f"range [{lo:g}, {hi:g}] (the frame would carry another code)")
        return cls(msg.name, signal, MappingProxyType(numbers))

    def code(self, name: str) -> int:
        """The number of ``name``; :class:`CanEdgeError` if the table has none."""
        try:
            return self.numbers[name]
        except KeyError:
            raise CanEdgeError(f"message {self.message} signal {self.signal}: no value-table "
                               f"entry for {name!r}") from None

    def name(self, number: int) -> str | None:
        """The name of ``number`` (None for a number the table does not list)."""
        for k, v in self.numbers.items():
            if v == number:
                return k
        return None


def role_codes(msg: Message, role: str, source: str = "DBC") -> dict[str, ValueCodes]:
    """Every value table a message in ``role`` (``result``, ``summary``, ``status``,
    ``command``, ``ack``) needs, checked (signals the message lacks are skipped: the
    config checks those)."""
    have = {s.name for s in msg.signals}
    out = {}
    for signal, needed in SIGNAL_NAMES[role].items():
        if signal in have:
            names = needed() if callable(needed) else needed
            out[signal] = ValueCodes.of(msg, signal, names, source)  # type: ignore[arg-type]
    return out


def check_width(msg: Message, signal: str, mask: int, what: str, source: str = "DBC") -> None:
    """A bitmask ``mask`` (e.g. the ``ModelTerms`` of a model) must fit ``msg.signal``'s
    width and range: raise :class:`CanEdgeError` naming ``what`` otherwise (the encoder
    would saturate it into another mask)."""
    sig = msg.get_signal_by_name(signal)
    top = int(sig.maximum) if sig.maximum is not None else (1 << sig.length) - 1
    top = min(top, (1 << sig.length) - 1)
    if mask > top:
        raise CanEdgeError(f"{source}: message {msg.name} signal {signal} "
                           f"({sig.length} bits, max {top}) cannot carry {what} "
                           f"(mask 0x{mask:X} needs {mask.bit_length()} bits)")
