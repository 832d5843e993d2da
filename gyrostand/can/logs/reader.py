"""The reader process: :func:`~gyrostand.can.logs.read.read_logs` run in a separate OS
process that sends the frames back in batches, in file order.

:class:`ReaderProcess` starts ``python -m gyrostand.can.logs.reader`` and iterates over
the batches it sends: lists of :data:`~gyrostand.can.logs.frames.Frame` tuples, or with
``arrays`` :class:`~gyrostand.can.logs.blfarray.FrameArrays`. Parsing the file
(python-can's own reader, about half of a replay's work) then runs on one core while
decoding, binning and estimation run on the other. The consumer gives each batch to
:meth:`~gyrostand.can.receive.listener.DecodingListener.receive_frames` (or
``receive_arrays``), which runs the very steps ``on_message_received`` runs for a live
frame.
"""

from __future__ import annotations

import logging
import os
import pickle
import signal
import struct
import subprocess
import sys
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any, BinaryIO

from gyrostand.can.logs.frames import ERROR_FRAME, EXTENDED_KEY_BIT, REMOTE_FRAME, Frame
from gyrostand.can.logs.read import LogDamage, read_logs, read_logs_arrays
from gyrostand.errors import CanEdgeError, LogError, LogNotFoundError

__all__ = ["ReaderProcess", "array_batches"]


# -- the reader process -------------------------------------------------------------------
# ``python -m gyrostand.can.logs.reader [--batch N] LOG...`` writes messages to its standard
# output, each an 8-byte little-endian length and a pickle: ("frames", [Frame, ...]) |
# ("arrays", FrameArrays) (with --arrays) |
# ("log", level, logger, text) | ("damage", LogDamage.as_dict()) |
# ("error", text, "missing" | "log") (a log not found, or one that cannot be read) |
# ("end", frame count). A separate
# interpreter started this way imports python-can and this module only (~0.1 s), where a
# multiprocessing "spawn" child would import the parent's main module and all it imports.

_HEADER = struct.Struct("<Q")


def _error_kind(exc: Exception) -> str:
    """What the parent raises for an error of the reader: "missing" (a log not found,
    :class:`LogNotFoundError`) or "log" (:class:`LogError`)."""
    return "missing" if isinstance(exc, LogNotFoundError) else "log"


def _send(out: BinaryIO, obj: object) -> None:
    data = pickle.dumps(obj, pickle.HIGHEST_PROTOCOL)
    out.write(_HEADER.pack(len(data)))
    out.write(data)
    out.flush()


class _PipeHandler(logging.Handler):
    """Forwards the reader process's log records (e.g. a torn BLF's warning) to the parent."""

    def __init__(self, out: BinaryIO) -> None:
        super().__init__(logging.INFO)
        self.out = out

    def emit(self, record: logging.LogRecord) -> None:
        try:
            _send(self.out, ("log", record.levelno, record.name, record.getMessage()))
        except Exception:  # the parent is gone: nothing to tell
            pass


def array_batches(parts: Iterable[Any], batch: int) -> Iterator[Any]:
    """FrameArrays ``parts`` regrouped into batches of exactly ``batch`` frames (the last
    one shorter); an error raised by ``parts`` comes after the frames read before it."""
    from gyrostand.can.logs.blfarray import FrameArrays

    pending: list[Any] = []
    have = 0
    try:
        for part in parts:
            pending.append(part)
            have += len(part)
            while have >= batch:
                whole = FrameArrays.concat(pending)
                yield whole[:batch]
                rest = whole[batch:]
                pending, have = ([rest] if len(rest) else []), len(rest)
    except Exception:
        if have:
            yield FrameArrays.concat(pending)
        raise
    if have:
        yield FrameArrays.concat(pending)


def _reader_main(paths: Sequence[str], out: BinaryIO, batch: int, arrays: bool = False
                 ) -> None:
    """Body of the reader process: read ``paths`` in order, send frame batches (lists of
    :data:`Frame` tuples, or with ``arrays`` FrameArrays), then end. An error is sent
    after every frame read before it, as the in-process reader would have delivered
    them."""
    root = logging.getLogger("gyrostand")
    root.addHandler(_PipeHandler(out))
    root.setLevel(logging.INFO)
    if arrays:
        _reader_arrays(paths, out, batch)
        return
    n = 0
    buf: list[Frame] = []
    append = buf.append
    damage = LogDamage()
    try:
        for msg in read_logs(paths, damage):
            # frame_fields(msg), inlined: this loop is the reader's whole cost
            aid = msg.arbitration_id
            append((msg.timestamp, aid | EXTENDED_KEY_BIT if msg.is_extended_id else aid,
                    (ERROR_FRAME if msg.is_error_frame else 0)
                    | (REMOTE_FRAME if msg.is_remote_frame else 0), msg.data))
            if len(buf) >= batch:
                _send(out, ("frames", buf))
                n += len(buf)
                buf = []
                append = buf.append
    except (BrokenPipeError, ConnectionResetError):
        raise
    except Exception as exc:
        error = str(exc) if isinstance(exc, CanEdgeError) else (
            f"{' + '.join(paths)}: cannot read CAN log: {type(exc).__name__}: {exc}")
        if buf:
            _send(out, ("frames", buf))
        _send(out, ("damage", damage.as_dict()))
        _send(out, ("error", error, _error_kind(exc)))
        return
    if buf:
        _send(out, ("frames", buf))
        n += len(buf)
    _send(out, ("damage", damage.as_dict()))
    _send(out, ("end", n))


def _reader_arrays(paths: Sequence[str], out: BinaryIO, batch: int) -> None:
    """:func:`_reader_main` sending FrameArrays batches (:func:`array_batches`)."""
    n = 0
    damage = LogDamage()
    try:
        for frames in array_batches(read_logs_arrays(paths, damage), batch):
            _send(out, ("arrays", frames))
            n += len(frames)
    except (BrokenPipeError, ConnectionResetError):
        raise
    except Exception as exc:
        error = str(exc) if isinstance(exc, CanEdgeError) else (
            f"{' + '.join(paths)}: cannot read CAN log: {type(exc).__name__}: {exc}")
        _send(out, ("damage", damage.as_dict()))
        _send(out, ("error", error, _error_kind(exc)))
        return
    _send(out, ("damage", damage.as_dict()))
    _send(out, ("end", n))


def _deepen(fd: int, size: int = 1 << 20) -> None:
    """Let the pipe hold many batches (Linux: F_SETPIPE_SZ, up to pipe-max-size): with the
    default 64 KiB about one batch fits, and reader and consumer wait on each other."""
    try:
        import fcntl

        fcntl.fcntl(fd, getattr(fcntl, "F_SETPIPE_SZ", 1031), size)
    except (ImportError, OSError):
        pass  # another OS, or a lower limit: the default depth works, only slower


class ReaderProcess:
    """Read logs in a separate process; iterate to get their frames in batches of
    ``batch`` :data:`Frame` tuples (the last one shorter), in file order; with ``arrays``
    each batch is a :class:`~gyrostand.can.logs.blfarray.FrameArrays` (BLF containers parsed
    as arrays in the reader: :func:`read_log_arrays`).

    Errors the reader meets are raised here as :class:`LogError` (a log not found:
    :class:`LogNotFoundError`) naming the file, after the batches read before them; its log records are logged here. Leaving the
    iteration early (or an error) stops the process. Memory stays bounded: the reader
    blocks while the pipe is full.
    """

    def __init__(self, paths: Sequence[str | Path], batch: int = 1024,
                 arrays: bool = False) -> None:
        if batch < 1:
            raise ValueError(f"batch must be >= 1, got {batch!r}")
        self.paths = [str(p) for p in paths]
        self.batch = int(batch)
        self.arrays = bool(arrays)
        self.frames = 0  # frames delivered so far
        self.damage = LogDamage()  # what the reader skipped (complete once iterated)
        self.returncode: int | None = None  # the process's exit code, once it has ended

    def __iter__(self) -> Iterator[Any]:
        what = " + ".join(self.paths)
        # the child imports this very gyrostand, installed or not (a source checkout)
        env = dict(os.environ)
        here = str(Path(__file__).resolve().parents[3])
        env["PYTHONPATH"] = os.pathsep.join([here] + ([env["PYTHONPATH"]]
                                                      if env.get("PYTHONPATH") else []))
        proc = subprocess.Popen(
            [sys.executable, "-m", "gyrostand.can.logs.reader", "--batch", str(self.batch),
             *(["--arrays"] if self.arrays else []), "--", *self.paths],
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, env=env)
        assert proc.stdout is not None
        _deepen(proc.stdout.fileno())
        read = proc.stdout.read
        try:
            while True:
                head = read(_HEADER.size)
                size = _HEADER.unpack(head)[0] if len(head) == _HEADER.size else -1
                body = read(size) if size >= 0 else b""
                if size < 0 or len(body) != size:
                    code = proc.wait(10.0)
                    raise LogError(f"{what}: the log reader process ended without "
                                   f"finishing (exit code {code})")
                msg = pickle.loads(body)
                kind = msg[0]
                if kind in ("frames", "arrays"):
                    self.frames += len(msg[1])
                    yield msg[1]
                elif kind == "damage":
                    self.damage.add(msg[1])
                elif kind == "log":
                    logging.getLogger(msg[2]).log(msg[1], "%s", msg[3])
                elif kind == "error":
                    raise (LogNotFoundError if msg[2:3] == ("missing",) else LogError)(msg[1])
                else:  # "end"
                    return
        finally:
            proc.stdout.close()
            try:
                self.returncode = proc.wait(5.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                self.returncode = proc.wait()


def _main(argv: Sequence[str]) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python -m gyrostand.can.logs.reader",
                                 description="Send the frames of CAN logs to standard "
                                             "output (gyrostand's replay reader process).")
    ap.add_argument("--batch", type=int, default=1024)
    ap.add_argument("--arrays", action="store_true",
                    help="send FrameArrays batches (BLF containers parsed as arrays)")
    ap.add_argument("logs", nargs="+")
    args = ap.parse_args(argv)
    out = sys.stdout.buffer
    # Ctrl-C reaches the whole process group: the parent handles it and closes the pipe,
    # which ends this process (no second traceback from here)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if out.isatty():
        ap.error("standard output is a terminal; this is gyrostand's replay reader")
    try:
        _reader_main(args.logs, out, max(1, args.batch), args.arrays)
    except (BrokenPipeError, ConnectionResetError):
        os._exit(0)  # the consumer stopped reading: nothing more to say, nor to flush
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
