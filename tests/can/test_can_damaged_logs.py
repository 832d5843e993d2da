"""Damaged logs (issue 11, items 6 and 7): a damaged BLF container or a bad ASC/candump
line is skipped with a counted, logged warning and reading goes on; a BLF cut inside a
container is read up to the cut with a warning; a replay that fails marks its folder
``failed``. Damage at random offsets (hypothesis): whatever is read is a subsequence of
the frames written, and anything missing is accounted for."""

from __future__ import annotations

import json
import random
import re

import can
import pytest
from canhelpers import ROOT, damaged, smooth_truth
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gyrostand.can.framesim import FrameSimOptions, generate_frames
from gyrostand.can.logs.read import LogDamage, read_log
from gyrostand.can.recorder import Recorder
from gyrostand.can.routes import ChannelMap
from gyrostand.config import load_config
from gyrostand.errors import CanEdgeError

CFG = load_config(ROOT / "configs" / "demo.yaml")
FRAMES = list(generate_frames(CFG.db, ChannelMap.from_config(CFG), [smooth_truth(30)],
                              FrameSimOptions(drift_rate=20, temperature_rate=5,
                                              jitter=0.002, seed=5)))
BLF_HEADER = 144


def _key(m: can.Message):
    return (m.timestamp, m.arbitration_id, bytes(m.data))


def _blf(path, frames=FRAMES, container=2048):
    with Recorder(path, max_container_size=container) as rec:  # many containers, as a long run has
        for f in frames:
            rec.on_message_received(f)
    return path.read_bytes()


def _is_subsequence(got, want) -> bool:
    it = iter(want)
    return all(any(g == w for w in it) for g in got)


@pytest.fixture(scope="module")
def blf_bytes(tmp_path_factory):
    return _blf(tmp_path_factory.mktemp("blf") / "whole.blf")


@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.data())
def test_blf_damaged_at_random_offsets_reads_the_rest(blf_bytes, tmp_path_factory, data):
    raw, kind, at = damaged(blf_bytes, data, BLF_HEADER)
    path = tmp_path_factory.mktemp("bad") / "d.blf"
    path.write_bytes(bytes(raw))
    damage = LogDamage()
    got = [_key(m) for m in read_log(path, damage)]  # never raises past the header
    want = [_key(m) for m in FRAMES]
    assert _is_subsequence(got, want)
    if len(got) < len(want):
        assert damage.total + damage.other_objects > 0, (kind, at)
        if damage.total:
            assert damage.notes and str(path) in damage.notes[0]


def test_blf_with_a_damaged_header_is_an_error_naming_the_file(blf_bytes, tmp_path):
    path = tmp_path / "h.blf"
    path.write_bytes(b"XXXX" + blf_bytes[4:])
    with pytest.raises(CanEdgeError, match=r"h\.blf: cannot read CAN log"):
        list(read_log(path))


def test_one_damaged_container_costs_that_container_only(blf_bytes, tmp_path, caplog):
    raw = bytearray(blf_bytes)
    starts = [i for i in range(BLF_HEADER, len(raw)) if raw[i:i + 4] == b"LOBJ"]
    mid = starts[len(starts) // 2]
    raw[mid + 40:mid + 60] = b"\xa5" * 20  # inside its compressed data
    path = tmp_path / "c.blf"
    path.write_bytes(bytes(raw))
    damage = LogDamage()
    got = list(read_log(path, damage))
    assert damage.containers == 1 and damage.truncated == 0
    assert f"damaged container at byte {mid}" in caplog.text
    lost = len(FRAMES) - len(got)
    assert 0 < lost < 2048 // 16 + 2  # about one container's frames
    assert _key(got[-1]) == _key(FRAMES[-1])  # reading went on to the end


def test_truncated_inside_a_container_warns(blf_bytes, tmp_path, caplog):
    path = tmp_path / "t.blf"
    path.write_bytes(blf_bytes[:-300])
    damage = LogDamage()
    got = list(read_log(path, damage))
    assert damage.truncated == 1 and "cut short inside the container" in caplog.text
    assert 0 < len(got) < len(FRAMES)


@pytest.mark.parametrize("suffix", [".log", ".asc"])
def test_text_log_bad_lines_skipped_counted_named(tmp_path, caplog, suffix):
    path = tmp_path / f"x{suffix}"
    with can.Logger(str(path)) as lg:
        for f in FRAMES:
            lg.on_message_received(f)
    clean = [_key(m) for m in read_log(path)]
    lines = path.read_text().splitlines(keepends=True)
    rng = random.Random(3)
    body = [i for i, ln in enumerate(lines) if "#" in ln or re.search(r" [RT]x ", ln)]
    broken = sorted(rng.sample(body, 5))
    for i in broken:
        lines[i] = lines[i][:12] + " #garbage§\n" if suffix == ".log" else \
            lines[i].replace(" d 8 ", " d 8 zz ")
    path.write_text("".join(lines))
    damage = LogDamage()
    got = [_key(m) for m in read_log(path, damage)]
    assert len(got) == len(clean) - 5 and _is_subsequence(got, clean)
    assert damage.lines == 5
    assert f"{path.name}: line {broken[0] + 1}: cannot parse" in caplog.text


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=400), st.integers(0, 10_000))
def test_candump_with_random_bytes_spliced_in_never_aborts(tmp_path_factory, junk, at):
    path = tmp_path_factory.mktemp("cd") / "r.log"
    with can.Logger(str(path)) as lg:
        for f in FRAMES[:200]:
            lg.on_message_received(f)
    raw = path.read_bytes()
    at = at % len(raw)
    path.write_bytes(raw[:at] + junk + raw[at:])
    got = list(read_log(path, LogDamage()))
    assert len(got) >= 200 - 2 - junk.count(b"\n")


def test_replay_of_a_damaged_log_finishes_and_counts_it(blf_bytes, tmp_path):
    from gyrostand.session.offline import run_replay

    raw = bytearray(blf_bytes)
    starts = [i for i in range(BLF_HEADER, len(raw)) if raw[i:i + 4] == b"LOBJ"]
    raw[starts[3] + 40:starts[3] + 60] = b"\x5a" * 20
    path = tmp_path / "c.blf"
    path.write_bytes(bytes(raw))
    out = run_replay(CFG, path, out=tmp_path / "runs", parallel=False)
    doc = json.loads(out.result_json.read_text())
    assert doc["state"] == "finished" and doc["stats"]["log"]["containers_skipped"] == 1
    assert out.stats["decoder"]["received"] < len(FRAMES)


def test_a_replay_that_fails_marks_its_folder_failed(tmp_path):
    from gyrostand.session.offline import run_replay

    with pytest.raises(CanEdgeError, match="nothing.blf: log file not found"):
        run_replay(CFG, tmp_path / "nothing.blf", out=tmp_path / "runs")
    (run,) = (tmp_path / "runs").iterdir()
    doc = json.loads((run / "result.json").read_text())
    assert doc["state"] == "failed" and "nothing.blf: log file not found" in doc["error"]
