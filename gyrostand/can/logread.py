"""Reading recorded logs, in this process or in a reader process beside it.

:func:`read_log` opens anything :class:`can.LogReader` reads (``.blf``, ``.asc``, ``.csv``,
candump ``.log``, ``.trc``, ``.mf4`` when asammdf is installed); ASC is read with absolute
timestamps (note: python-can 4.6's ASC *writer* prints the start time's milliseconds
unpadded, so ASC files it wrote can be off by up to 0.99 s in absolute time; BLF is exact).

:func:`frame_fields` is what the decoding listener looks at in a frame. :class:`ReaderProcess`
runs :func:`read_logs` in a separate OS process and sends the frames back as batches of
those tuples, in file order: parsing the file (python-can's own reader, about half of a
replay's work) then runs on one core while decoding, binning and estimation run on the
other. The consumer gives each batch to
:meth:`~gyrostand.can.decode.DecodingListener.receive_frames`, which runs the very steps
``on_message_received`` runs for a live frame.

This module imports python-can but not cantools (nor numpy), so the reader process starts
quickly.
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
from typing import BinaryIO

import can

from gyrostand.errors import CanEdgeError

__all__ = ["read_log", "read_logs", "frame_fields", "Frame", "ERROR_FRAME", "REMOTE_FRAME",
           "EXTENDED_KEY_BIT", "ReaderProcess"]

log = logging.getLogger("gyrostand.can.logread")  # also when run as __main__

#: bit set in a frame key for an extended (29-bit) id, so standard 0x100 and extended 0x100
#: are different keys of one int-keyed dict (:func:`~gyrostand.can.dbc.frame_key`)
EXTENDED_KEY_BIT = 1 << 29
ERROR_FRAME, REMOTE_FRAME = 1, 2

#: a received frame as the listener uses it: ``(timestamp s, key, flags, payload)``; key
#: the id (| EXTENDED_KEY_BIT for an extended id), flags ERROR_FRAME | REMOTE_FRAME
Frame = tuple[float, int, int, "bytes | bytearray"]


def frame_fields(msg: can.Message) -> Frame:
    """The fields of ``msg`` the decoding listener looks at, as a :data:`Frame`."""
    aid = msg.arbitration_id
    return (msg.timestamp, aid | EXTENDED_KEY_BIT if msg.is_extended_id else aid,
            (ERROR_FRAME if msg.is_error_frame else 0)
            | (REMOTE_FRAME if msg.is_remote_frame else 0), msg.data)


def read_log(path: str | Path) -> Iterator[can.Message]:
    """Frames of a log file, in file order. Raises :class:`CanEdgeError` naming the file.

    A BLF whose last object is torn (the recording process was killed while appending, or
    the disk filled up) is read up to the tear, with a warning: python-can's reader
    raises there, after the last complete frame. Damage anywhere else is an error.
    """
    path = Path(path)
    if not path.is_file():
        raise CanEdgeError(f"{path}: log file not found")
    kwargs = {"relative_timestamp": False} if path.suffix.lower() == ".asc" else {}
    try:
        reader = can.LogReader(path, **kwargs)
    except Exception as exc:
        raise CanEdgeError(f"{path}: cannot read CAN log: {exc}") from exc
    try:
        yield from reader
    except Exception as exc:
        f = getattr(reader, "file", None)
        try:
            at_end = f is not None and not f.closed and f.tell() >= path.stat().st_size
        except (OSError, ValueError):
            at_end = False
        if not (at_end and path.suffix.lower() == ".blf"):
            raise CanEdgeError(f"{path}: corrupt CAN log: {exc}") from exc
        log.warning("%s: torn last object ignored (the recording stopped while writing "
                    "it): %s", path, exc or type(exc).__name__)
    finally:
        reader.stop()


def read_logs(paths: Iterable[str | Path]) -> Iterator[can.Message]:
    """The frames of several logs (e.g. a resumed run's segments), one after the other."""
    for p in paths:
        yield from read_log(p)


# -- the reader process -------------------------------------------------------------------
# ``python -m gyrostand.can.logread [--batch N] LOG...`` writes messages to its standard
# output, each an 8-byte little-endian length and a pickle: ("frames", [Frame, ...]) |
# ("log", level, logger, text) | ("error", text) | ("end", frame count). A separate
# interpreter started this way imports python-can and this module only (~0.1 s), where a
# multiprocessing "spawn" child would import the parent's main module and all it imports.

_HEADER = struct.Struct("<Q")


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


def _reader_main(paths: Sequence[str], out: BinaryIO, batch: int) -> None:
    """Body of the reader process: read ``paths`` in order, send frame batches, then end.
    An error is sent after every frame read before it, as the in-process reader would
    have delivered them."""
    root = logging.getLogger("gyrostand")
    root.addHandler(_PipeHandler(out))
    root.setLevel(logging.INFO)
    n = 0
    buf: list[Frame] = []
    append = buf.append
    try:
        for msg in read_logs(paths):
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
        _send(out, ("error", error))
        return
    if buf:
        _send(out, ("frames", buf))
        n += len(buf)
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
    ``batch`` :data:`Frame` tuples (the last one shorter), in file order.

    Errors the reader meets are raised here as :class:`CanEdgeError` naming the file,
    after the batches read before them; its log records are logged here. Leaving the
    iteration early (or an error) stops the process. Memory stays bounded: the reader
    blocks while the pipe is full.
    """

    def __init__(self, paths: Sequence[str | Path], batch: int = 1024) -> None:
        if batch < 1:
            raise ValueError(f"batch must be >= 1, got {batch!r}")
        self.paths = [str(p) for p in paths]
        self.batch = int(batch)
        self.frames = 0  # frames delivered so far
        self.returncode: int | None = None  # the process's exit code, once it has ended

    def __iter__(self) -> Iterator[list[Frame]]:
        what = " + ".join(self.paths)
        # the child imports this very gyrostand, installed or not (a source checkout)
        env = dict(os.environ)
        here = str(Path(__file__).resolve().parents[2])
        env["PYTHONPATH"] = os.pathsep.join([here] + ([env["PYTHONPATH"]]
                                                      if env.get("PYTHONPATH") else []))
        proc = subprocess.Popen(
            [sys.executable, "-m", "gyrostand.can.logread", "--batch", str(self.batch),
             "--", *self.paths],
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
                    raise CanEdgeError(f"{what}: the log reader process ended without "
                                       f"finishing (exit code {code})")
                msg = pickle.loads(body)
                kind = msg[0]
                if kind == "frames":
                    self.frames += len(msg[1])
                    yield msg[1]
                elif kind == "log":
                    logging.getLogger(msg[2]).log(msg[1], "%s", msg[3])
                elif kind == "error":
                    raise CanEdgeError(msg[1])
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

    ap = argparse.ArgumentParser(prog="python -m gyrostand.can.logread",
                                 description="Send the frames of CAN logs to standard "
                                             "output (gyrostand's replay reader process).")
    ap.add_argument("--batch", type=int, default=1024)
    ap.add_argument("logs", nargs="+")
    args = ap.parse_args(argv)
    out = sys.stdout.buffer
    # Ctrl-C reaches the whole process group: the parent handles it and closes the pipe,
    # which ends this process (no second traceback from here)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if out.isatty():
        ap.error("standard output is a terminal; this is gyrostand's replay reader")
    try:
        _reader_main(args.logs, out, max(1, args.batch))
    except (BrokenPipeError, ConnectionResetError):
        os._exit(0)  # the consumer stopped reading: nothing more to say, nor to flush
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
