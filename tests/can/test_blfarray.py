"""BLF containers parsed as arrays (gyrostand.can.logs.blfarray, issue 13's vectorized path):
frame for frame python-can's BLFReader (timestamp to the bit, id, extended, error,
remote, payload) on every kind of BLF the tests write, on crafted containers of every
object type it reads (header versions 1 and 2, 10-µs and 1-ns ticks, padding, objects
split across containers, object types it skips), and, through the damage-handling reader,
the same frames and the same damage counts and messages on damaged files."""

from __future__ import annotations

import random
import struct

import can
import pytest
from can.io import blf
from canhelpers import damaged, smooth_truth
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gyrostand.can.framesim import FrameSimOptions, generate_frames
from gyrostand.can.logs.blfarray import FrameArrays, parse_container
from gyrostand.can.logs.frames import frame_fields
from gyrostand.can.logs.read import LogDamage, _container_arrays, read_log, read_log_arrays
from gyrostand.can.recorder import Recorder
from gyrostand.can.routes import ChannelMap


def _exact(frames):
    """Frames with the timestamp's bits (== alone would let -0.0 == 0.0 pass)."""
    return [(struct.pack("<d", t), k, f, bytes(d)) for t, k, f, d in frames]


def _reference(path):
    reader = can.BLFReader(path)
    try:
        return _exact(frame_fields(m) for m in reader)
    finally:
        reader.stop()


def _arrays(path, damage=None):
    parts = list(read_log_arrays(path, damage))
    assert all(isinstance(p, FrameArrays) for p in parts)
    return _exact(FrameArrays.concat(parts).frames())


def _write(path, messages, container=128 * 1024):
    with can.BLFWriter(path) as w:
        w.max_container_size = container
        for m in messages:
            w.on_message_received(m)
    return path


def _mixed(n=3000, seed=3):
    """Classic (dlc 0-8), remote, error, extended and CAN FD frames, jittered times."""
    rng = random.Random(seed)
    t = 1_700_000_000.123
    out = []
    for i in range(n):
        t += rng.uniform(0.0, 0.003)
        kind = rng.random()
        ext = rng.random() < 0.3
        aid = rng.getrandbits(29 if ext else 11)
        if kind < 0.05:
            out.append(can.Message(timestamp=t, is_error_frame=True, arbitration_id=aid,
                                   is_extended_id=ext, dlc=rng.randint(0, 8),
                                   data=bytes(rng.getrandbits(8) for _ in range(8))))
        elif kind < 0.1:
            out.append(can.Message(timestamp=t, arbitration_id=aid, is_extended_id=ext,
                                   is_remote_frame=True, dlc=rng.randint(0, 8)))
        elif kind < 0.25:
            size = rng.choice([0, 3, 8, 12, 16, 20, 24, 32, 48, 64])
            out.append(can.Message(timestamp=t, arbitration_id=aid, is_extended_id=ext,
                                   is_fd=True, bitrate_switch=rng.random() < 0.5,
                                   data=bytes(rng.getrandbits(8) for _ in range(size))))
        else:
            size = rng.randint(0, 8)
            out.append(can.Message(timestamp=t, arbitration_id=aid, is_extended_id=ext,
                                   data=bytes(rng.getrandbits(8) for _ in range(size)),
                                   is_rx=rng.random() < 0.9, channel=i % 2))
    return out


@pytest.mark.parametrize("container", [128 * 1024, 2048, 333, 60])
def test_mixed_frames_match_python_can(tmp_path, container):
    path = _write(tmp_path / "m.blf", _mixed(), container)
    want = _reference(path)
    assert len(want) >= 2990  # (python-can itself may lose one when containers are tiny)
    assert _arrays(path) == want


def test_session_logs_match_python_can(tmp_path, demo_cfg, triad_cfg, foreign_cfg):
    demo = list(generate_frames(demo_cfg.db, ChannelMap.from_config(demo_cfg),
                                [smooth_truth(30)],
                                FrameSimOptions(drift_rate=20, temperature_rate=5,
                                                jitter=0.002, seed=5)))
    with Recorder(tmp_path / "demo.blf", max_container_size=2048) as rec:
        for f in demo:
            rec.on_message_received(f)
    paths = [tmp_path / "demo.blf"]
    for name, cfg in (("triad", triad_cfg), ("foreign", foreign_cfg)):
        cm = ChannelMap.from_config(cfg)
        frames = list(generate_frames(cfg.db, cm, [smooth_truth(40, k)
                                                   for k in range(len(cm.gyros))],
                                      FrameSimOptions(drift_rate=100, temperature_rate=20,
                                                      jitter=0.001, drop=0.01, seed=11)))
        paths.append(_write(tmp_path / f"{name}.blf", frames))
    for p in paths:
        want = _reference(p)
        assert len(want) > 500
        assert _arrays(p) == want, p


# -- crafted containers ---------------------------------------------------------------

def _obj(rng, otype, version, tflags, ticks):
    if otype in (blf.CAN_MESSAGE, blf.CAN_MESSAGE2):
        body = blf.CAN_MSG_STRUCT.pack(1, rng.choice([0, 0x80, 1]), rng.randint(0, 15),
                                       rng.getrandbits(32), rng.randbytes(8))
        if otype == blf.CAN_MESSAGE2:
            body += struct.pack("<LBB2x", 0, 0, 0)
    elif otype == blf.CAN_ERROR_EXT:
        body = blf.CAN_ERROR_EXT_STRUCT.pack(1, 0, 0, 0, 0, rng.randint(0, 15), 0,
                                             rng.getrandbits(32), 0, rng.randbytes(8))
    elif otype == blf.CAN_FD_MESSAGE:
        body = blf.CAN_FD_MSG_STRUCT.pack(1, rng.choice([0, 0x80]), rng.randint(0, 15),
                                          rng.getrandbits(32), 0, 0, 1,
                                          rng.choice([0, 5, 8, 20, 64, 70]),
                                          rng.randbytes(64))
    elif otype == blf.CAN_FD_MESSAGE_64:
        valid = rng.choice([0, 8, 12, 64])
        held = rng.choice([valid, max(0, valid - 4)])  # fewer bytes than stated: zeros
        body = blf.CAN_FD_MSG_64_STRUCT.pack(1, 9, valid, 0, rng.getrandbits(32), 0,
                                             rng.choice([0x1000, 0x1010, 0x3000]), 0, 0, 0,
                                             0, 0, 0, 0, 0) + rng.randbytes(held)
    else:  # an object type neither reader decodes (e.g. a global marker)
        body = rng.randbytes(rng.choice([8, 13, 40]))
    vhead = (blf.OBJ_HEADER_V1_STRUCT.pack(tflags, 0, 0, ticks) if version == 1
             else blf.OBJ_HEADER_V2_STRUCT.pack(tflags, 0, 0, ticks))
    size = 16 + len(vhead) + len(body)
    pad = rng.choice([0, 0, 0, size % 4, 4 - size % 4 if size % 4 else 0])
    return (blf.OBJ_HEADER_BASE_STRUCT.pack(b"LOBJ", 16 + len(vhead), version, size, otype)
            + vhead + body + bytes(pad))


def _stream(seed, n=400):
    """Object bytes: runs of one type and header (as loggers write) and odd ones."""
    rng = random.Random(seed)
    out = []
    ticks = rng.getrandbits(40)
    types = [1, 86, 73, 100, 101, 96, 1, 1]
    while len(out) < n:
        otype, version, tflags = rng.choice(types), rng.choice([1, 1, 2]), rng.choice([1, 2])
        for _ in range(rng.choice([1, 2, 50])):
            ticks += rng.randint(0, 10**7)
            out.append(_obj(rng, otype, version, tflags, ticks))
    return b"".join(out)


def _reader(tmp_path):
    path = _write(tmp_path / "e.blf", [can.Message(timestamp=1_700_000_000.5)])
    r = can.BLFReader(path)
    r.stop()
    return r


@pytest.mark.parametrize("seed", range(6))
def test_crafted_containers_match_python_can(tmp_path, seed):
    raw = _stream(seed)
    rng = random.Random(seed)
    cuts = sorted(rng.sample(range(1, len(raw)), 25))
    pieces = [raw[a:b] for a, b in zip([0] + cuts, cuts + [len(raw)], strict=True)]
    ref, mine = _reader(tmp_path), _reader(tmp_path)
    want, got = [], []
    for piece in pieces:  # objects split across containers: the tail carries them over
        want += _exact(frame_fields(m) for m in ref._parse_container(piece))
        for part in _container_arrays(mine, piece):
            got += _exact(part.frames())
        assert mine._tail == ref._tail
    assert len(want) > 50
    assert got == want
    # and parsed as arrays, not by the fallback: a whole stream at once
    whole = parse_container(raw, ref.start_timestamp)
    assert whole is not None
    assert _exact(whole[0].frames()) == _exact(
        frame_fields(m) for m in _reader(tmp_path)._parse_container(raw))


def test_declined_containers_go_to_python_can(tmp_path):
    rng = random.Random(1)
    good = b"".join(_obj(rng, 1, 1, 2, 1000 * i) for i in range(10))
    odd_version = bytearray(_obj(rng, 1, 1, 2, 5000))
    odd_version[6:8] = (3).to_bytes(2, "little")  # python-can warns and skips it
    huge = _obj(rng, 1, 1, 2, 1 << 60)  # ticks a double cannot hold exactly
    for raw in (good + bytes(odd_version) + good, good + huge + good):
        assert parse_container(raw, 1.5) is None
        ref, mine = _reader(tmp_path), _reader(tmp_path)
        want = _exact(frame_fields(m) for m in ref._parse_container(raw))
        got = [f for p in _container_arrays(mine, raw) for f in _exact(p.frames())]
        assert got == want and len(got) >= 20


# -- damaged files: the same frames and the same damage as the per-object reader -------

@pytest.fixture(scope="module")
def mixed_bytes(tmp_path_factory):
    return _write(tmp_path_factory.mktemp("blfa") / "w.blf", _mixed(800), 1500).read_bytes()


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.data())
def test_damaged_files_read_alike(mixed_bytes, tmp_path_factory, data):
    raw, _, _ = damaged(mixed_bytes, data, 144)
    path = tmp_path_factory.mktemp("bad") / "d.blf"
    path.write_bytes(bytes(raw))
    d1, d2 = LogDamage(), LogDamage()
    want = _exact(frame_fields(m) for m in read_log(path, d1))
    got = _arrays(path, d2)
    assert got == want
    assert d2.as_dict() == d1.as_dict()
