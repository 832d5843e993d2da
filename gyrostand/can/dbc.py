"""DBC loading and name resolution: the one place that turns names in a session file into
frames and signals of a cantools database.

Nothing here knows gyrostand's own frame ids or layouts: a message is found by name or by
frame id (standard or extended), a signal by name inside it, and a signal that lives under a
multiplexer is returned with the multiplexer's name and the values that select it.

Errors are :class:`~gyrostand.errors.CanEdgeError` with a message that names what was looked
up and what exists; the session loader prefixes them with the key path.
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import cantools
import cantools.j1939
from cantools.database.can import Database, Message

from gyrostand.can.logs.frames import EXTENDED_KEY_BIT
from gyrostand.errors import CanEdgeError

__all__ = [
    "SignalRef",
    "MessageRef",
    "load_dbc",
    "text_encoding",
    "find_message",
    "find_signal",
    "frame_key",
    "EXTENDED_KEY_BIT",
]

log = logging.getLogger(__name__)



def frame_key(arbitration_id: int, is_extended: bool) -> int:
    """Dictionary key of a frame id: ``id`` for standard, ``id | 2**29`` for extended."""
    return arbitration_id | EXTENDED_KEY_BIT if is_extended else arbitration_id


@functools.lru_cache(maxsize=8192)
def j1939_pgn(frame_id: int) -> int:
    """The J1939 parameter group number of a 29-bit id: the id without its priority and
    source address, and without the destination address (PS) when the PDU format is
    below 240 (PDU1). cantools' own ``j1939.pgn_from_frame_id``, memoised: it costs ~26 µs
    a call (bitstruct), and the receive path asks once per unrouted extended frame, of
    the few hundred ids a bus repeats (a cached call: ~0.1 µs)."""
    return int(cantools.j1939.pgn_from_frame_id(frame_id))


@dataclass(frozen=True)
class MessageRef:
    """A resolved DBC message: name, id, whether the id is extended, payload length (bytes)."""

    name: str
    frame_id: int
    is_extended: bool
    length: int

    @property
    def key(self) -> int:
        """See :func:`frame_key`."""
        return frame_key(self.frame_id, self.is_extended)

    def describe(self) -> str:
        kind = "extended" if self.is_extended else "standard"
        return f"{self.name} (0x{self.frame_id:X}, {kind})"


@dataclass(frozen=True)
class SignalRef:
    """A resolved signal of a DBC message.

    ``minimum``/``maximum`` are the DBC's physical range (None where the DBC gives none);
    ``multiplexer`` names the multiplexer signal when the signal is multiplexed, and
    ``multiplexer_ids`` lists the multiplexer values under which it is present.
    ``resolution`` is the physical value of one raw bit (the DBC scale; 0 for floats).
    """

    message: MessageRef
    name: str
    unit: str
    minimum: float | None
    maximum: float | None
    resolution: float
    multiplexer: str | None = None
    multiplexer_ids: tuple[int, ...] = ()

    def in_range(self, value: float) -> bool:
        """True when ``value`` is finite and inside the DBC range (where one is given)."""
        if not math.isfinite(value):
            return False
        if self.minimum is not None and value < self.minimum:
            return False
        return not (self.maximum is not None and value > self.maximum)


def load_dbc(path: str | Path) -> Database:
    """Load a DBC (or any format cantools reads) with strict checks.

    Raises :class:`CanEdgeError` naming the file when it cannot be read or parsed.
    """
    path = Path(path)
    if not path.is_file():
        raise CanEdgeError(f"{path}: DBC file not found")
    try:
        db = cantools.database.load_file(str(path), strict=True, encoding=text_encoding(path))
    except Exception as exc:  # cantools raises a zoo of parser errors
        raise CanEdgeError(f"{path}: cannot load DBC: {exc}") from exc
    if not isinstance(db, Database):
        raise CanEdgeError(f"{path}: not a CAN database")
    return db


def text_encoding(path: str | Path) -> str:
    """The encoding a database file's text is read in: UTF-8 when its bytes are UTF-8
    (``"°/h"`` is then ``°/h``, not cantools' cp1252 default's ``Â°/h``), else cp1252 (a
    DBC editor's Windows default, byte 0xB0 for ``°``). Raises :class:`CanEdgeError` when
    the file cannot be read."""
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise CanEdgeError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    try:
        raw.decode("utf-8")
    except UnicodeDecodeError:
        return "cp1252"
    return "utf-8-sig" if raw.startswith(b"\xef\xbb\xbf") else "utf-8"


def _message_ref(msg: Message) -> MessageRef:
    return MessageRef(msg.name, msg.frame_id, bool(msg.is_extended_frame), msg.length)


def find_message(
    db: Database, ref: str | int, extended: bool | None = None, *, source: str = "DBC"
) -> tuple[MessageRef, Message]:
    """Find a message by name (str) or frame id (int).

    ``extended`` restricts an id lookup to extended (True) or standard (False) frames; when
    None and both exist with that id, the lookup is ambiguous and fails. ``source`` names the
    database in error messages (usually its path).
    """
    if isinstance(ref, bool) or not isinstance(ref, (str, int)):
        raise CanEdgeError(f"expected a message name or frame id, got {ref!r}")
    if isinstance(ref, str):
        for msg in db.messages:
            if msg.name == ref:
                if extended is not None and bool(msg.is_extended_frame) != extended:
                    kind = "extended" if msg.is_extended_frame else "standard"
                    raise CanEdgeError(f"message {ref} in {source} has a {kind} id")
                return _message_ref(msg), msg
        known = ", ".join(sorted(m.name for m in db.messages)) or "none"
        raise CanEdgeError(f"{ref!r} is not a message in {source} (known: {known})")
    hits = [
        m
        for m in db.messages
        if m.frame_id == ref and (extended is None or bool(m.is_extended_frame) == extended)
    ]
    if not hits:
        raise CanEdgeError(f"no message with frame id 0x{ref:X} in {source}")
    if len(hits) > 1:
        raise CanEdgeError(
            f"frame id 0x{ref:X} is both a standard and an extended message in {source}; "
            "say which with 'extended: true/false'"
        )
    return _message_ref(hits[0]), hits[0]


def find_signal(
    db: Database, message: str | int, signal: str, extended: bool | None = None,
    *, source: str = "DBC",
) -> SignalRef:
    """Resolve ``signal`` inside ``message`` (name or frame id) to a :class:`SignalRef`."""
    mref, msg = find_message(db, message, extended, source=source)
    for sig in msg.signals:
        if sig.name == signal:
            break
    else:
        known = ", ".join(s.name for s in msg.signals) or "none"
        raise CanEdgeError(
            f"{signal!r} is not a signal of message {msg.name} in {source} (known: {known})"
        )
    mux_name: str | None = None
    mux_ids: tuple[int, ...] = ()
    if sig.multiplexer_ids:
        mux_name = sig.multiplexer_signal
        mux_ids = tuple(int(i) for i in sig.multiplexer_ids)
    return SignalRef(
        message=mref,
        name=sig.name,
        unit=sig.unit or "",
        minimum=None if sig.minimum is None else float(sig.minimum),
        maximum=None if sig.maximum is None else float(sig.maximum),
        resolution=0.0 if sig.is_float else abs(float(sig.scale)),
        multiplexer=mux_name,
        multiplexer_ids=mux_ids,
    )


def signal_names(db: Database, message: str | int, extended: bool | None = None) -> list[str]:
    """Names of the signals of a message (for validation messages)."""
    _, msg = find_message(db, message, extended)
    return [s.name for s in msg.signals]
