"""Raw frame recorder: every frame as received, lossless, replayable, crash tolerant.

BLF (recommended: compact, fast, keeps CAN FD flags and timestamps) is written by
:class:`can.BLFWriter` (python-can's public API only) into a :class:`CommitFile`: nothing
reaches the disk until :meth:`Recorder.flush`, which stops the writer (python-can's
``stop`` compresses the pending log container and rewrites the header in place), commits
with one ``write``, and goes on with a writer that appends (``append=True``). So a process killed at any moment (even
``kill -9``) leaves a BLF whose last complete container ends at or after the last flush;
python-can's own writer, killed, leaves a torn object in ~7 % of cut points, which
``can.LogReader`` cannot read past (measured on every prefix of a file). A kill during
the append itself can still tear the last container (the kernel may cut a large write at
a page): :func:`gyrostand.can.replay.read_log` reads up to such a torn tail and warns.

Other suffixes go to :class:`can.Logger` (``.asc``, ``.log``, ``.csv``, ...), flushed at
the file level.

The recorder flushes itself whenever frame time has advanced ``flush_interval`` seconds
(1 s by default) since the last flush; call :meth:`Recorder.flush` from the daemon's 1-Hz
tick as well, so a silent bus still gets its tail written.

A write that fails (disk full, file size limit, I/O error) stops the recording: the error
is kept in :attr:`Recorder.failed` (a :class:`~gyrostand.errors.OutputError` naming the
file) for the daemon to stop on, logged once, and later frames are counted in ``errors``.

A frame whose timestamp is not finite cannot be stored by any log format (BLF's writer
fails on it and would lose the file header): it is counted in ``unrecordable`` and skipped;
the decoder rejects such frames anyway (``bad_timestamp``).
"""

from __future__ import annotations

import logging
import math
import os
import threading
from collections.abc import Callable
from pathlib import Path

import can

from gyrostand.errors import CanEdgeError, OutputError
from gyrostand.runfolder import datasync

__all__ = ["Recorder", "FlushingBLFWriter", "CommitFile"]

log = logging.getLogger(__name__)


class CommitFile:
    """A write-only binary file that holds every write in memory until :meth:`flush`
    (the *commit*): then in-place rewrites of already committed bytes (the BLF header) go
    out first with ``pwrite``, and the appended bytes with a single ``write`` (looped
    only if the kernel writes short). Memory is bounded by what is written between
    commits. After a failed commit the file refuses further writes (appending after a
    torn write would bury it mid-file).
    """

    def __init__(self, path: str | Path, *, sync_on_close: bool = False) -> None:
        self.name = str(path)
        self._fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_TRUNC, 0o644)
        self._committed = 0  # bytes on disk
        self._pending = bytearray()  # bytes after _committed, not yet on disk
        self._patches: list[tuple[int, bytes]] = []  # rewrites inside the committed part
        self._pos = 0
        self._broken: OSError | None = None
        self.closed = False
        self.sync_on_close = sync_on_close  # fdatasync before closing

    def seekable(self) -> bool:
        return True

    def fileno(self) -> int:
        return self._fd

    def tell(self) -> int:
        return self._pos

    def seek(self, offset: int, whence: int = 0) -> int:
        end = self._committed + len(self._pending)
        self._pos = {0: offset, 1: self._pos + offset, 2: end + offset}[whence]
        if not 0 <= self._pos <= end:
            raise ValueError(f"seek to {self._pos} outside [0, {end}]")
        return self._pos

    def read(self, size: int = -1) -> bytes:
        """Up to ``size`` bytes (all with -1) from the current position, committed or
        pending (a writer that appends reads the header back); not while rewrites of the
        committed part are pending."""
        if self.closed:
            raise ValueError("read from a closed CommitFile")
        if self._patches:
            raise ValueError("read before the pending rewrites are committed")
        pos, com = self._pos, self._committed
        end = com + len(self._pending)
        stop = end if size < 0 else min(end, pos + size)
        out = b""
        if pos < com:
            out += os.pread(self._fd, min(stop, com) - pos, pos)
        if stop > com:
            out += bytes(self._pending[max(pos, com) - com:stop - com])
        self._pos = pos + len(out)
        return out

    def write(self, data: bytes | bytearray | memoryview) -> int:
        if self.closed:
            raise ValueError("write to a closed CommitFile")
        if self._broken is not None:
            raise self._broken
        b = bytes(data)
        pos, end, com = self._pos, self._committed + len(self._pending), self._committed
        if pos == end:
            self._pending += b
        elif pos >= com and pos + len(b) <= end:
            self._pending[pos - com:pos - com + len(b)] = b
        elif pos + len(b) <= com:
            self._patches.append((pos, b))
        else:
            raise ValueError("a write may not straddle the committed end or the file end")
        self._pos = pos + len(b)
        return len(b)

    def flush(self) -> None:
        """Commit: rewrite patches in place, then append the pending bytes."""
        if self.closed or self._broken is not None:
            if self._broken is not None:
                raise self._broken
            return
        try:
            for off, b in self._patches:
                os.pwrite(self._fd, b, off)
            self._patches.clear()
            view = memoryview(self._pending)
            done = 0
            while done < len(view):
                done += os.write(self._fd, view[done:])
            view.release()
            self._committed += len(self._pending)
            self._pending.clear()
        except OSError as exc:
            self._broken = exc
            raise

    def close(self) -> None:
        if self.closed:
            return
        try:
            if self._broken is None:
                self.flush()
                if self.sync_on_close:
                    datasync(self._fd)
        finally:
            self.closed = True
            os.close(self._fd)


#: BLF header times before this (1990-01-01) are written as zeros, which read back as 0
_BLF_MIN_START = 631152000.0
#: how far before its first frame a BLF file starts (s): a clock that steps back by up to
#: this much is still recorded faithfully in the same file
BLF_MARGIN = 86400.0
#: how far after its start a BLF file records to the nanosecond (s): object times are
#: integer ns from the start, exact in a double below 2**53 ns
BLF_SPAN = 2.0**53 / 1e9


class _Segment:
    """A :class:`CommitFile` as one :class:`can.BLFWriter` sees it: the writer's ``stop``
    closes it, which commits; the file itself stays open for the next writer."""

    def __init__(self, file: CommitFile) -> None:
        self.file = file
        self.name = file.name
        self.closed = False

    def seekable(self) -> bool:
        return True

    def fileno(self) -> int:
        return self.file.fileno()

    def tell(self) -> int:
        return self.file.tell()

    def seek(self, offset: int, whence: int = 0) -> int:
        return self.file.seek(offset, whence)

    def read(self, size: int = -1) -> bytes:
        return self.file.read(size)

    def write(self, data: bytes | bytearray | memoryview) -> int:
        return self.file.write(data)

    def flush(self) -> None:
        self.file.flush()

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self.file.flush()


class FlushingBLFWriter(can.Listener):
    """A BLF log on a :class:`CommitFile`, written by :class:`can.BLFWriter`, with a
    :meth:`flush` that leaves a complete, readable file on disk (the BLF header, whose
    start time every object's timestamp is relative to, is committed before the
    containers that need it).

    python-can's public API only: :meth:`flush` is the writer's ``stop`` (the pending
    container compressed, the header rewritten in place) on a :class:`_Segment`, whose
    close commits; writing goes on with a ``can.BLFWriter(..., append=True)`` on the same
    file, which reads the counts and start time back from the header. The bytes are those
    one writer would write and stop with; ``tests/can`` checks the result is readable at
    every flush.

    python-can's writer starts the file at its first frame and stores an earlier frame
    with the start's time (an object time is unsigned); it also writes a start before
    1990 as zeros (read back as 0). So the file starts :data:`BLF_MARGIN` before the first
    frame (at 0 when that is before 1990), and :meth:`fits` says whether a frame's time
    can be stored to the nanosecond; the :class:`Recorder` starts a new file for one that
    cannot.
    """

    def __init__(self, path: str | Path, *, sync_on_close: bool = False,
                 max_container_size: int | None = None) -> None:
        """``max_container_size``: bytes of uncompressed objects per log container
        (python-can's option; default python-can's, 128 KiB)."""
        self.file = CommitFile(path, sync_on_close=sync_on_close)
        self.max_container_size = max_container_size
        self._writer = self._blf(append=False)

    def _blf(self, *, append: bool) -> can.BLFWriter:
        kwargs = ({} if self.max_container_size is None
                  else {"max_container_size": self.max_container_size})
        return can.BLFWriter(_Segment(self.file), append=append,  # type: ignore[arg-type]
                             **kwargs)

    @property
    def start_timestamp(self) -> float | None:
        """The file's start (s): object times are stored relative to it; None before the
        first frame."""
        return self._writer.start_timestamp

    @staticmethod
    def start_for(t: float) -> float:
        """The file start (s, ms-aligned as BLF stores it) for a first frame at ``t``."""
        if t - BLF_MARGIN >= _BLF_MIN_START:
            return int((t - BLF_MARGIN) * 1000) / 1000
        return _BLF_MIN_START if t >= _BLF_MIN_START else 0.0

    def fits(self, t: float) -> bool:
        """Whether a frame at ``t`` (s) is stored with its own time in this file."""
        start = self.start_timestamp
        if start is None:
            return True
        return start <= t < start + BLF_SPAN

    def on_message_received(self, msg: can.Message) -> None:
        w = self._writer
        if w.start_timestamp is None and math.isfinite(msg.timestamp):
            w.start_timestamp = self.start_for(msg.timestamp)
        w.on_message_received(msg)

    def flush(self) -> None:
        """Commit: the header in place, then the container(s), one write."""
        if self.file.closed:
            return
        if self._writer.start_timestamp is None:  # no frame yet: commit the bare header
            self.file.flush()  # (a writer appending to it would read a start of 0)
            return
        self._writer.stop()  # container + header into the CommitFile, which commits
        self.file.seek(0)  # the appending writer reads the header where it stands
        self._writer = self._blf(append=True)

    def stop(self) -> None:
        """Flush and close the file (fdatasync'ed first with ``sync_on_close``)."""
        if self.file.closed:
            return
        try:
            self._writer.stop()
        finally:
            self.file.close()


class Recorder(can.Listener):
    """A listener that writes every frame to ``path`` (suffix picks the format)."""

    #: at most this many files are started for frames that do not fit the current BLF;
    #: beyond it such frames are written as python-can writes them (counted unfaithful)
    MAX_FILES = 64

    def __init__(self, path: str | Path, flush_interval: float = 1.0, *,
                 durable: bool = False,
                 next_path: Callable[[], Path] | None = None,
                 max_container_size: int | None = None) -> None:
        """``durable``: :meth:`stop` fdatasyncs a BLF before closing it (see :meth:`sync`).
        ``max_container_size``: a BLF's log container size (python-can's option, bytes of
        uncompressed objects; default python-can's).
        ``next_path()``: the file to continue in when a frame's time does not fit the BLF
        (:meth:`FlushingBLFWriter.fits`; default ``<stem>-<n><suffix>`` beside ``path``);
        the files, in order, replay to the frames received (:attr:`files`)."""
        self.path = Path(path)
        self.flush_interval = float(flush_interval)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.durable = durable
        self.next_path = next_path
        self.max_container_size = max_container_size
        self.files = [self.path]
        self.unfaithful = 0
        self._writer = self._open(self.path)
        self._lock = threading.Lock()
        self._last_flush_t = -math.inf
        self.frames = 0
        self.flushes = 0
        self.errors = 0
        self.unrecordable = 0
        self.failed: OutputError | None = None
        self._stopped = False

    def _open(self, path: Path) -> can.Listener:
        try:
            if path.suffix.lower() == ".blf":
                return FlushingBLFWriter(path, sync_on_close=self.durable,
                                         max_container_size=self.max_container_size)
            return can.Logger(path)
        except Exception as exc:
            raise CanEdgeError(f"{path}: cannot open frame log: {exc}") from exc

    def _continue_in_new_file(self, t: float) -> None:
        """Close the current BLF and go on in the next file (a frame at ``t`` does not fit
        it: a clock step back beyond its margin, or a stray timestamp)."""
        old = self._writer
        path = (self.next_path() if self.next_path is not None else
                self.path.with_name(f"{self.path.stem}-{len(self.files) + 1}"
                                    f"{self.path.suffix}"))
        old.stop()  # durable: fdatasync'ed before closing (sync_on_close)
        self._writer = self._open(path)
        self.files.append(path)
        log.warning("frame at t=%.6f does not fit %s (stored to the ns from its start "
                    "%.3f): the raw log continues in %s", t, old.file.name,  # type: ignore[attr-defined]
                    old.start_timestamp, path.name)  # type: ignore[attr-defined]

    def on_message_received(self, msg: can.Message) -> None:
        try:
            with self._lock:
                if self._stopped or self.failed is not None:
                    if self.failed is not None:
                        self.errors += 1
                    return
                if not math.isfinite(msg.timestamp):  # no log format can store it
                    self.unrecordable += 1
                    return
                w = self._writer
                if isinstance(w, FlushingBLFWriter) and not w.fits(msg.timestamp):
                    if len(self.files) < self.MAX_FILES:
                        self._continue_in_new_file(msg.timestamp)
                    else:
                        self.unfaithful += 1
                self._writer.on_message_received(msg)
                self.frames += 1
                t = msg.timestamp
                if self._last_flush_t == -math.inf or t < self._last_flush_t:
                    self._last_flush_t = t  # (also after a clock step back)
                elif t - self._last_flush_t >= self.flush_interval:
                    self._flush_locked()
                    self._last_flush_t = t
        except OSError as exc:  # disk full, size limit, I/O error: recording has stopped
            self._fail(exc)
        except Exception as exc:  # keep the Notifier alive; the count shows the loss
            self.errors += 1
            log.error("recorder failed on a frame: %s", exc)

    def _fail(self, exc: OSError) -> None:
        self.errors += 1
        if self.failed is None:
            self.failed = OutputError(f"{self.path}: cannot write the frame log: "
                                      f"{exc.strerror or exc}")
            self.failed.__cause__ = exc
            log.error("%s; recording stopped", self.failed)

    def on_error(self, exc: Exception) -> None:
        log.debug("recorder saw bus error: %s", exc)

    def _flush_locked(self) -> None:
        flush = getattr(self._writer, "flush", None)
        if flush is not None:
            flush()
        else:  # text writers: flush the file object
            f = getattr(self._writer, "file", None)
            if f is not None:
                f.flush()
        self.flushes += 1

    def flush(self) -> None:
        """Write everything received so far to disk (safe from any thread). A failure is
        kept in :attr:`failed`, not raised."""
        with self._lock:
            if not self._stopped and self.failed is None:
                try:
                    self._flush_locked()
                except OSError as exc:
                    self._fail(exc)

    def sync(self) -> None:
        """:meth:`flush`, then ``fdatasync`` the file: what was received is on the disk
        itself, not only in the OS's cache (survives a power cut). A failure is kept in
        :attr:`failed`, not raised."""
        with self._lock:  # the Notifier's thread takes this lock for every frame
            if self._stopped or self.failed is not None:
                return
            try:
                self._flush_locked()
                f = getattr(self._writer, "file", None)
                fd = os.dup(f.fileno()) if f is not None else None  # open if stop() closes
            except OSError as exc:
                self._fail(exc)
                return
        if fd is None:
            return
        try:  # outside the lock: frames keep being recorded while the disk catches up
            datasync(fd)
        except OSError as exc:
            with self._lock:
                self._fail(exc)
        finally:
            os.close(fd)

    def stop(self) -> None:
        """Flush and close the file; later frames are ignored."""
        with self._lock:
            if self._stopped:
                return
            self._stopped = True
            try:
                self._writer.stop()
            except OSError as exc:
                self._fail(exc)
                f = getattr(self._writer, "file", None)
                try:  # release the descriptor; nothing more can be written
                    if isinstance(f, CommitFile):
                        f._broken = f._broken or exc
                        f.close()
                except OSError:
                    pass
        log.info("recorded %d frames to %s", self.frames, self.path)

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
