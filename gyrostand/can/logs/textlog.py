"""Text logs (ASC, candump ``.log``, python-can CSV) read line by line, damage skipped.

python-can's text readers end the file at the first line they cannot parse (CSV: "not
enough values to unpack", no line number), or drop a line silently (ASC: a frame line cut
short before its direction matches nothing they know; one cut inside its data gives a
frame shorter than its DLC). Here every such line is skipped, counted in
:attr:`LogDamage.lines <gyrostand.can.logs.read.LogDamage>` and warned about with the file
and the line number, and reading goes on with the next line (the reader's state, e.g.
ASC's start time and number base, carried over). Blank lines are no damage.

Used by :func:`~gyrostand.can.logs.read.read_log`.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import can

from gyrostand.errors import LogError

if TYPE_CHECKING:
    from gyrostand.can.logs.read import LogDamage

__all__ = ["read_text_log", "TEXT_SUFFIXES"]

#: the text formats read here (python-can's readers, driven line by line)
TEXT_SUFFIXES = (".asc", ".log", ".csv")

#: an ASC classic-CAN frame line cut inside its time (nothing else is a bare number), or
#: as far as its channel (``<t> <channel>``) then nothing or an id: the start of a frame,
#: not a comment, statistic or error-frame line
_ASC_FRAME_START = re.compile(
    r"\s*\d+(?:\.\d*)?\s*$|\s*\d+\.\d+\s+\d+\s*(?:[0-9A-Fa-f]+x?(?:\s|$)|$)")
#: ... and complete up to its kind: ``<t> <ch> <id> Tx|Rx d|r`` (the data are counted on
#: the frame python-can makes of it, :func:`_short`)
_ASC_FRAME_HEAD = re.compile(r"\s*\d+\.\d+\s+\d+\s+\w+\s+(?:Tx|Rx)\s+[dr](?:\s|$)",
                             re.IGNORECASE)


#: a CAN FD frame line's start: ``<t> CANFD`` (or a cut prefix of it) ...
_ASC_FD_START = re.compile(r"\s*\d+\.\d+\s+C(?:A(?:N(?:F(?:D)?)?)?)?(?:\s|$)")
#: ... and complete up to its data length: ``<t> CANFD <ch> Rx|Tx <id> [name] <brs>
#: <esi> <dlc> <length>`` (the data are counted on the frame python-can makes of it)
_ASC_FD_HEAD = re.compile(r"\s*\d+\.\d+\s+CANFD\s+\d+\s+(?:Tx|Rx)\s+[0-9A-Fa-f]+x?\s+"
                          r"(?:\S+\s+)?[01]\s+[01]\s+[0-9A-Fa-f]{1,2}\s+\d+(?:\s|$)",
                          re.IGNORECASE)


def _asc_cut(line: str) -> bool:
    """Whether ``line`` is an ASC frame line (classic or CAN FD) cut short before its data
    (python-can would skip it without a word)."""
    if _ASC_FD_START.match(line):
        return not _ASC_FD_HEAD.match(line)
    return bool(_ASC_FRAME_START.match(line)) and not _ASC_FRAME_HEAD.match(line)


class _Lines:
    """A text file that counts the lines read from it (for the line number of a bad one),
    leaves out blank lines and lines ``cut(line)`` calls damaged (counted and warned),
    and can give one line back (:meth:`unread`, not counted)."""

    def __init__(self, path: Path, damage: LogDamage,
                 cut: Callable[[str], bool] | None = None, skip_blank: bool = False) -> None:
        self.path, self.damage, self.cut, self.skip_blank = path, damage, cut, skip_blank
        self.f = path.open("r", encoding="utf-8", errors="replace", newline=None)
        self.n = 0
        self.closed = False
        self._back: list[str] = []

    def __iter__(self) -> _Lines:
        return self

    def __next__(self) -> str:
        if self._back:
            return self._back.pop()
        while True:
            line = next(self.f)
            self.n += 1
            if self.skip_blank and not line.strip():
                continue
            if self.cut is not None and self.cut(line):
                self.damage.lines += 1
                self.damage.warn(f"{self.path}: line {self.n}: frame line cut short, "
                                 f"skipped ({line.strip()[:60]!r})")
                continue
            return line

    def unread(self, line: str) -> None:
        self._back.append(line)

    def close(self) -> None:
        self.closed = True
        self.f.close()


def _short(msg: can.Message) -> bool:
    """A data frame with fewer data bytes than its DLC: its line was cut inside the data."""
    if msg.is_remote_frame or msg.is_error_frame:
        return False
    return len(msg.data) < (msg.dlc if msg.is_fd else min(8, msg.dlc))


def read_text_log(path: Path, damage: LogDamage) -> Iterator[can.Message]:
    """The frames of an ASC (absolute timestamps), candump ``.log`` or python-can CSV log;
    see the module doc. Raises :class:`CanEdgeError` naming the file when it cannot be
    read at all."""
    suffix = path.suffix.lower()
    lines = _Lines(path, damage, _asc_cut if suffix == ".asc" else None,
                   skip_blank=suffix == ".csv")
    header = ""
    make: Callable[[], Any]
    if suffix == ".asc":
        def make() -> Any:
            return can.ASCReader(lines, relative_timestamp=False)  # type: ignore[arg-type]
    elif suffix == ".csv":
        header = next(lines, "")
        lines.unread(header)  # python-can's CSV reader skips the first line

        def make() -> Any:
            return can.CSVReader(lines)  # type: ignore[arg-type]
    else:
        def make() -> Any:
            return can.CanutilsLogReader(lines)  # type: ignore[arg-type]
    try:
        reader = make()
    except Exception as exc:
        lines.close()
        raise LogError(f"{path}: cannot read CAN log: {exc}") from exc
    try:
        at = -1
        while True:
            try:
                for msg in reader:
                    if _short(msg):
                        damage.lines += 1
                        damage.warn(f"{path}: line {lines.n}: frame line cut short ("
                                    f"{len(msg.data)} of {msg.dlc} data bytes), skipped")
                        continue
                    yield msg
                return
            except Exception as exc:
                if lines.n == at:  # nothing more was read: not a line's fault
                    raise LogError(f"{path}: corrupt CAN log after line {at}: "
                                   f"{type(exc).__name__}: {exc}") from exc
                at = lines.n
                damage.lines += 1
                damage.warn(f"{path}: line {lines.n}: cannot parse, skipped "
                            f"({type(exc).__name__}: {str(exc)[:80]})")
                if suffix == ".csv":
                    lines.unread(header)
                    reader = make()
                elif suffix == ".asc":
                    # the same reader goes on (its base and start time kept); iterating
                    # reads a header first: give it the line that ends one, with the
                    # value it has (the file's next line would be taken as header)
                    lines.unread("internal events logged" if reader.internal_events_logged
                                 else "no internal events logged")
    finally:
        lines.close()
