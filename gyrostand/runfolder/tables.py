"""The run folder's two tables per gyro, ``samples.csv`` and ``estimates.csv``: one
committed-CSV writer for both, and their readers.

``<gyro>/samples.csv``: ``t, drift, temp, n_drift, n_temp``, one row per closed 1-s bin
(t = bin start, s; drift and temp the bin means, ``nan`` in a gap; floats in Python's
shortest round-trip form, so a file read back gives the same floats).

``<gyro>/estimates.csv``: ``t``, then per online identifier and parameter
``<id>:<param>``, ``<id>:<param>:std``, then ``<id>:status``; one row per closed bin, the
estimates after that bin (``%.9g``, ``nan`` while unknown).

Both are written by :class:`CommittedCSV`: rows wait in memory until :meth:`commit`, which
writes them with one write (and with ``sync`` an ``fdatasync``). The daemon commits the
raw log first, then the samples, then the estimates, so a row on disk (*acknowledged*)
always replays from the raw log.
"""

from __future__ import annotations

import csv
import io
import logging
import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, TextIO

from ..errors import DataError, OutputError
from .files import datasync, read_lines
from .layout import samples_path

if TYPE_CHECKING:
    from ..can.binning import Bin

__all__ = ["CommittedCSV", "SamplesWriter", "EstimatesWriter", "SAMPLES_COLUMNS",
           "estimate_columns", "samples_row", "estimates_row", "read_samples_csv",
           "read_estimates_csv", "cut_estimates_after", "read_header", "csv_line"]

log = logging.getLogger(__name__)

SAMPLES_COLUMNS = ("t", "drift", "temp", "n_drift", "n_temp")


class CommittedCSV:
    """One growing CSV of the run folder whose rows reach the disk only when committed.

    The constructor only stores; :meth:`open` creates the file with its header (or, with
    ``append`` and a file that is not empty, continues it: a resumed run). :meth:`add`
    queues a row (a line without its line end), :meth:`commit` writes every queued row with
    one write and flushes it (``sync``: also ``fdatasync``). Raises :class:`OutputError`
    naming the file.
    """

    def __init__(self, path: Path, header: Sequence[str], *, append: bool = False,
                 sync: bool = False) -> None:
        self.path = path
        self.header = tuple(header)
        self.append = append
        self.sync = sync
        self.rows = 0  # rows this writer committed to the disk
        self._pending: list[str] = []
        self._f: TextIO | None = None
        self._closed = False  # once closed, never opened again (it would start over)

    @property
    def pending(self) -> int:
        return len(self._pending)

    def open(self) -> None:
        path = self.path
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fresh = not (self.append and path.is_file() and path.stat().st_size > 0)
            self._f = path.open("w" if fresh else "a", newline="", encoding="utf-8")
            if fresh:
                self._f.write(csv_line(self.header))
                self._f.flush()
        except OSError as exc:
            raise OutputError(f"{path}: cannot write: {exc.strerror or exc}") from exc

    def add(self, line: str) -> None:
        self._pending.append(line)

    def commit(self) -> None:
        """Every queued row to the disk (a file not opened yet is opened first)."""
        if self._closed:
            if self._pending:
                raise OutputError(f"{self.path}: cannot write: the file is closed")
            return
        if self._f is None:
            self.open()
        f = self._f
        assert f is not None
        if not self._pending:
            return
        try:
            f.write("\n".join(self._pending) + "\n")
            f.flush()
            if self.sync:
                datasync(f.fileno())
        except OSError as exc:
            raise OutputError(f"{self.path}: cannot write: {exc.strerror or exc}") from exc
        self.rows += len(self._pending)
        self._pending.clear()

    def close(self, *, commit: bool = True) -> None:
        """Commit and close (a file never opened is created first: every run's table
        exists, if only with its header). ``commit=False``: close only; rows not yet
        committed are dropped (e.g. after the raw log they were binned from failed to
        reach the disk: they were never acknowledged)."""
        try:
            if commit:
                self.commit()
        finally:
            self._closed = True
            if self._f is not None:
                try:
                    self._f.close()
                except OSError:  # the unwritable tail is lost; commit() said so
                    pass
                self._f = None


def csv_line(cells: Sequence[str]) -> str:
    """One CSV line with its line end (cells quoted only where CSV needs it)."""
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(cells)
    return buf.getvalue()


# -- samples.csv ----------------------------------------------------------------------------

def samples_row(b: Bin) -> str:
    """A bin's row (t = bin start; ``repr``: the shortest text that reads back the same)."""
    return f"{b.t!r},{b.drift!r},{b.temp!r},{b.n_drift},{b.n_temp}"


class SamplesWriter:
    """Write each gyro's bins to ``<run_dir>/<gyro>/samples.csv`` (one
    :class:`CommittedCSV` per gyro).

    Rows are held in memory until :meth:`flush` (or until ``max_pending`` rows wait), which
    first calls ``before_flush`` (the live daemon passes the raw recorder's flush) and then
    commits every file. So a row reaches the disk only after every frame it was binned
    from: a row on disk is *acknowledged*, and the raw log replays to it. ``append``
    continues existing files (a resumed run) instead of starting them over. The files are
    created at once unless ``open_now`` is false (then by :meth:`open`, or the first flush).
    """

    def __init__(self, run_dir: str | Path, gyros: Sequence[str], *,
                 before_flush: Callable[[], None] | None = None, max_pending: int = 4096,
                 append: bool = False, sync: bool = False, open_now: bool = True) -> None:
        self.sync = sync
        self.before_flush = before_flush
        self.max_pending = int(max_pending)
        self.files = {name: CommittedCSV(samples_path(run_dir, name), SAMPLES_COLUMNS,
                                         append=append, sync=sync) for name in gyros}
        self.paths: dict[str, Path] = {name: f.path for name, f in self.files.items()}
        self._n_pending = 0
        if open_now:
            self.open()

    def open(self) -> None:
        for f in self.files.values():
            f.open()

    @property
    def rows(self) -> int:
        """Rows written to disk by this writer."""
        return sum(f.rows for f in self.files.values())

    def write(self, bins: Iterable[Bin]) -> None:
        files = self.files
        for b in bins:
            files[b.gyro].add(samples_row(b))
            self._n_pending += 1
        if self._n_pending >= self.max_pending:
            self.flush()

    def flush(self) -> None:
        """``before_flush()``, then every pending row to disk (one write per file; with
        ``sync``, each file is fdatasync'ed after its write).
        Raises :class:`~gyrostand.errors.OutputError` naming the file that failed."""
        if self.before_flush is not None:
            self.before_flush()
        for f in self.files.values():
            f.commit()
        self._n_pending = 0

    def close(self) -> None:
        """:meth:`flush`, then close every file; when the flush fails (e.g. the raw log
        could not be written) the rows still pending are dropped, never written."""
        try:
            self.flush()
        finally:
            for f in self.files.values():
                f.close(commit=False)

    def __enter__(self) -> SamplesWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_samples_csv(path: str | Path) -> dict[str, list[float]]:
    """Read a ``samples.csv`` back as columns of floats (counts as floats too).

    A last line without its line end is torn (the writer was killed or the disk filled
    mid-line): it is left out with a warning (:func:`~gyrostand.runfolder.files.read_lines`)."""
    rows = [r.split(",") for r in read_lines(path)]
    if not rows:
        raise DataError(f"{path}: empty file (expected the header {','.join(SAMPLES_COLUMNS)})")
    header, body = rows[0], rows[1:]
    if tuple(header) != SAMPLES_COLUMNS:
        raise DataError(f"{path}: unexpected columns {header}")
    try:
        return {name: [float(r[i]) for r in body] for i, name in enumerate(header)}
    except (ValueError, IndexError) as exc:
        raise DataError(f"{path}: not a samples file ({exc})") from None


# -- estimates.csv --------------------------------------------------------------------------

class Estimate(Protocol):
    """What a row is made of (:class:`~gyrostand.core.tracking.OnlineEstimate`): read-only
    ``values`` (parameter name -> (value, std)) and ``status``."""

    @property
    def values(self) -> Any: ...

    @property
    def status(self) -> str: ...


def estimate_columns(identifiers: Sequence[str], param_names: Sequence[str]) -> list[str]:
    """``t`` then, per identifier and parameter, ``<id>:<param>`` and ``<id>:<param>:std``,
    then ``<id>:status``."""
    cols = ["t"]
    for ident in identifiers:
        for p in param_names:
            cols += [f"{ident}:{p}", f"{ident}:{p}:std"]
        cols.append(f"{ident}:status")
    return cols


def _num(x: float) -> str:
    return "nan" if math.isnan(x) else f"{x:.9g}"


#: the row format of (identifiers, parameters): ``%.9g`` formats a number as ``_num`` does
#: (``nan`` for any NaN, ``inf``, ``-0``: one formatting routine), in one operation a row
_ROW_FORMATS: dict[tuple[int, int], str] = {}


def estimates_row(t: float, estimates: Sequence[Estimate], param_names: Sequence[str]
                  ) -> str:
    """The row of bin ``t``: per identifier each parameter's value and std, its status."""
    shape = (len(estimates), len(param_names))
    fmt = _ROW_FORMATS.get(shape)
    if fmt is None:
        fmt = _ROW_FORMATS[shape] = "%r" + (",%.9g,%.9g" * shape[1] + ",%s") * shape[0]
    args: list[Any] = [t]
    for e in estimates:
        values = e.values
        for p in param_names:
            args += values[p]
        args.append(e.status)
    return fmt % tuple(args)


class EstimatesWriter:
    """``<run>/<gyro>/estimates.csv``: one row per closed bin (t = bin start, s), the
    online estimates after that bin (NaN written ``nan`` while unknown); a
    :class:`CommittedCSV` committed by :meth:`flush` (or when ``max_pending`` rows wait)."""

    def __init__(self, path: Path, identifiers: Sequence[str],
                 param_names: Sequence[str], *, append: bool = False,
                 sync: bool = False, max_pending: int = 4096, open_now: bool = True) -> None:
        self.path = path
        self.sync = sync
        self.param_names = tuple(param_names)
        self.max_pending = int(max_pending)
        self.file = CommittedCSV(path, estimate_columns(identifiers, param_names),
                                 append=append, sync=sync)
        if open_now:
            self.open()

    def open(self) -> None:
        self.file.open()

    def write(self, t: float, estimates: Sequence[Estimate]) -> None:
        self.file.add(estimates_row(t, estimates, self.param_names))
        if self.file.pending >= self.max_pending:
            self.file.commit()

    def flush(self) -> None:
        self.file.commit()

    def close(self) -> None:
        self.file.close()


def read_estimates_csv(path: Path) -> dict[str, list[Any]]:
    """An ``estimates.csv`` back as columns by name: ``<id>:status`` as strings, every
    other column as floats (``nan`` while unknown). A last line without its line end is
    torn (the run was killed while appending it): it is left out with a warning; a row
    with the wrong number of cells is an error naming its line."""
    reader = csv.reader(read_lines(path))
    try:
        rows = list(reader)
    except csv.Error as exc:  # e.g. a cell over csv.field_size_limit() (128 KiB)
        raise OutputError(f"{path}: line {reader.line_num}: not CSV ({exc})") from None
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


def cut_estimates_after(path: Path, t_last: float | None) -> float | None:
    """Cut estimate rows of bins after ``t_last`` (None: keep only the header); return the
    t of the last row kept (None when none). For a resumed run: both tables end at the
    same bin. (The file ends in a line end: :func:`~gyrostand.runfolder.files.cut_torn_tail`
    first.)"""
    with path.open("rb") as fh:
        lines = fh.read().split(b"\n")
    body = lines[1:-1] if lines and lines[-1] == b"" else lines[1:]
    keep, last = len(lines[0]) + 1, None
    for ln in body:
        try:
            t = float(ln.split(b",", 1)[0])
        except ValueError:
            break
        if t_last is None or t > t_last:
            break
        keep += len(ln) + 1
        last = t
    if keep < path.stat().st_size:
        with path.open("rb+") as fh:
            fh.truncate(keep)
        log.warning("%s: cut estimate rows after the last kept bin", path)
    return last


def read_header(path: Path) -> list[str] | None:
    """The cells of a table's first line (its columns), or None when the file cannot be
    read or is empty."""
    try:
        with path.open(encoding="utf-8", errors="replace") as fh:
            header = fh.readline().rstrip("\n").split(",")
    except OSError:
        return None
    return None if header == [""] else header
