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

:func:`read_log_arrays` gives the same frames as
:class:`~gyrostand.can.blfarray.FrameArrays` chunks (a BLF's containers parsed whole as
arrays, with the same damage handling); the reader process sends such batches with
``--arrays``.

This module imports python-can but not cantools (numpy only for the arrays, when used),
so the reader process starts quickly.
"""

from __future__ import annotations

import logging
import os
import pickle
import signal
import struct
import subprocess
import sys
import zlib
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import can

from gyrostand.errors import CanEdgeError

__all__ = ["read_log", "read_logs", "read_log_arrays", "read_logs_arrays", "LogDamage", "frame_fields", "Frame", "ERROR_FRAME",
           "REMOTE_FRAME", "EXTENDED_KEY_BIT", "ReaderProcess"]

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


@dataclass
class LogDamage:
    """What reading a log skipped (:func:`read_log`): BLF objects (containers) that were
    damaged and skipped, ``truncated`` files (a last object cut short: read up to the cut),
    text lines that could not be parsed, other top-level BLF objects (not frames), and the
    first few warnings as text (``notes``)."""

    containers: int = 0
    truncated: int = 0
    lines: int = 0
    other_objects: int = 0
    notes: list[str] = field(default_factory=list)

    @property
    def total(self) -> int:
        return self.containers + self.truncated + self.lines

    def warn(self, text: str) -> None:
        if len(self.notes) < 20:
            self.notes.append(text)
        if len(self.notes) < 20 or self.total % 1000 == 0:
            log.warning("%s", text)

    def as_dict(self) -> dict[str, object]:
        return {"containers_skipped": self.containers, "truncated": self.truncated,
                "lines_skipped": self.lines, "other_objects": self.other_objects,
                "notes": list(self.notes)}

    def add(self, other: dict[str, object]) -> None:
        """Add counts sent by a reader process (:meth:`as_dict`)."""
        self.containers += int(other["containers_skipped"])  # type: ignore[call-overload]
        self.truncated += int(other["truncated"])  # type: ignore[call-overload]
        self.lines += int(other["lines_skipped"])  # type: ignore[call-overload]
        self.other_objects += int(other["other_objects"])  # type: ignore[call-overload]
        self.notes += [str(n) for n in other["notes"]][:max(0, 20 - len(self.notes))]  # type: ignore[attr-defined]


def read_log(path: str | Path, damage: LogDamage | None = None) -> Iterator[can.Message]:
    """Frames of a log file, in file order. Raises :class:`CanEdgeError` naming the file
    when it cannot be opened at all (missing, not a log, a damaged BLF file header).

    Damage inside the file is skipped, counted in ``damage`` and logged with the file and
    the place: a BLF object (container) that cannot be decompressed or parsed is skipped
    (the next object is found by its signature); a BLF cut short inside its last object
    (a kill while appending, a full disk, a truncated copy) is read up to the cut; an ASC
    or candump line that cannot be parsed is skipped (file and line number named).
    """
    path = Path(path)
    damage = damage if damage is not None else LogDamage()
    if not path.is_file():
        raise CanEdgeError(f"{path}: log file not found")
    suffix = path.suffix.lower()
    if suffix == ".blf":
        yield from _read_blf(path, damage)
        return
    if suffix in (".asc", ".log"):
        yield from _read_text(path, damage)
        return
    try:
        reader = can.LogReader(path)
    except Exception as exc:
        raise CanEdgeError(f"{path}: cannot read CAN log: {exc}") from exc
    try:
        yield from reader
    except Exception as exc:
        raise CanEdgeError(f"{path}: corrupt CAN log: {exc}") from exc
    finally:
        reader.stop()


def _read_blf(path: Path, damage: LogDamage, arrays: bool = False) -> Iterator[Any]:
    """python-can's BLF reader, driven one top-level object at a time: its header and
    container parsing, with damage skipped instead of ending the file. With ``arrays``,
    each container's frames come as one :class:`~gyrostand.can.blfarray.FrameArrays`
    (parsed by :func:`~gyrostand.can.blfarray.parse_container`, or by python-can's own
    parser when that declines), else as :class:`can.Message` objects."""
    from can.io import blf

    try:
        reader = blf.BLFReader(path)
    except Exception as exc:
        raise CanEdgeError(f"{path}: cannot read CAN log: {exc}") from exc
    f = reader.file
    size = path.stat().st_size
    head_s, cont_s = blf.OBJ_HEADER_BASE_STRUCT, blf.LOG_CONTAINER_STRUCT
    try:
        while True:
            start = f.tell()
            head = f.read(head_s.size)
            if not head:
                if reader.file_size > size:  # the header knows how long the file was
                    damage.truncated += 1
                    damage.warn(f"{path}: cut short: {size} of the {reader.file_size} "
                                f"bytes its header states")
                return
            if len(head) < head_s.size:
                damage.truncated += 1
                damage.warn(f"{path}: cut short inside the object at byte {start} (the last "
                            f"{len(head)} bytes ignored)")
                return
            sig, _, _, obj_size, obj_type = head_s.unpack(head)
            if sig != b"LOBJ" or obj_size < head_s.size + (
                    cont_s.size if obj_type == blf.LOG_CONTAINER else 0):
                nxt = _next_object(f, start + 1)
                damage.containers += 1
                damage.warn(f"{path}: damaged object at byte {start} skipped "
                            f"({(nxt if nxt is not None else size) - start} bytes)")
                reader._tail = b""
                if nxt is None:
                    return
                f.seek(nxt)
                continue
            want = obj_size - head_s.size
            body = f.read(want)
            f.read(obj_size % 4)
            cut = len(body) < want
            if obj_type != blf.LOG_CONTAINER:
                damage.other_objects += 1
                if cut:
                    damage.truncated += 1
                    damage.warn(f"{path}: cut short inside the object at byte {start}")
                    return
                continue
            method = cont_s.unpack_from(body)[0] if len(body) >= cont_s.size else -1
            packed = body[cont_s.size:]
            zobj = None
            try:
                if method == blf.NO_COMPRESSION:
                    data = packed
                elif method == blf.ZLIB_DEFLATE:
                    zobj = zlib.decompressobj()
                    data = zobj.decompress(packed)
                    if not (zobj.eof or cut):  # the stream never ends: not verified
                        raise ValueError("the compressed data does not end")
                else:
                    raise ValueError(f"unknown compression method {method}")
            except (zlib.error, ValueError) as exc:
                if cut:  # a torn tail that does not even decompress: nothing to read
                    damage.truncated += 1
                    damage.warn(f"{path}: cut short inside the container at byte {start} "
                                f"({len(body)} of {want} bytes; nothing readable in it)")
                    return
                damage.containers += 1
                damage.warn(f"{path}: damaged container at byte {start} skipped ({exc})")
                reader._tail = b""
                continue
            try:
                if arrays:
                    yield from _container_arrays(reader, data)
                else:
                    yield from reader._parse_container(data)
            except Exception as exc:  # a parse error inside the container's objects
                damage.containers += 1
                damage.warn(f"{path}: damaged frames in the container at byte {start}: "
                            f"the rest of it skipped ({type(exc).__name__}: {exc})")
                reader._tail = b""
            if cut and not (zobj is not None and zobj.unused_data):
                damage.truncated += 1
                damage.warn(f"{path}: cut short inside the container at byte {start} "
                            f"({len(body)} of {want} bytes): read up to the cut")
                return
            if zobj is not None and zobj.unused_data:
                # the container ended before its stated size: its size field is damaged
                end = start + head_s.size + cont_s.size + len(packed) - len(zobj.unused_data)
                nxt = _next_object(f, end)
                damage.containers += 1
                damage.warn(f"{path}: container at byte {start} states a wrong size; "
                            f"reading on at the next object")
                if nxt is None:
                    return
                f.seek(nxt)
    finally:
        reader.stop()


def _container_arrays(reader: Any, data: bytes) -> Iterator[Any]:
    """The frames of one decompressed container as one FrameArrays: parsed as arrays, or,
    when :func:`~gyrostand.can.blfarray.parse_container` declines, by python-can's own
    ``_parse_container`` (the frames it gave before an error are delivered, then the
    error is raised, as the per-object path delivers them)."""
    from gyrostand.can.blfarray import parse_container

    tail = reader._tail
    got = parse_container(tail + data if tail else data, reader.start_timestamp)
    if got is not None:
        frames, reader._tail = got
        if len(frames):
            yield frames
        return
    yield from _as_arrays((frame_fields(m) for m in reader._parse_container(data)), None)


def read_log_arrays(path: str | Path, damage: LogDamage | None = None,
                    chunk: int = 4096) -> Iterator[Any]:
    """:func:`read_log` as :class:`~gyrostand.can.blfarray.FrameArrays` chunks (a BLF
    container each, or ``chunk`` frames of another format): the same frames, the same
    damage handling and messages."""
    path = Path(path)
    if path.suffix.lower() == ".blf" and path.is_file():
        yield from _read_blf(path, damage if damage is not None else LogDamage(), True)
        return
    yield from _as_arrays((frame_fields(m) for m in read_log(path, damage)), chunk)


def _as_arrays(frames: Iterable[Frame], chunk: int | None) -> Iterator[Any]:
    """``frames`` as FrameArrays of ``chunk`` frames (None: one for all); an error raised
    by ``frames`` comes after the frames read before it."""
    from gyrostand.can.blfarray import FrameArrays

    buf: list[Frame] = []
    try:
        for f in frames:
            buf.append(f)
            if chunk is not None and len(buf) >= chunk:
                yield FrameArrays.from_frames(buf)
                buf = []
    except Exception:
        if buf:
            yield FrameArrays.from_frames(buf)
        raise
    if buf:
        yield FrameArrays.from_frames(buf)


def read_logs_arrays(paths: Iterable[str | Path], damage: LogDamage | None = None
                     ) -> Iterator[Any]:
    """:func:`read_logs` as FrameArrays chunks (:func:`read_log_arrays`)."""
    for p in paths:
        yield from read_log_arrays(p, damage)


def _next_object(f: BinaryIO, start: int, chunk: int = 1 << 16) -> int | None:
    """Offset of the next ``LOBJ`` signature at or after ``start``, or None."""
    pos = start
    while True:
        f.seek(pos)
        buf = f.read(chunk + 3)
        if len(buf) < 4:
            return None
        i = buf.find(b"LOBJ")
        if i >= 0:
            return pos + i
        pos += chunk


class _Lines:
    """A text file that counts the lines read from it (for the line number of a bad one)."""

    def __init__(self, path: Path) -> None:
        self.f = path.open("r", encoding="utf-8", errors="replace", newline=None)
        self.n = 0
        self.closed = False

    def __iter__(self) -> _Lines:
        return self

    def __next__(self) -> str:
        line = next(self.f)
        self.n += 1
        return line

    def close(self) -> None:
        self.closed = True
        self.f.close()


def _read_text(path: Path, damage: LogDamage) -> Iterator[can.Message]:
    """ASC (absolute timestamps) or candump ``.log`` through python-can's reader; a line it
    cannot parse is skipped and counted, and reading goes on with the next line (the
    reader's state, e.g. ASC's start time and number base, carried over)."""
    import copy

    lines = _Lines(path)
    try:
        if path.suffix.lower() == ".asc":
            reader: Any = can.ASCReader(lines, relative_timestamp=False)  # type: ignore[arg-type]
        else:
            reader = can.CanutilsLogReader(lines)  # type: ignore[arg-type]
    except Exception as exc:
        lines.close()
        raise CanEdgeError(f"{path}: cannot read CAN log: {exc}") from exc
    try:
        at = -1
        while True:
            try:
                yield from reader
                return
            except Exception as exc:
                if lines.n == at:  # nothing more was read: not a line's fault
                    raise CanEdgeError(f"{path}: corrupt CAN log after line {at}: "
                                       f"{type(exc).__name__}: {exc}") from exc
                at = lines.n
                damage.lines += 1
                damage.warn(f"{path}: line {lines.n}: cannot parse, skipped "
                            f"({type(exc).__name__}: {exc})")
                nxt = copy.copy(reader)  # same file (at the next line), same state
                nxt._extract_header = lambda: None
                reader = nxt
    finally:
        lines.close()


def read_logs(paths: Iterable[str | Path], damage: LogDamage | None = None
              ) -> Iterator[can.Message]:
    """The frames of several logs (e.g. a resumed run's segments), one after the other."""
    for p in paths:
        yield from read_log(p, damage)


# -- the reader process -------------------------------------------------------------------
# ``python -m gyrostand.can.logread [--batch N] LOG...`` writes messages to its standard
# output, each an 8-byte little-endian length and a pickle: ("frames", [Frame, ...]) |
# ("arrays", FrameArrays) (with --arrays) |
# ("log", level, logger, text) | ("damage", LogDamage.as_dict()) | ("error", text) |
# ("end", frame count). A separate
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


def array_batches(parts: Iterable[Any], batch: int) -> Iterator[Any]:
    """FrameArrays ``parts`` regrouped into batches of exactly ``batch`` frames (the last
    one shorter); an error raised by ``parts`` comes after the frames read before it."""
    from gyrostand.can.blfarray import FrameArrays

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
        _send(out, ("error", error))
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
        _send(out, ("error", error))
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
    each batch is a :class:`~gyrostand.can.blfarray.FrameArrays` (BLF containers parsed
    as arrays in the reader: :func:`read_log_arrays`).

    Errors the reader meets are raised here as :class:`CanEdgeError` naming the file,
    after the batches read before them; its log records are logged here. Leaving the
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
        here = str(Path(__file__).resolve().parents[2])
        env["PYTHONPATH"] = os.pathsep.join([here] + ([env["PYTHONPATH"]]
                                                      if env.get("PYTHONPATH") else []))
        proc = subprocess.Popen(
            [sys.executable, "-m", "gyrostand.can.logread", "--batch", str(self.batch),
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
                    raise CanEdgeError(f"{what}: the log reader process ended without "
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
