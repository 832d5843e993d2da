"""Raw frame recorder: every frame as received, lossless and replayable.

BLF (recommended: compact, fast, keeps CAN FD flags and timestamps) is written by a
:class:`can.BLFWriter` that is also flushed on demand: the pending log container is
compressed and written and the file header rewritten, so the file on disk is a complete,
readable BLF up to the last flush. Other suffixes go to :class:`can.Logger` (``.asc``,
``.log``, ``.csv``, ...), flushed at the file level.

The recorder flushes itself whenever frame time has advanced ``flush_interval`` seconds
(1 s by default) since the last flush; call :meth:`Recorder.flush` from the daemon's 1-Hz
tick as well, so a silent bus still gets its tail written.

A frame whose timestamp is not finite cannot be stored by any log format (BLF's writer
fails on it and would lose the file header): it is counted in ``unrecordable`` and skipped;
the decoder rejects such frames anyway (``bad_timestamp``).
"""

from __future__ import annotations

import logging
import math
import threading
from pathlib import Path

import can

from gyrostand.errors import CanEdgeError

__all__ = ["Recorder", "FlushingBLFWriter"]

log = logging.getLogger(__name__)


class FlushingBLFWriter(can.BLFWriter):
    """:class:`can.BLFWriter` with a :meth:`flush` that leaves a complete file on disk.

    Uses ``BLFWriter._flush`` and ``_write_header`` (python-can 4.x), exactly what
    ``BLFWriter.stop`` does, without closing; ``tests/can`` checks the result is readable.
    """

    def flush(self) -> None:
        if self.file.closed:
            return
        self._flush()  # compress + write the pending container
        if self.file.seekable():
            end = self.file.tell()
            self.file.seek(0)
            self._write_header(end)
            self.file.seek(end)
        self.file.flush()


class Recorder(can.Listener):
    """A listener that writes every frame to ``path`` (suffix picks the format)."""

    def __init__(self, path: str | Path, flush_interval: float = 1.0) -> None:
        self.path = Path(path)
        self.flush_interval = float(flush_interval)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            if self.path.suffix.lower() == ".blf":
                self._writer: can.Listener = FlushingBLFWriter(self.path)
            else:
                self._writer = can.Logger(self.path)
        except Exception as exc:
            raise CanEdgeError(f"{self.path}: cannot open frame log: {exc}") from exc
        self._lock = threading.Lock()
        self._last_flush_t = -math.inf
        self.frames = 0
        self.flushes = 0
        self.errors = 0
        self.unrecordable = 0
        self._stopped = False

    def on_message_received(self, msg: can.Message) -> None:
        try:
            with self._lock:
                if self._stopped:
                    return
                if not math.isfinite(msg.timestamp):  # no log format can store it
                    self.unrecordable += 1
                    return
                self._writer.on_message_received(msg)
                self.frames += 1
                t = msg.timestamp
                if self._last_flush_t == -math.inf:
                    self._last_flush_t = t
                elif t - self._last_flush_t >= self.flush_interval:
                    self._flush_locked()
                    self._last_flush_t = t
        except Exception as exc:  # keep the Notifier alive; the count shows the loss
            self.errors += 1
            log.error("recorder failed on a frame: %s", exc)

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
        """Write everything received so far to disk (safe from any thread)."""
        with self._lock:
            if not self._stopped:
                self._flush_locked()

    def stop(self) -> None:
        """Flush and close the file; later frames are ignored."""
        with self._lock:
            if self._stopped:
                return
            self._stopped = True
            self._writer.stop()
        log.info("recorded %d frames to %s", self.frames, self.path)

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
