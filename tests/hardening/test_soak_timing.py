"""Soak-style (issue 11, acceptance): a live daemon (a real process) over python-can-remote
on 127.0.0.1, fed a stand whose stream has, in this order, a host clock stepping back
300 s, a stray frame 3000 s in the future, a burst of non-finite and absurd float drift
values, and a corrupted stretch (unknown ids, wrong lengths, error and remote frames,
garbage payloads). The daemon keeps running, answers the stop command with an ack, and
the replay of its raw log is byte-identical to its live samples.csv."""

from __future__ import annotations

import json
import random
import struct

import can
import yaml

from gyrostand.can.bus import FrameEncoder
from gyrostand.cli import main as cli_main
from gyrostand.config import load_config
from gyrostand.runfolder import raw_segments
from gyrostand.session.offline import simulated_frames

from .procs import DBC, DEMO, Daemon, Observer, RemoteServer, send_paced

SPEED = 40.0  # x real time: 600 s of frame time in ~15 s


def _float_dbc(path):
    """Our DBC with GYRO_DRIFT_1.Drift an IEEE float32 without a range ([0|0]), the layout
    of electronics that send raw floats (and so can send inf and NaN)."""
    text = DBC.read_text().replace(
        ' SG_ Drift : 0|32@1- (1E-005,0) [-1000|1000] "deg/h" GYROSTAND',
        ' SG_ Drift : 0|32@1- (1,0) [0|0] "deg/h" GYROSTAND', 1)
    assert "(1,0) [0|0]" in text
    text += "\nSIG_VALTYPE_ 256 Drift : 1;\n"
    path.write_text(text)
    return path


def _shift(f, t):
    return can.Message(timestamp=t, arbitration_id=f.arbitration_id,
                       is_extended_id=f.is_extended_id, data=bytes(f.data),
                       is_remote_frame=f.is_remote_frame, is_error_frame=f.is_error_frame,
                       dlc=f.dlc)


def test_soak_clock_step_stray_nonfinite_corrupt_stop_and_replay_equals_live(tmp_path):
    srv = RemoteServer().start()
    d = yaml.safe_load(DEMO.read_text())
    d["session"]["output"] = str(tmp_path / "runs")
    d["bus"] = {"interface": "remote", "channel": srv.url, "preserve_timestamps": True}
    d["dbc"] = str(_float_dbc(tmp_path / "float.dbc"))
    d["simulate"].update(duration=600.0, rates={"drift": 20, "temperature": 10})
    cfg_path = tmp_path / "soak.yaml"
    cfg_path.write_text(yaml.safe_dump(d))
    cfg = load_config(cfg_path)
    clean = list(simulated_frames(cfg))
    n = len(clean)
    drift_id = cfg.gyros[0].drift.signal.message.frame_id
    rng = random.Random(7)
    a, b, c, e = n // 5, 2 * n // 5, 3 * n // 5, 4 * n // 5
    frames = clean[:a]
    frames += [_shift(f, f.timestamp - 300.0) for f in clean[a:b]]  # clock steps back
    t = clean[b].timestamp - 300.0
    frames.append(_shift(clean[b], t + 3000.0))  # one stray frame far ahead
    frames += [_shift(f, f.timestamp - 300.0) for f in clean[b + 1:c]]
    t = clean[c].timestamp - 300.0
    bad_values = [float("inf"), float("-inf"), float("nan"), 3e38, -3e38, 1e13] * 10
    frames += [can.Message(timestamp=t + 1e-4 * i, arbitration_id=drift_id,
                           is_extended_id=False, data=struct.pack("<fI", v, i % 256))
               for i, v in enumerate(bad_values)]  # non-finite and absurd floats
    frames += [_shift(f, f.timestamp - 300.0) for f in clean[c:e]]
    t = clean[e].timestamp - 300.0
    junk = []
    for i in range(300):  # a corrupted stretch
        kind = rng.choice(["unknown", "dlc", "error", "remote", "garbage"])
        ts = t + 1e-4 * i
        if kind == "unknown":
            junk.append(can.Message(timestamp=ts, arbitration_id=rng.randrange(0x400, 0x7FF),
                                    is_extended_id=False, data=rng.randbytes(8)))
        elif kind == "dlc":
            junk.append(can.Message(timestamp=ts, arbitration_id=drift_id,
                                    is_extended_id=False, data=rng.randbytes(rng.randrange(8))))
        elif kind == "error":
            junk.append(can.Message(timestamp=ts, is_error_frame=True))
        elif kind == "remote":
            junk.append(can.Message(timestamp=ts, arbitration_id=drift_id,
                                    is_extended_id=False, is_remote_frame=True, dlc=8))
        else:
            junk.append(can.Message(timestamp=ts, arbitration_id=drift_id,
                                    is_extended_id=False,
                                    data=struct.pack("<fI", rng.choice(bad_values), 0)))
    frames += junk
    frames += [_shift(f, f.timestamp - 300.0) for f in clean[e:]]
    stop = FrameEncoder(cfg.db).command_frame(cfg.responses.command, "stop", 7, 255,
                                              timestamp=frames[-1].timestamp + 0.01)

    daemon = Daemon(cfg_path, "--out", str(tmp_path / "runs"))
    obs = stand = None
    try:
        run_dir = daemon.run_dir(daemon.wait_for("ready: "))
        obs = Observer(srv.url)
        stand = can.Bus(interface="remote", channel=srv.url, preserve_timestamps=True)
        assert send_paced(stand, frames, SPEED) == len(frames)
        stand.send(stop)
        rc, err = daemon.finish(120)
    finally:
        daemon.close()
        for x in (obs, stand):
            if x is not None:
                (x.close if isinstance(x, Observer) else x.shutdown)()
        srv.stop()
    assert rc == 0, err[-3000:]
    ack = cfg.db.get_message_by_name("GS_ACK")
    acks = [dict(ack.decode(f.data, decode_choices=False)) for f in obs.frames
            if f.arbitration_id == ack.frame_id]
    assert any(int(x["Sequence"]) == 7 and int(x["Result"]) == 0 for x in acks), acks
    doc = json.loads((run_dir / "result.json").read_text())
    assert doc["stats"]["stop_reason"] == "stop command"
    dec = doc["stats"]["decoder"]
    assert dec["clock_steps"] == 1
    assert dec["rejected"]["time_jump"] == 1  # the stray frame, and nothing else
    assert dec["rejected"]["out_of_range"] >= len(bad_values)
    assert dec["listener_errors"] == 0
    live = (run_dir / "az" / "samples.csv").read_bytes()
    rows = live.decode().splitlines()[1:]
    assert len(rows) >= 590 and all("inf" not in r for r in rows)
    assert doc["gyros"]["az"]["fits"]["ml"].get("parameters"), doc["gyros"]["az"]["fits"]
    # replay of the raw log (every raw file, in order) = live, byte for byte
    segs = raw_segments(run_dir)
    assert [p.name for p in segs] == doc["stats"]["recorder"]["files"]
    assert cli_main(["replay", str(cfg_path), str(run_dir), "--out", str(tmp_path / "rep"),
                     "--reader", "inline"]) == 0
    (rep,) = (tmp_path / "rep").iterdir()
    assert (rep / "az" / "samples.csv").read_bytes() == live
    rdoc = json.loads((rep / "result.json").read_text())
    assert rdoc["stats"]["decoder"]["clock_steps"] == 1
    assert rdoc["stats"]["decoder"]["rejected"] == dec["rejected"]
