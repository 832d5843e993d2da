"""Where each file of a run folder lives, how a run folder is named, found and locked.

::

    <output>/<session name>-<UTC yyyymmdd-HHMMSS>[-n]/
        raw.blf, raw-2.blf, ...  the raw log, one file per segment (RAW_LOG, raw_segments)
        <gyro>/samples.csv       1-s bins (SAMPLES)
        <gyro>/estimates.csv     online estimates after every bin (ESTIMATES)
        <gyro>/samples.parquet,  the same tables as Parquet, written at the run's end with
        <gyro>/estimates.parquet   session.formats: [parquet] or --data-format parquet
        <run folder name>.mf4    the run as MDF4, at the end with formats: [mf4]
        result.json              final fits and counts (RESULT)
        segments.json            each raw segment's counts (SEGMENTS_FILE)
        report.txt               the final table (REPORT)
        snapshot.json            online estimates at a snapshot command (SNAPSHOT)
        ledger.jsonl             the workbench's steps (LEDGER)
        run.log                  the run's log (RUN_LOG)
        .lock                    held by the daemon writing the folder (LOCK)

The folder name uses the wall clock (it names a file, it is not data); a suffix ``-2``,
``-3``, ... keeps two runs started in the same second apart.
"""

from __future__ import annotations

import fcntl
import os
import re
import time
from pathlib import Path

from ..errors import OutputError

__all__ = ["SAMPLES", "ESTIMATES", "RESULT", "REPORT", "SNAPSHOT", "SEGMENTS_FILE",
           "LEDGER", "RUN_LOG", "LOCK", "RAW_LOG", "samples_path", "estimates_path",
           "csv_ledger_path", "make_run_dir", "latest_run_dir", "raw_segments",
           "next_raw_segment", "check_writable", "RunLock", "DATA_FORMATS"]

SAMPLES = "samples.csv"
ESTIMATES = "estimates.csv"
RESULT = "result.json"
REPORT = "report.txt"
SNAPSHOT = "snapshot.json"
SEGMENTS_FILE = "segments.json"
LEDGER = "ledger.jsonl"
RUN_LOG = "run.log"
LOCK = ".lock"
RAW_LOG = "raw.blf"
#: the formats a run also writes its samples and estimates in, beside the CSVs (which are
#: always written), at its end (``session.formats``, ``--data-format``), each with the
#: package it needs (:mod:`gyrostand.session.export` writes them)
DATA_FORMATS = {"parquet": "pyarrow", "mf4": "asammdf"}


def samples_path(run_dir: str | Path, gyro: str) -> Path:
    """``<run>/<gyro>/samples.csv``."""
    return Path(run_dir) / gyro / SAMPLES


def estimates_path(run_dir: str | Path, gyro: str) -> Path:
    """``<run>/<gyro>/estimates.csv``."""
    return Path(run_dir) / gyro / ESTIMATES


def csv_ledger_path(csv_path: str | Path) -> Path:
    """The ledger of a plain CSV subject: ``<csv stem>.ledger.jsonl`` beside it."""
    p = Path(csv_path)
    return p.with_name(p.stem + ".ledger.jsonl")


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
        return run_dir / RAW_LOG
    m = _SEG_RE.match(segs[-1].name)
    n = int(m[1] or 1) if m else len(segs)
    return run_dir / f"raw-{n + 1}.blf"


def check_writable(run_dir: Path) -> None:
    """Fail early, naming the folder, when files cannot be created in ``run_dir``."""
    probe = run_dir / f".write-probe-{os.getpid()}"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise OutputError(f"{run_dir}: cannot write in the run folder: "
                          f"{exc.strerror or exc}") from exc


class RunLock:
    """An exclusive ``flock`` on ``<run>/.lock`` for as long as a daemon writes the folder:
    a second daemon (e.g. ``--resume`` of a folder still being written) is refused; the
    kernel drops the lock when the holder dies, even by ``kill -9``."""

    def __init__(self, run_dir: Path) -> None:
        self.path = run_dir / LOCK
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
