"""Bad timestamps on a live run (issue 11, items 1 and 4): a stray first frame at t = 1,
a host clock stepping back 300 s, one frame 3000 s ahead, a clock stepping back two days
(beyond the raw BLF's one-day margin: the raw log continues in a new file). The daemon
loses only the bad frames, answers the stop command, and the replay of its raw log is
byte-identical to its live samples.csv (replay = live)."""

from __future__ import annotations

import json

import can
import pytest
from sessionhelpers import make_cfg, run_virtual

from gyrostand.can.recorder import Recorder
from gyrostand.can.replay import read_logs
from gyrostand.runfolder import raw_segments
from gyrostand.session.offline import run_replay, simulated_frames


def _shift(f: can.Message, t: float) -> can.Message:
    return can.Message(timestamp=t, arbitration_id=f.arbitration_id,
                       is_extended_id=f.is_extended_id, data=bytes(f.data))


@pytest.fixture(scope="module")
def stepped_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("steps")
    cfg = make_cfg(out, duration=400.0)
    clean = list(simulated_frames(cfg))
    n = len(clean)
    a, b, c = n // 4, n // 2, 3 * n // 4
    frames = [_shift(clean[0], 1.0)] + clean[:a]
    frames += [_shift(f, f.timestamp - 300.0) for f in clean[a:b]]
    frames += [_shift(clean[b], clean[b].timestamp - 300.0 + 3000.0)]  # stray future
    frames += [_shift(f, f.timestamp - 300.0) for f in clean[b + 1:c]]
    frames += [_shift(f, f.timestamp - 300.0 - 2 * 86400.0) for f in clean[c:]]
    outcome, _, stand = run_virtual(cfg, frames)
    return cfg, outcome, stand, frames, out


def test_the_daemon_keeps_every_good_frame_and_answers_stop(stepped_run):
    cfg, outcome, stand, frames, _ = stepped_run
    assert outcome.ok and outcome.stop_reason == "stop command"
    dec = outcome.stats["decoder"]
    assert dec["clock_steps"] == 2  # 300 s back, then two days back
    assert dec["rejected"]["time_jump"] + dec["rejected"]["non_monotonic"] == 2
    assert dec["decoded"] == len(frames) - 2 + 1  # every good frame and the stop command
    files = outcome.stats["recorder"]["files"]
    assert files[0] == "raw.blf" and len(files) >= 2  # t = 1 and two days back: new files


def test_raw_log_is_faithful_and_replay_equals_live(stepped_run, tmp_path):
    cfg, outcome, stand, frames, _ = stepped_run
    segs = raw_segments(outcome.run_dir)
    assert [p.name for p in segs] == outcome.stats["recorder"]["files"]
    recorded = list(read_logs(segs))
    sent = frames + [None]  # the stop command follows the frames
    assert len(recorded) == len(sent)
    for got, want in zip(recorded, frames, strict=False):
        assert abs(got.timestamp - want.timestamp) < 2e-9 and bytes(got.data) == \
            bytes(want.data)
        if want.timestamp > 1e9:
            assert got.timestamp == want.timestamp  # to the bit
    rep = run_replay(cfg, segs, out=tmp_path, parallel=False)
    live_csv = (outcome.run_dir / "az" / "samples.csv").read_bytes()
    assert (rep.run_dir / "az" / "samples.csv").read_bytes() == live_csv
    doc = json.loads(rep.result_json.read_text())
    assert doc["stats"]["decoder"]["clock_steps"] == 2


def test_the_recorder_starts_a_new_file_for_a_frame_it_cannot_store(tmp_path):
    t0 = 1_700_000_000.0
    ts = [t0, t0 + 0.5, t0 - 300.0, t0 - 86000.0, t0 - 90000.0, t0 - 89999.0, 1.0, t0 + 1]
    with Recorder(tmp_path / "raw.blf") as rec:
        for i, t in enumerate(ts):
            rec.on_message_received(can.Message(timestamp=t, arbitration_id=0x100 + i,
                                                is_extended_id=False, data=bytes(8)))
    assert [p.name for p in rec.files] == ["raw.blf", "raw-2.blf", "raw-3.blf",
                                           "raw-4.blf"]
    got = [m.timestamp for m in read_logs(rec.files)]
    assert got == ts  # every time exactly as received (python-can alone: clamped)
    plain = tmp_path / "plain.blf"
    with can.BLFWriter(plain) as w:
        for t in ts[:3]:
            w.on_message_received(can.Message(timestamp=t, arbitration_id=1, data=b""))
    assert [m.timestamp for m in can.LogReader(plain)][2] != ts[2]  # what item 4 found
