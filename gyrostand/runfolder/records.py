"""The run folder's JSON files and its log: ``result.json`` (read back), ``segments.json``
(each raw segment's counts) and ``run.log``.

``result.json`` is written by :mod:`gyrostand.session.final` (its content) through
:func:`write_json` (atomically); every reader goes through :func:`read_result` (a run
folder must have one: an error otherwise) or :func:`read_result_or_none` (a hint only).
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..errors import DataError, NoInputError
from .files import read_text, write_atomic
from .layout import RESULT, RUN_LOG, SEGMENTS_FILE

__all__ = ["write_json", "finite", "json_safe", "read_result", "read_result_or_none", "SegmentLog",
           "read_segments", "RunLog"]

log = logging.getLogger(__name__)


def write_json(path: Path, doc: Any, *, indent: int = 2, allow_nan: bool = False) -> None:
    """``doc`` as JSON (with a final line end) to ``path``, atomically
    (:func:`~gyrostand.runfolder.files.write_atomic`). Raises :class:`OutputError`;
    ``ValueError`` for a NaN or infinity unless ``allow_nan``."""
    write_atomic(path, json.dumps(doc, indent=indent, allow_nan=allow_nan) + "\n")


def finite(x: float) -> float | None:
    """``x`` as a JSON number: a float, or None (``null``) when it is NaN or infinite."""
    return float(x) if math.isfinite(x) else None


def json_safe(x: Any) -> Any:
    """``x`` with every float :func:`finite` (nested mappings, with string keys, and
    sequences as lists): what ``result.json``'s counts and every document printing them
    hold, strict JSON with no NaN."""
    if isinstance(x, float):
        return finite(x)
    if isinstance(x, Mapping):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [json_safe(v) for v in x]
    return x


def read_result(run_dir: str | Path) -> dict[str, Any]:
    """``<run>/result.json``, checked to have the shape its readers use (an object, ``dt``
    a positive number, ``gyros`` an object of objects whose ``model`` is a list of term
    names); else a :class:`DataError` naming the file (and line or key), also when the
    folder has none (not a run folder)."""
    path = Path(run_dir) / RESULT
    if not path.is_file():
        raise NoInputError(f"{run_dir}: not a run folder (no result.json)")
    try:
        info = json.loads(read_text(path))
    except json.JSONDecodeError as exc:
        raise DataError(f"{path}: line {exc.lineno}: invalid JSON ({exc.msg})") from None
    except OSError as exc:
        raise DataError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if not isinstance(info, dict):
        raise DataError(f"{path}: expected a JSON object, got {type(info).__name__}")
    dt = info.get("dt", 1.0)
    if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not (
            math.isfinite(dt) and dt > 0):
        raise DataError(f"{path}: dt: expected a positive number of seconds, got "
                        f"{str(dt)[:40]!r}")
    gyros = info.get("gyros", {})
    if not isinstance(gyros, dict) or not all(isinstance(g, dict) for g in gyros.values()):
        raise DataError(f"{path}: gyros: expected an object of gyro objects")
    for name, g in gyros.items():
        model = g.get("model", [])
        if not (isinstance(model, list) and all(isinstance(m, str) for m in model)):
            raise DataError(f"{path}: gyros.{str(name)[:40]}.model: expected a list of "
                            f"term names")
    return info


def read_result_or_none(run_dir: str | Path) -> Any:
    """``<run>/result.json`` as parsed, or None when it is missing or unreadable (for
    readers that only take hints from it)."""
    try:
        return json.loads((Path(run_dir) / RESULT).read_text(encoding="utf-8"))
    except (OSError, ValueError):  # UnicodeDecodeError and JSONDecodeError are ValueErrors
        return None


# -- the segments of a live run -----------------------------------------------------------

_CRASHED = "crashed: counts as of its last acknowledgement"


def read_segments(run_dir: Path) -> list[dict[str, Any]]:
    """The earlier segments recorded in ``<run>/segments.json`` (for a resumed run); one
    still marked ``running`` belonged to a daemon that died: it is marked crashed. A
    missing file gives []; a damaged one is logged and gives [] (the counts are lost,
    nothing else)."""
    path = Path(run_dir) / SEGMENTS_FILE
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        segs = [dict(x) for x in doc["segments"]]
    except FileNotFoundError:
        return []
    except (OSError, ValueError, KeyError, TypeError) as exc:
        log.warning("%s: unreadable (%s); the earlier segments' counts are lost", path, exc)
        return []
    for seg in segs:
        if seg.get("state") == "running":
            seg["state"], seg["ended_by"] = "crashed", _CRASHED
    return segs


def _add(total: dict[str, Any], part: dict[str, Any]) -> None:
    for k, v in part.items():
        if isinstance(v, dict):
            _add(total.setdefault(k, {}), v)
        elif isinstance(v, int | float) and not isinstance(v, bool):
            total[k] = total.get(k, 0) + v


class SegmentLog:
    """``<run>/segments.json``: for each raw segment of a live run (``raw.blf``, then one
    per resume) its decoder and binner counts and the rows it wrote, rewritten atomically
    at every acknowledgement, so a daemon that dies leaves its counts as of its last
    acknowledgement. :meth:`totals` sums the counts over the segments."""

    def __init__(self, run_dir: Path, raw: str, previous: Sequence[dict[str, Any]] = ()
                 ) -> None:
        self.path = Path(run_dir) / SEGMENTS_FILE
        self.previous = [dict(x) for x in previous]
        self.current: dict[str, Any] = {
            "raw": raw, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "state": "running"}

    def update(self, stats: dict[str, Any], *, ended_by: str | None = None,
               extra: dict[str, Any] | None = None) -> None:
        """Record this segment's counts (:meth:`Pipeline.counts`: ``decoder``, ``binner``,
        ``samples``; plus ``extra``, e.g. the recorder's) and write the file;
        ``ended_by`` marks the segment finished. Raises :class:`OutputError`."""
        cur = self.current
        cur["decoder"] = stats["decoder"]
        cur["binner"] = stats["binner"]
        cur["rows_written"] = stats["samples"]["rows_written"]
        cur.update(extra or {})
        if ended_by is not None:
            cur["state"], cur["ended_by"] = "finished", ended_by
            cur["ended"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        write_json(self.path, {"segments": self.segments()}, indent=1)

    def segments(self) -> list[dict[str, Any]]:
        return self.previous + [self.current]

    def totals(self) -> dict[str, Any]:
        """Counts summed over every segment (crashed ones as of their last
        acknowledgement): ``decoder``, ``binner``, ``rows_written`` and the like."""
        total: dict[str, Any] = {}
        for seg in self.segments():
            _add(total, {k: v for k, v in seg.items() if k not in ("raw", "started",
                                                                  "ended", "state",
                                                                  "ended_by")})
        return total


class _RunLogHandler(logging.FileHandler):
    """``run.log``'s handler: a record it cannot write (a full disk) is dropped and
    counted (``failed``), never a "--- Logging error ---" traceback on stderr; the
    console handler still shows every record."""

    failed = 0

    def handleError(self, record: logging.LogRecord) -> None:  # noqa: N802 (logging's)
        self.failed += 1


class RunLog:
    """Attach a ``run.log`` file handler to the ``gyrostand`` logger for one run (INFO and
    above, with wall-clock times); :meth:`close` detaches it."""

    def __init__(self, run_dir: Path, level: int = logging.INFO) -> None:
        self.path = run_dir / RUN_LOG
        self.handler = _RunLogHandler(self.path, encoding="utf-8")
        self.handler.setLevel(level)
        self.handler.setFormatter(logging.Formatter(
            "%(asctime)s %(levelname)s %(name)s: %(message)s"))
        self.logger = logging.getLogger("gyrostand")
        self._old_level = self.logger.level
        if self.logger.getEffectiveLevel() > level:
            self.logger.setLevel(level)
        self.logger.addHandler(self.handler)

    def close(self) -> None:
        self.logger.removeHandler(self.handler)
        self.logger.setLevel(self._old_level)
        try:
            self.handler.close()
        except OSError:  # its last lines cannot be flushed (a full disk): they are lost
            pass
