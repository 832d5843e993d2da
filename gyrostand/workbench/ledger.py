"""The workbench's ledger: one JSON object per line, one line per step.

``<run>/ledger.jsonl`` (or ``<csv stem>.ledger.jsonl`` beside a CSV subject). A step is
appended whole and fsync'ed; the ledger is a growing file of the run folder, so a torn
last entry (the process died while appending it) is left out by the reader and cut off
before the next append (:mod:`gyrostand.runfolder.files`); a last entry that is whole but
lost its line end (a hand-edited ledger) is kept, and gets its line end back.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import logging
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..errors import DataError, OutputError
from ..runfolder import append_line, cut_torn_tail, read_lines

__all__ = ["read_ledger", "append_ledger", "ledger_lock"]

log = logging.getLogger(__name__)


def _whole(line: str | bytes) -> bool:
    """A last line that needs no cut: blank, or a JSON value."""
    if not line.strip():
        return True
    try:
        json.loads(line)
    except (ValueError, RecursionError):  # JSONDecodeError and UnicodeDecodeError too
        return False
    return True


def read_ledger(path: Path) -> list[dict[str, Any]]:
    """All entries of a ledger (a missing ledger is empty); a bad line names its number."""
    if not path.exists():
        return []
    out = []
    for i, line in enumerate(read_lines(path, what="entry", complete=_whole), start=1):
        if not line.strip():
            continue
        try:
            entry = json.loads(line)
        except (json.JSONDecodeError, RecursionError) as exc:
            why = exc.msg if isinstance(exc, json.JSONDecodeError) else "nested too deep"
            raise DataError(f"{path}: line {i}: not a JSON ledger entry ({why})") from None
        if not isinstance(entry, dict) or not isinstance(entry.get("model", []), (list, str)):
            raise DataError(f"{path}: line {i}: a ledger entry is a JSON object (with "
                            f"'model' a list of terms), got {type(entry).__name__}")
        out.append(entry)
    return out


def append_ledger(path: Path, entry: dict[str, Any]) -> dict[str, Any]:
    """Append one step (with its number and UTC time) and flush it to disk."""
    steps = read_ledger(path)
    entry = {"step": len(steps) + 1,
             "time": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"), **entry}
    try:
        if path.exists():
            cut_torn_tail(path, complete=_whole)
        append_line(path, json.dumps(entry, allow_nan=False))
    except OSError as exc:
        raise OutputError(f"{path}: cannot record the step: {exc.strerror or exc}") from exc
    return entry


@contextlib.contextmanager
def ledger_lock(path: Path) -> Iterator[None]:
    """Hold the ledger for a read-fit-append (an exclusive ``flock`` on the ledger file,
    created empty if missing): two ``fit`` commands on one run at once each start from
    the model the other recorded, one after the other (before, the second started from
    the model both had read and its step dropped the first's term). Where ``fcntl`` is
    missing (Windows) nothing is held."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    try:
        fh = path.open("a", encoding="utf-8")
    except OSError as exc:
        raise OutputError(f"{path}: cannot open the ledger: {exc.strerror or exc}") from exc
    with fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
