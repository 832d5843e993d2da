"""How the run folder's files are written and read back: the rules every file shares.

* **Rewritten files** (``result.json``, ``report.txt``, ``snapshot.json``,
  ``segments.json``) go through :func:`write_atomic`: a temporary file beside the target,
  renamed over it, so a reader sees the old or the new file, never half of one (the
  report's page and figures and the fleet table too).
* **Growing files** (``samples.csv``, ``estimates.csv``, ``ledger.jsonl``) are appended a
  whole line at a time, each line ending in ``\\n``. A process killed (or a disk filled)
  in the middle of an append leaves a *torn* last line: the text after the last line end.
  :func:`read_lines` is the one reader of that rule (the torn line is left out with a
  warning naming the file and line), :func:`cut_torn_tail` the one repair (before a file
  is appended to again).
* **Durable** writes call :func:`datasync` (``fdatasync``): the data is on the disk, not
  only in the operating system's cache, and survives a power cut.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from pathlib import Path

from ..errors import DataError, OutputError

__all__ = ["datasync", "write_atomic", "read_text", "read_lines", "cut_torn_tail",
           "append_line"]

log = logging.getLogger(__name__)

#: how far back from the end :func:`cut_torn_tail` looks for the last line end, bytes
TAIL_WINDOW = 1 << 16


def datasync(fd: int) -> None:
    """``fdatasync`` where the OS has it (Linux), else ``fsync``: the file's data is on the
    disk itself, not only in the OS's cache (it survives a power cut)."""
    getattr(os, "fdatasync", os.fsync)(fd)


def write_atomic(path: Path, data: str | bytes, *, sync: bool = False) -> None:
    """Write ``data`` (text, written as UTF-8, or bytes) to a temporary file beside
    ``path``, then rename it over ``path``; with ``sync`` the data is on the disk
    (:func:`datasync`) before the rename, so the new file survives a power cut too.
    Raises :class:`OutputError` naming ``path`` (the old file, if any, is left intact)."""
    raw = data.encode("utf-8") if isinstance(data, str) else data
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with tmp.open("wb") as fh:
            fh.write(raw)
            fh.flush()
            if sync:
                datasync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise OutputError(f"{path}: cannot write: {exc.strerror or exc}") from exc


def read_text(path: str | Path) -> str:
    """The file's text, UTF-8 with no newline translation. Raises :class:`DataError`
    naming the file and byte when it is not UTF-8 (an ``OSError`` when it cannot be read)."""
    data = Path(path).read_bytes()
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not UTF-8 text (byte {exc.start})") from None


def read_lines(path: str | Path, *, what: str = "line",
               complete: Callable[[str], bool] | None = None) -> list[str]:
    """The lines of a growing file, without their line ends; line ``i + 1`` of the file
    is item ``i``.

    The text after the last ``\\n`` is a torn last line (an append cut short) and is left
    out, with a warning naming the file and line (``what`` names a line in it, e.g.
    ``"entry"``), unless ``complete(tail)`` says it is whole (a hand-written file whose
    last line has no line end): then it is kept.
    """
    lines = read_text(path).split("\n")
    tail = lines.pop()
    if tail:
        if complete is not None and complete(tail):
            lines.append(tail)
        else:
            log.warning("%s: line %d: torn last %s left out: %r", path, len(lines) + 1,
                        what, tail[:80])
    return lines


def cut_torn_tail(path: Path, *, complete: Callable[[bytes], bool] | None = None) -> int:
    """Make ``path`` end in a line end before it is appended to: a torn last line is cut
    off (a warning says how many bytes), or, if ``complete(tail)`` says the last line is
    whole, its line end is added. Returns the bytes removed."""
    size = path.stat().st_size
    if size == 0:
        return 0
    with path.open("rb+") as fh:
        fh.seek(-1, os.SEEK_END)
        if fh.read(1) == b"\n":
            return 0
        back = min(size, TAIL_WINDOW)
        fh.seek(size - back)
        tail = fh.read(back)
        start = tail.rfind(b"\n") + 1  # of the last line in tail (0: none in the window)
        keep = size - back + start if start else 0
        if complete is not None and complete(tail[start:]):
            fh.seek(0, os.SEEK_END)
            fh.write(b"\n")
            log.warning("%s: added the line end of its last line", path)
            return 0
        fh.truncate(keep)
    log.warning("%s: cut a torn last line (%d bytes)", path, size - keep)
    return size - keep


def append_line(path: Path, line: str, *, sync: bool = True) -> None:
    """Append one line (``line`` without its line end) and flush it to the disk (with
    ``sync``, ``fsync``). Raises ``OSError`` (the caller says what was not recorded)."""
    with path.open("a", encoding="utf-8") as fh:
        fh.write(line + "\n")
        fh.flush()
        if sync:
            os.fsync(fh.fileno())
