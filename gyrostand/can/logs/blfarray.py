"""BLF containers parsed as arrays, and frames as arrays (:class:`FrameArrays`).

python-can's :class:`can.io.blf.BLFReader` builds one :class:`can.Message` per object of a
decompressed container (``_parse_data``), about 2 µs each. :func:`parse_container` parses
the same bytes with numpy: it walks the objects as python-can does (signature searched in
the 8 bytes after the previous object, an object that runs past the end kept as the tail
for the next container), and every run of consecutive objects with the same header (size,
type, header version) at one stride is read at once through a structured view. It reads
CAN_MESSAGE (1), CAN_MESSAGE2 (86), CAN_ERROR_EXT (73), CAN_FD_MESSAGE (100) and
CAN_FD_MESSAGE_64 (101) and skips other object types as python-can does.

The fields are python-can's, to the bit: the timestamp is ``float(Decimal(ticks) * 1e-5
or 1e-9) + start`` there, the correctly rounded quotient ``ticks / 10^5`` (or ``10^9``)
plus the start; here ``float64(ticks) / 1e5 + start``, the same correctly rounded IEEE
quotient while ``ticks < 2^53`` (exact in a double) and the same addition. The id, the
extended, remote and error flags and the payload (``data[:dlc]``, ``data[:valid_bytes]``,
CAN_FD_MESSAGE_64's zero padding, none for a remote frame) are taken as python-can and
:class:`can.Message` take them.

Anything else - an unknown header version, an object too small for its own fields, a
signature missing where python-can would raise, ticks of 2^53 or more, a CAN FD payload
stated longer than 64 bytes or an extended data offset - makes :func:`parse_container`
return None before it changes anything, and the caller parses that container with
python-can's own per-object code (with all its damage handling).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrostand.can.logs.frames import ERROR_FRAME, EXTENDED_KEY_BIT, REMOTE_FRAME

__all__ = ["FrameArrays", "parse_container", "SUPPORTED"]

CAN_MESSAGE, CAN_MESSAGE2, CAN_ERROR_EXT, CAN_FD_MESSAGE, CAN_FD_MESSAGE_64 = 1, 86, 73, 100, 101
SUPPORTED = (CAN_MESSAGE, CAN_MESSAGE2, CAN_ERROR_EXT, CAN_FD_MESSAGE, CAN_FD_MESSAGE_64)
_LOBJ = int.from_bytes(b"LOBJ", "little")
_EXT, _ID_MASK = 0x80000000, 0x1FFFFFFF
#: body size (bytes python-can unpacks after the object header) per object type
_BODY = {CAN_MESSAGE: 16, CAN_MESSAGE2: 16, CAN_ERROR_EXT: 32, CAN_FD_MESSAGE: 84,
         CAN_FD_MESSAGE_64: 40}
_VHEAD = {1: 16, 2: 24}  # OBJ_HEADER_V1 / V2 sizes
_TICKS_LIMIT = 1 << 53


@dataclass
class FrameArrays:
    """Frames as arrays, in order: ``t`` timestamps (s, float64), ``key`` the id (|
    EXTENDED_KEY_BIT for an extended id, int64), ``flags`` ERROR_FRAME | REMOTE_FRAME
    (uint8), ``length`` payload bytes (int16) and ``data`` the payloads, zero-padded
    (uint8, n x 8, or n x 64 when a payload is longer than 8 bytes)."""

    t: np.ndarray
    key: np.ndarray
    flags: np.ndarray
    length: np.ndarray
    data: np.ndarray

    def __len__(self) -> int:
        return len(self.t)

    def frames(self, start: int = 0, stop: int | None = None) -> list:
        """Frames ``start:stop`` as :data:`~gyrostand.can.logs.frames.Frame` tuples (the
        payload as ``bytes`` of its length)."""
        d = self.data[start:stop]
        ls = self.length[start:stop].tolist()
        raw = d.tobytes()
        w = d.shape[1]
        pay = [raw[i * w:i * w + n] for i, n in enumerate(ls)]
        return list(zip(self.t[start:stop].tolist(), self.key[start:stop].tolist(),
                        self.flags[start:stop].tolist(), pay, strict=True))

    def __getitem__(self, s: slice) -> FrameArrays:
        return FrameArrays(self.t[s], self.key[s], self.flags[s], self.length[s],
                           self.data[s])

    @classmethod
    def from_frames(cls, frames: Sequence) -> FrameArrays:
        """From :data:`~gyrostand.can.logs.frames.Frame` tuples (payloads up to 64 bytes)."""
        n = len(frames)
        if n == 0:
            return cls.empty()
        t, key, flags, pay = zip(*frames, strict=True)
        lens = [len(p) for p in pay]
        w = 8 if max(lens) <= 8 else 64
        if max(lens) > 64:
            raise ValueError("a payload longer than 64 bytes")
        buf = b"".join(bytes(p).ljust(w, b"\0") for p in pay)
        return cls(np.array(t, dtype=np.float64), np.array(key, dtype=np.int64),
                   np.array(flags, dtype=np.uint8), np.array(lens, dtype=np.int16),
                   np.frombuffer(buf, dtype=np.uint8).reshape(n, w).copy())

    @classmethod
    def empty(cls, width: int = 8) -> FrameArrays:
        return cls(np.empty(0, np.float64), np.empty(0, np.int64), np.empty(0, np.uint8),
                   np.empty(0, np.int16), np.empty((0, width), np.uint8))

    @classmethod
    def concat(cls, parts: Sequence[FrameArrays]) -> FrameArrays:
        parts = [p for p in parts if len(p)]
        if not parts:
            return cls.empty()
        if len(parts) == 1:
            return parts[0]
        w = max(p.data.shape[1] for p in parts)
        data = [p.data if p.data.shape[1] == w else
                np.pad(p.data, ((0, 0), (0, w - p.data.shape[1]))) for p in parts]
        return cls(np.concatenate([p.t for p in parts]),
                   np.concatenate([p.key for p in parts]),
                   np.concatenate([p.flags for p in parts]),
                   np.concatenate([p.length for p in parts]), np.concatenate(data))


def _header(buf: bytes, pos: int) -> tuple[int, int, int, int]:
    """(header size, header version, object size, object type) at ``pos``."""
    return (int.from_bytes(buf[pos + 4:pos + 6], "little"),
            int.from_bytes(buf[pos + 6:pos + 8], "little"),
            int.from_bytes(buf[pos + 8:pos + 12], "little"),
            int.from_bytes(buf[pos + 12:pos + 16], "little"))


def _view(buf: bytes, pos: int, m: int, stride: int, fields: dict[str, tuple[Any, int]],
          itemsize: int) -> np.ndarray:
    dt = np.dtype({"names": list(fields), "formats": [f for f, _ in fields.values()],
                   "offsets": [o for _, o in fields.values()], "itemsize": itemsize})
    return np.ndarray((m,), dtype=dt, buffer=buf, offset=pos, strides=(stride,))


def _run(buf: bytes, pos: int, size: int, stride: int, n: int) -> int:
    """How many objects from ``pos`` on, at ``stride``, python-can would read one after
    the other with the very header of the first (and nothing found in the padding)."""
    m = (n - pos - size) // stride + 1
    if m <= 1:
        return 1
    head = _view(buf, pos, m, stride, {"sig": ("<u4", 0), "a": ("<u4", 4), "b": ("<u8", 8)},
                 16)
    ok = (head["sig"] == _LOBJ) & (head["a"] == head["a"][0]) & (head["b"] == head["b"][0])
    if stride > size:  # padding: python-can's search would stop at an earlier signature
        for k in range(size, min(stride, size + 5)):
            if k + 4 > size + 8:
                break
            pad = np.ndarray((m - 1,), dtype="<u4", buffer=buf, offset=pos + k,
                             strides=(stride,))
            ok[1:] &= pad != _LOBJ
    bad = np.flatnonzero(~ok)
    return int(bad[0]) if len(bad) else m


def _parse_run(buf: bytes, pos: int, r: int, stride: int, size: int, hsize: int,
               version: int, otype: int, start: float) -> FrameArrays | None:
    body = 16 + _VHEAD[version]
    f: dict[str, tuple[Any, int]] = {"tflags": ("<u4", 16), "ticks": ("<u8", 24)}
    if otype in (CAN_MESSAGE, CAN_MESSAGE2):
        f |= {"mflags": ("u1", body + 2), "dlc": ("u1", body + 3), "id": ("<u4", body + 4),
              "data": (("u1", 8), body + 8)}
    elif otype == CAN_ERROR_EXT:
        f |= {"dlc": ("u1", body + 10), "id": ("<u4", body + 16),
              "data": (("u1", 8), body + 24)}
    elif otype == CAN_FD_MESSAGE:
        f |= {"mflags": ("u1", body + 2), "id": ("<u4", body + 4),
              "valid": ("u1", body + 14), "data": (("u1", 64), body + 20)}
    else:  # CAN_FD_MESSAGE_64
        cap = size - body - 40  # payload bytes the object holds after its fields
        f |= {"valid": ("u1", body + 2), "id": ("<u4", body + 4),
              "fdflags": ("<u4", body + 12), "ext": ("u1", body + 35)}
        if cap > 0:
            f["data"] = (("u1", min(cap, 64)), body + 40)
    v = _view(buf, pos, r, stride, f, size)
    ticks = v["ticks"]
    if int(ticks.max()) >= _TICKS_LIMIT:
        return None
    tf = ticks.astype(np.float64)
    t = np.where(v["tflags"] == 1, tf / 1e5, tf / 1e9) + start
    cid = v["id"].astype(np.int64)
    key = (cid & _ID_MASK) | np.where(cid & _EXT, EXTENDED_KEY_BIT, 0)
    width = 8
    if otype in (CAN_MESSAGE, CAN_MESSAGE2):
        flags = np.where(v["mflags"] & 0x80, REMOTE_FRAME, 0).astype(np.uint8)
        length = np.minimum(v["dlc"], 8).astype(np.int16)
        data = np.array(v["data"])
    elif otype == CAN_ERROR_EXT:
        flags = np.full(r, ERROR_FRAME, np.uint8)
        length = np.minimum(v["dlc"], 8).astype(np.int16)
        data = np.array(v["data"])
    elif otype == CAN_FD_MESSAGE:
        flags = np.where(v["mflags"] & 0x80, REMOTE_FRAME, 0).astype(np.uint8)
        length = np.minimum(v["valid"], 64).astype(np.int16)
        data, width = np.array(v["data"]), 64
    else:
        if (v["ext"] != 0).any() or hsize != body:
            return None  # an extended data offset, or a header of another length
        valid = v["valid"].astype(np.int16)
        if int(valid.max()) > 64:
            return None
        flags = np.where(v["fdflags"] & 0x10, REMOTE_FRAME, 0).astype(np.uint8)
        length = valid
        width = 64
        data = np.zeros((r, 64), np.uint8)
        if "data" in f:
            have = np.array(v["data"])
            data[:, :have.shape[1]] = have
        # python-can: data[:min(valid, cap)] padded with zeros to valid bytes
        cols = np.arange(64)
        data[cols[None, :] >= np.minimum(valid, max(cap, 0))[:, None]] = 0
    # can.Message keeps no payload for a remote frame
    length = np.where(flags & REMOTE_FRAME, 0, length).astype(np.int16)
    if width == 64 and data.shape[1] != 64:
        data = np.pad(data, ((0, 0), (0, 64 - data.shape[1])))
    # bytes beyond a frame's length are zero (FrameArrays' padding)
    if width == 8:
        data[np.arange(8)[None, :] >= length[:, None]] = 0
    else:
        data[np.arange(64)[None, :] >= length[:, None]] = 0
    return FrameArrays(t, key, flags, length, data)


def parse_container(data: bytes, start_timestamp: float
                    ) -> tuple[FrameArrays, bytes] | None:
    """The frames of one decompressed container's bytes (the previous container's tail
    already prepended, as python-can's ``_parse_container`` does) and the new tail, or
    None when python-can's own parser must read it (see the module's text)."""
    n = len(data)
    pos = 0
    parts: list[FrameArrays] = []
    find = data.find
    while True:
        cur = pos  # python-can's self._pos: where the tail starts if this object is cut
        i = find(b"LOBJ", pos, pos + 8)
        if i < 0:
            if pos + 8 > n:
                break
            return None  # python-can raises BLFParseError: its damage handling decides
        pos = i
        if pos + 16 > n:
            break  # struct.error in python-can: the tail starts at cur
        hsize, version, size, otype = _header(data, pos)
        if version not in _VHEAD:
            return None
        need = 16 + _VHEAD[version] + _BODY.get(otype, 0)
        if size < need:
            return None  # python-can would read past the object (or loop on it)
        if pos + size > n:
            break  # continues in the next container
        if otype not in _BODY:  # skipped by python-can (after reading its header)
            pos += size
            continue
        # the stride to the next object, as python-can's search would find it
        nxt = find(b"LOBJ", pos + size, pos + size + 8)
        stride = nxt - pos if nxt >= 0 else size
        r = _run(data, pos, size, stride, n) if nxt >= 0 else 1
        part = _parse_run(data, pos, r, stride, size, hsize, version, otype,
                          start_timestamp)
        if part is None:
            return None
        parts.append(part)
        pos += (r - 1) * stride + size
    return FrameArrays.concat(parts), data[cur:]
