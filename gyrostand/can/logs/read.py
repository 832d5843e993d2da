"""Reading recorded logs in this process, damage skipped and counted.

:func:`read_log` opens anything :class:`can.LogReader` reads (``.blf``, ``.asc``, ``.csv``,
candump ``.log``, ``.trc``, ``.mf4`` when asammdf is installed); ASC is read with absolute
timestamps (note: python-can 4.6's ASC *writer* prints the start time's milliseconds
unpadded, so ASC files it wrote can be off by up to 0.99 s in absolute time; BLF is exact).

:func:`read_log_arrays` gives the same frames as
:class:`~gyrostand.can.logs.blfarray.FrameArrays` chunks (a BLF's containers parsed whole
as arrays, with the same damage handling). The reader process
(:mod:`~gyrostand.can.logs.reader`) runs these readers beside the decoding.

This module imports python-can but not cantools (numpy only for the arrays, when used),
so the reader process starts quickly.
"""

from __future__ import annotations

import contextlib
import gc
import io
import logging
import sys
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import can

from gyrostand.can.logs.frames import Frame, frame_fields
from gyrostand.can.logs.textlog import TEXT_SUFFIXES, read_text_log
from gyrostand.errors import LogError, LogNotFoundError

__all__ = ["read_log", "read_logs", "read_log_arrays", "read_logs_arrays", "LogDamage"]

log = logging.getLogger(__name__)


@dataclass
class LogDamage:
    """What reading a log skipped (:func:`read_log`): BLF objects (containers) that were
    damaged and skipped, ``truncated`` files (a last object cut short: read up to the cut),
    text lines that could not be parsed, other top-level BLF objects (not frames), the
    ``bytes`` of decompressed BLF data skipped to find the next intact object after damage
    (the rest of an object spanning into the next container), and the first few warnings
    as text (``notes``)."""

    containers: int = 0
    truncated: int = 0
    lines: int = 0
    other_objects: int = 0
    bytes: int = 0
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
                "bytes_skipped": self.bytes, "notes": list(self.notes)}

    def add(self, other: dict[str, object]) -> None:
        """Add counts sent by a reader process (:meth:`as_dict`)."""
        self.containers += int(other["containers_skipped"])  # type: ignore[call-overload]
        self.truncated += int(other["truncated"])  # type: ignore[call-overload]
        self.lines += int(other["lines_skipped"])  # type: ignore[call-overload]
        self.other_objects += int(other["other_objects"])  # type: ignore[call-overload]
        self.bytes += int(other["bytes_skipped"])  # type: ignore[call-overload]
        self.notes += [str(n) for n in other["notes"]][:max(0, 20 - len(self.notes))]  # type: ignore[attr-defined]


@contextlib.contextmanager
def _quiet_unraisable(path: Path) -> Iterator[None]:
    """``sys.unraisablehook`` logging at debug level, instead of printing "Exception
    ignored in: ... __del__" tracebacks (a reader half-built from a truncated file)."""
    old = sys.unraisablehook

    def hook(u: Any) -> None:
        log.debug("%s: %s in %r while closing a reader", path, u.exc_value, u.object)

    sys.unraisablehook = hook
    try:
        yield
    finally:
        sys.unraisablehook = old


def read_log(path: str | Path, damage: LogDamage | None = None) -> Iterator[can.Message]:
    """Frames of a log file, in file order. Raises :class:`CanEdgeError` naming the file
    when it cannot be opened at all (missing, not a log, a damaged BLF file header).

    Damage inside the file is skipped, counted in ``damage`` and logged with the file and
    the place: a BLF object (container) that cannot be decompressed or parsed is skipped
    (the next object is found by its signature); a BLF cut short inside its last object
    (a kill while appending, a full disk, a truncated copy) is read up to the cut; an ASC,
    candump or CSV line that cannot be parsed or was cut short is skipped (file and line
    number named, :mod:`~gyrostand.can.logs.textlog`).
    """
    path = Path(path)
    damage = damage if damage is not None else LogDamage()
    if not path.is_file():
        raise LogNotFoundError(f"{path}: log file not found")
    suffix = path.suffix.lower()
    if suffix == ".blf":
        yield from _read_blf(path, damage)
        return
    if suffix in TEXT_SUFFIXES:
        yield from read_text_log(path, damage)
        return
    failed = None
    with _quiet_unraisable(path):  # asammdf's MDF4.__del__ fails on a half-opened file
        try:
            reader = can.LogReader(path)
        except Exception as exc:
            failed = f"{path}: cannot read CAN log: {exc}"
        gc.collect()  # the half-built reader goes here, under the quiet hook
    if failed is not None:
        raise LogError(failed)
    try:
        yield from reader
    except Exception as exc:
        raise LogError(f"{path}: corrupt CAN log: {exc}") from exc
    finally:
        reader.stop()


def _read_blf(path: Path, damage: LogDamage, arrays: bool = False) -> Iterator[Any]:
    """python-can's BLF reader, driven one top-level object at a time: its header and
    container parsing, with damage skipped instead of ending the file. With ``arrays``,
    each container's frames come as one :class:`~gyrostand.can.logs.blfarray.FrameArrays`
    (parsed by :func:`~gyrostand.can.logs.blfarray.parse_container`, or by python-can's own
    parser when that declines), else as :class:`can.Message` objects."""
    from can.io import blf

    size = path.stat().st_size
    if size < blf.FILE_HEADER_STRUCT.size:  # python-can: "unpack requires a buffer ..."
        raise LogError(f"{path}: not a BLF log: " + (
                       "empty file (0 bytes)" if size == 0 else
                       f"{size} bytes, shorter than a BLF file header "
                       f"({blf.FILE_HEADER_STRUCT.size} bytes)"))
    try:
        reader = blf.BLFReader(path)
    except Exception as exc:
        raise LogError(f"{path}: cannot read CAN log: {exc}") from exc
    f = reader.file
    head_s, cont_s = blf.OBJ_HEADER_BASE_STRUCT, blf.LOG_CONTAINER_STRUCT
    lost = False  # after damage: the object stream is found again at an intact object
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
                reader._tail, lost = b"", True
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
                reader._tail, lost = b"", True
                continue
            if lost:  # the container after damage: its data start inside an object
                data = _resync(data, 0, damage, f"{path}: the container at byte {start}")
                lost = False
            while True:
                tail = reader._tail
                try:
                    if arrays:
                        yield from _container_arrays(reader, data)
                    else:
                        yield from reader._parse_container(data)
                    break
                except Exception as exc:  # a parse error inside the container's objects
                    damage.containers += 1
                    damage.warn(f"{path}: damaged frames in the container at byte {start} "
                                f"({type(exc).__name__}: {exc})")
                    reader._tail = b""
                    data = _resync(tail + data, reader._pos + 1, damage,
                                   f"{path}: the container at byte {start}")
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


def _first_object(data: bytes, pos: int) -> int | None:
    """Offset of the first intact-looking object header at or after ``pos`` in a container's
    decompressed data (``LOBJ``, header version 1 or 2 with its size, an object no smaller
    than its header; one too close to the end to check is taken), or None."""
    from can.io.blf import OBJ_HEADER_BASE_STRUCT as head_s

    while (i := data.find(b"LOBJ", pos)) >= 0:
        if i + head_s.size > len(data):
            return i
        _, hsize, version, size, _ = head_s.unpack_from(data, i)
        if hsize == {1: 32, 2: 40}.get(version) and size >= hsize:
            return i
        pos = i + 1
    return None


def _resync(data: bytes, pos: int, damage: LogDamage, where: str) -> bytes:
    """``data`` from its first intact object at or after ``pos`` (nothing when none): the
    bytes before it (the rest of a damaged object, or of one spanning from a damaged
    container) are skipped, counted in ``damage.bytes`` and warned about."""
    i = _first_object(data, pos)
    skip = len(data) if i is None else i
    if skip:
        damage.bytes += skip
        damage.warn(f"{where}: {skip} bytes skipped to " + (
            f"the next intact object (at byte {skip} of its data)" if i is not None
            else "its end (no intact object in it)"))
    return data[skip:]


def _container_arrays(reader: Any, data: bytes) -> Iterator[Any]:
    """The frames of one decompressed container as one FrameArrays: parsed as arrays, or,
    when :func:`~gyrostand.can.logs.blfarray.parse_container` declines, by python-can's own
    ``_parse_container`` (the frames it gave before an error are delivered, then the
    error is raised, as the per-object path delivers them)."""
    from gyrostand.can.logs.blfarray import parse_container

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
    """:func:`read_log` as :class:`~gyrostand.can.logs.blfarray.FrameArrays` chunks (a BLF
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
    from gyrostand.can.logs.blfarray import FrameArrays

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


def _next_object(f: BinaryIO | io.BufferedIOBase, start: int, chunk: int = 1 << 16) -> int | None:
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


def read_logs(paths: Iterable[str | Path], damage: LogDamage | None = None
              ) -> Iterator[can.Message]:
    """The frames of several logs (e.g. a resumed run's segments), one after the other."""
    for p in paths:
        yield from read_log(p, damage)
