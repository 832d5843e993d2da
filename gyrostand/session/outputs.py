"""The run folder and what is written into it.

::

    <output>/<session name>-<UTC yyyymmdd-HHMMSS>/
        raw.blf              every raw frame received (live runs; replayable)
        raw-2.blf, ...       the raw log of each resumed segment (``run --resume``)
        <gyro>/samples.csv   1-s bins: t, drift, temp, n_drift, n_temp
        <gyro>/estimates.csv online estimates after every bin, with stds
        result.json          final batch fits per gyro + counts
        report.txt           the final table and counts, readable
        run.log              the log of the run

The folder name uses the wall clock (it names a file, it is not data); a suffix ``-2``,
``-3``, ... keeps two runs started in the same second apart.

Files that are rewritten (``result.json``, ``report.txt``, ``snapshot.json``) are written
to a temporary file beside them and renamed into place (:func:`write_atomic`), so a reader
sees the old or the new file, never half of one. Files that grow (``samples.csv``,
``estimates.csv``, ``run.log``, ``ledger.jsonl``) are appended line by line; a reader
leaves out a torn last line (no line end).
"""

from __future__ import annotations

import csv
import fcntl
import json
import logging
import math
import os
import re
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

from ..can.binning import datasync
from ..errors import OutputError
from .online import OnlineEstimate

__all__ = ["make_run_dir", "RunLog", "EstimatesWriter", "estimate_columns", "write_atomic",
           "raw_segments", "next_raw_segment", "latest_run_dir", "RunLock", "check_writable",
           "SegmentLog", "read_segments", "SEGMENTS_FILE", "read_estimates_csv"]

log = logging.getLogger(__name__)


def make_run_dir(output: str | Path, name: str, wall: float | None = None) -> Path:
    """Create and return a fresh ``<output>/<name>-<timestamp>`` folder."""
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime(time.time() if wall is None else wall))
    base = Path(output) / f"{name}-{stamp}"
    path, n = base, 1
    while True:
        try:
            path.mkdir(parents=True)
            return path
        except FileExistsError:
            if not Path(output).is_dir():  # a file where the output folder should be
                raise OutputError(f"{output}: cannot create the run folder there: not a "
                                  "folder") from None
            n += 1
            path = base.with_name(f"{base.name}-{n}")
        except OSError as exc:
            raise OutputError(f"{path}: cannot create the run folder: "
                              f"{exc.strerror or exc}") from exc


class RunLock:
    """An exclusive ``flock`` on ``<run>/.lock`` for as long as a daemon writes the folder:
    a second daemon (e.g. ``--resume`` of a folder still being written) is refused; the
    kernel drops the lock when the holder dies, even by ``kill -9``."""

    def __init__(self, run_dir: Path) -> None:
        self.path = run_dir / ".lock"
        try:
            self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise OutputError(f"{self.path}: cannot create the run folder's lock: "
                              f"{exc.strerror or exc}") from exc
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.pread(self._fd, 32, 0).decode(errors="replace").strip() or "?"
            os.close(self._fd)
            raise OutputError(f"{run_dir}: in use by a running daemon (pid {holder})") \
                from None
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, f"{os.getpid()}\n".encode(), 0)

    def release(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)  # releases the lock
            self._fd = -1


def check_writable(run_dir: Path) -> None:
    """Fail early, naming the folder, when files cannot be created in ``run_dir``."""
    probe = run_dir / f".write-probe-{os.getpid()}"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise OutputError(f"{run_dir}: cannot write in the run folder: "
                          f"{exc.strerror or exc}") from exc


_RUN_RE = re.compile(r"^(?P<stamp>\d{8}-\d{6})(?:-(?P<n>\d+))?$")


def latest_run_dir(output: str | Path, name: str, *, live_only: bool = False) -> Path:
    """The newest ``<output>/<name>-<stamp>[-n]`` folder (by its UTC stamp, then n);
    ``live_only``: only folders of live runs (with a raw log: a replay folder has none)."""
    found: list[tuple[str, int, Path]] = []
    out = Path(output)
    if out.is_dir():
        for p in out.iterdir():
            if p.is_dir() and p.name.startswith(f"{name}-"):
                m = _RUN_RE.match(p.name[len(name) + 1:])
                if m and not (live_only and not raw_segments(p)):
                    found.append((m["stamp"], int(m["n"] or 1), p))
    if not found:
        kind = "live run folder (with raw.blf)" if live_only else "run folder"
        raise OutputError(f"{out}: no {kind} of session {name!r} to resume")
    return max(found)[2]


_SEG_RE = re.compile(r"^raw(?:-(\d+))?\.blf$")


def raw_segments(run_dir: Path) -> list[Path]:
    """The run's raw logs in recording order: ``raw.blf``, ``raw-2.blf``, ..."""
    segs = []
    for p in Path(run_dir).iterdir():
        m = _SEG_RE.match(p.name)
        if m and p.is_file():
            segs.append((int(m[1] or 1), p))
    return [p for _, p in sorted(segs)]


def next_raw_segment(run_dir: Path) -> Path:
    """The file the next raw segment goes to (``raw.blf`` for a new run)."""
    segs = raw_segments(run_dir)
    if not segs:
        return run_dir / "raw.blf"
    m = _SEG_RE.match(segs[-1].name)
    n = int(m[1] or 1) if m else len(segs)
    return run_dir / f"raw-{n + 1}.blf"


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to a temporary file beside ``path``, then rename it over ``path``.
    Raises :class:`OutputError` naming ``path`` (the old file, if any, is left intact)."""
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with tmp.open("w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
        os.replace(tmp, path)
    except OSError as exc:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise OutputError(f"{path}: cannot write: {exc.strerror or exc}") from exc


class RunLog:
    """Attach a ``run.log`` file handler to the ``gyrostand`` logger for one run (INFO and
    above, with wall-clock times); :meth:`close` detaches it."""

    def __init__(self, run_dir: Path, level: int = logging.INFO) -> None:
        self.path = run_dir / "run.log"
        self.handler = logging.FileHandler(self.path, encoding="utf-8")
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
        self.handler.close()


def estimate_columns(identifiers: Sequence[str], param_names: Sequence[str]) -> list[str]:
    """``t`` then, per identifier and parameter, ``<id>:<param>`` and ``<id>:<param>:std``,
    then ``<id>:status``."""
    cols = ["t"]
    for ident in identifiers:
        for p in param_names:
            cols += [f"{ident}:{p}", f"{ident}:{p}:std"]
        cols.append(f"{ident}:status")
    return cols


class EstimatesWriter:
    """``<run>/<gyro>/estimates.csv``: one row per closed bin (t = bin start, s), the
    online estimates after that bin (NaN written ``nan`` while unknown)."""

    def __init__(self, path: Path, identifiers: Sequence[str],
                 param_names: Sequence[str], *, append: bool = False,
                 sync: bool = False) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self.sync = sync  # fdatasync at each flush
        self.param_names = tuple(param_names)
        fresh = not (append and path.is_file() and path.stat().st_size > 0)
        self._f: TextIO = path.open("w" if fresh else "a", newline="", encoding="utf-8")
        self._w = csv.writer(self._f, lineterminator="\n")
        if fresh:
            self._w.writerow(estimate_columns(identifiers, param_names))

    def write(self, t: float, estimates: Sequence[OnlineEstimate]) -> None:
        row: list[object] = [repr(t)]
        for e in estimates:
            for p in self.param_names:
                v, s = e.values[p]
                row += [_num(v), _num(s)]
            row.append(e.status)
        try:
            self._w.writerow(row)
        except OSError as exc:
            raise OutputError(f"{self.path}: cannot write: {exc.strerror or exc}") from exc

    def flush(self) -> None:
        try:
            self._f.flush()
            if self.sync:
                datasync(self._f.fileno())
        except OSError as exc:
            raise OutputError(f"{self.path}: cannot write: {exc.strerror or exc}") from exc

    def close(self) -> None:
        try:
            self.flush()
        finally:
            try:
                self._f.close()
            except OSError:
                pass


def read_estimates_csv(path: Path) -> dict[str, list[Any]]:
    """An ``estimates.csv`` back as columns by name: ``<id>:status`` as strings, every
    other column as floats (``nan`` while unknown). A last line without its line end is
    torn (the run was killed while appending it): it is left out with a warning; a row
    with the wrong number of cells is an error naming its line."""
    text = path.read_text(encoding="utf-8")
    lines = text.split("\n")
    if lines[-1]:
        log.warning("%s: torn last line left out: %r", path, lines[-1][:80])
    rows = list(csv.reader(lines[:-1]))
    if not rows or not rows[0] or rows[0][0] != "t":
        raise OutputError(f"{path}: not an estimates file (the header must start with t)")
    header = rows[0]
    cols: dict[str, list[Any]] = {h: [] for h in header}
    for lineno, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise OutputError(f"{path}: line {lineno}: {len(row)} cells, the header has "
                              f"{len(header)}")
        for h, cell in zip(header, row, strict=True):
            try:
                cols[h].append(cell if h.endswith(":status") else float(cell))
            except ValueError:
                raise OutputError(f"{path}: line {lineno}: column {h}: not a number: "
                                  f"{cell!r}") from None
    return cols


def _num(x: float) -> str:
    return "nan" if math.isnan(x) else f"{x:.9g}"


# -- the segments of a live run -----------------------------------------------------------

SEGMENTS_FILE = "segments.json"
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
        write_atomic(self.path, json.dumps({"segments": self.segments()}, indent=1,
                                           allow_nan=False) + "\n")

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
