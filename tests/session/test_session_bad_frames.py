"""Bad frames and commands on a live run: every bad frame is counted by reason (decoder
stats, heartbeat, run.log), the daemon keeps running, and the 1-s series is byte-identical
to that of the same frames without the bad ones."""

from __future__ import annotations

import json
from collections import Counter

import can
import pytest
from sessionhelpers import decode, make_cfg, run_virtual

from gyrostand.can.bus import FrameEncoder
from gyrostand.can.framesim import BAD_KINDS, BadFrameInjector
from gyrostand.can.routes import ChannelMap
from gyrostand.session.offline import run_replay, simulated_frames

BURST = 2000


@pytest.fixture(scope="module")
def bad_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bad")
    cfg = make_cfg(out, duration=300.0)
    clean = list(simulated_frames(cfg))
    inj = BadFrameInjector(cfg.db, ChannelMap.from_config(cfg), every=37,
                           kinds=tuple(BAD_KINDS))
    frames = list(inj(clean))
    # a burst of frames of an unknown id in the middle, all at one instant
    mid = len(frames) // 2
    t = frames[mid].timestamp
    frames[mid:mid] = [can.Message(timestamp=t, arbitration_id=0x7A5, is_extended_id=False,
                                   data=bytes(8))
                       for _ in range(BURST)]
    # commands after the data: snapshot, start (already running), an unknown code,
    # one for another node, reset; the stand then sends stop (sequence 1)
    enc, ref = FrameEncoder(cfg.db), cfg.responses.command
    t_end = clean[-1].timestamp
    cmd = cfg.db.get_message_by_name(ref.name)
    frames += [
        enc.command_frame(ref, "snapshot", 2, 1, timestamp=t_end + 0.01),
        enc.command_frame(ref, "start", 3, 255, timestamp=t_end + 0.02),
        can.Message(timestamp=t_end + 0.03, arbitration_id=ref.frame_id, is_extended_id=False,
                    data=cmd.encode({"Command": 9, "Sequence": 4, "Target": 1},
                                    strict=False)),
        enc.command_frame(ref, "reset", 5, 7, timestamp=t_end + 0.04),
        enc.command_frame(ref, "reset", 6, 1, timestamp=t_end + 0.05),
    ]
    expected = Counter(inj.expected)
    expected["unknown_id"] += BURST
    outcome, seen, stand = run_virtual(cfg, frames)
    clean_rep = run_replay(cfg, clean, out=out / "clean")
    return cfg, outcome, seen, stand, expected, clean_rep


def test_bad_frames_are_counted_by_reason(bad_run):
    cfg, outcome, seen, stand, expected, _ = bad_run
    assert outcome.ok and outcome.stop_reason == "stop command"
    dec = outcome.stats["decoder"]
    assert set(expected) == {"wrong_dlc", "unknown_id", "out_of_range", "error_frame",
                             "remote_frame", "non_monotonic", "bad_timestamp"}
    assert {k: v for k, v in dec["rejected"].items() if v} == dict(expected), dec["rejected"]
    assert dec["listener_errors"] == 0 and dec["received"] == stand.sent + 1
    p1 = [p for p in decode(cfg, seen, "GS_STATUS") if p["Page"] == 1]
    p2 = [p for p in decode(cfg, seen, "GS_STATUS") if p["Page"] == 2]
    assert p1[-1]["FramesRejected"] == sum(expected.values())
    assert p2[-1]["BusErrors"] == expected["error_frame"]
    log = (outcome.run_dir / "run.log").read_text()
    assert f"rejected frames {sum(expected.values())} (" in log
    assert f"unknown_id {expected['unknown_id']}" in log


def test_series_is_not_corrupted_by_bad_frames(bad_run):
    cfg, outcome, _, _, _, clean = bad_run
    got = (outcome.run_dir / "az" / "samples.csv").read_bytes()
    assert got == (clean.run_dir / "az" / "samples.csv").read_bytes()
    assert outcome.stats["binner"]["late"] == 0 and outcome.stats["binner"]["bins"] == 301


def test_commands_are_acked_or_refused_with_a_reason(bad_run):
    cfg, outcome, seen, stand, _, _ = bad_run
    acks = {d["Sequence"]: (d["Command"], d["Result"], d["Reason"])
            for d in decode(cfg, seen, "GS_ACK")}
    assert acks == {2: (4, 0, 0),    # snapshot: ok
                    3: (1, 1, 2),    # start while running: wrong_state
                    4: (9, 1, 1),    # unknown_command
                    6: (3, 0, 0),    # reset: ok (5 was for node 7: ignored)
                    1: (2, 0, 0)}    # stop
    assert outcome.stats["commands"] == {"received": 6, "acked": 3, "nacked": 2,
                                         "ignored": 1, "malformed": 0, "unknown": 1,
                                         "rate_limited": 0, "nacks_suppressed": 0}
    snap = json.loads((outcome.run_dir / "snapshot.json").read_text())
    assert snap["gyros"]["az"]["lsq"]["status"] in ("ok", "warning")
    # a reset restarts the online identifiers before the bin that holds its frame time
    # (replay = live): here it came after the last bin's end, so every row is from before
    last = (outcome.run_dir / "az" / "estimates.csv").read_text().splitlines()[-1]
    reset = FrameEncoder(cfg.db).command_frame(cfg.responses.command, "reset", 6, 1).data
    (reset_t,) = [f.timestamp for f in seen if f.arbitration_id == cfg.responses.command
                  .frame_id and bytes(f.data) == bytes(reset)]
    assert reset_t >= float(last.split(",")[0]) + cfg.sampling.dt
    assert last.endswith(",ok")
