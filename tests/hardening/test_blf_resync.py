"""One damaged BLF container costs only its own frames (issue 28, finding 1), through
``gyrostand replay``: 4 bytes flipped inside one container of a BLF written by python-can
(:class:`can.Logger`, its default container size), and the next container, which starts
with the tail of an object spanning the two, is read from its first intact object on.

The truth comes from the undamaged file: the frame objects having any byte in the damaged
container's part of the decompressed stream are the ones lost, exactly (before: "Could not
find next object" discarded the next container too: 5,462 of 9,021 frames lost, 2
containers skipped, with one damaged)."""

from __future__ import annotations

import json
import zlib

import can
import pytest
from can.io import blf

from gyrostand.cli import main as cli_main

from .procs import simulated_session


def _containers(raw: bytes) -> list[tuple[int, int, bytes]]:
    """(file offset, object size, decompressed data) of each top-level container."""
    out, pos = [], blf.FILE_HEADER_SIZE
    head_s, cont_s = blf.OBJ_HEADER_BASE_STRUCT, blf.LOG_CONTAINER_STRUCT
    while pos + head_s.size <= len(raw):
        sig, _, _, size, otype = head_s.unpack_from(raw, pos)
        assert sig == b"LOBJ" and otype == blf.LOG_CONTAINER
        packed = raw[pos + head_s.size + cont_s.size:pos + size]
        out.append((pos, size, zlib.decompress(packed)))
        pos += size + size % 4
    return out


def _frame_spans(stream: bytes) -> list[tuple[int, int]]:
    """[start, end) in the decompressed stream of every CAN message object, in order
    (the walk python-can's ``_parse_data`` makes: the next signature within 8 bytes)."""
    spans, pos = [], 0
    while (pos := stream.find(b"LOBJ", pos, pos + 8)) >= 0:
        _, _, _, size, otype = blf.OBJ_HEADER_BASE_STRUCT.unpack_from(stream, pos)
        if otype in (blf.CAN_MESSAGE, blf.CAN_MESSAGE2):
            spans.append((pos, pos + size))
        pos += size
    return spans


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("resync")
    cfg_path, frames = simulated_session(tmp)
    path = tmp / "whole.blf"
    with can.Logger(str(path)) as lg:
        for f in frames:
            lg.on_message_received(f)
    raw = path.read_bytes()
    conts = _containers(raw)
    spans = _frame_spans(b"".join(d for *_, d in conts))
    assert len(spans) == len(frames) and len(conts) == 4
    return cfg_path, raw, conts, spans


@pytest.mark.parametrize("per_frame", [False, True])
@pytest.mark.parametrize("k", [0, 1, 2])
def test_one_damaged_container_loses_only_its_own_frames(logged, tmp_path, capsys, k,
                                                         per_frame):
    cfg_path, raw, conts, spans = logged
    pos, size, _ = conts[k]
    lo = sum(len(d) for *_, d in conts[:k])  # the damaged container's part of the stream
    hi = lo + len(conts[k][2])
    lost = [i for i, (a, b) in enumerate(spans) if a < hi and b > lo]
    assert len(lost) > 2700
    damaged = bytearray(raw)
    mid = pos + 32 + size // 2
    damaged[mid:mid + 4] = bytes(b ^ 0xFF for b in damaged[mid:mid + 4])
    log = tmp_path / "damaged.blf"
    log.write_bytes(bytes(damaged))
    rc = cli_main(["replay", str(cfg_path), str(log), "--out", str(tmp_path / "runs"),
                   "--json", *(["--per-frame"] if per_frame else [])])
    out = capsys.readouterr()
    assert rc == 0, out.err
    doc = json.loads(out.out)
    stats = doc["stats"]
    assert stats["decoder"]["received"] == len(spans) - len(lost)
    assert stats["log"]["containers_skipped"] == 1
    # the tail of the object spanning out of the damaged container (if one does), skipped
    # at the start of the next one
    spill = max(0, spans[lost[-1]][1] - hi)
    assert stats["log"]["bytes_skipped"] == spill
    assert stats["log"]["notes"] == [
        f"{log}: damaged container at byte {pos} skipped (Error -3 while decompressing "
        f"data: incorrect data check)"] + ([
            f"{log}: the container at byte {conts[k + 1][0]}: {spill} bytes skipped to the "
            f"next intact object (at byte {spill} of its data)"] if spill else [])
    assert spill > 0 or k == 2  # (container 3 of this log starts with an object)
