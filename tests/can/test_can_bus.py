"""Bus opening and the daemon's frames: encoded by DBC name, read back from a real bus."""

from __future__ import annotations

import math

import can
import numpy as np
import pytest

from gyrostand.can.bus import FrameEncoder, model_terms_mask, open_bus
from gyrostand.errors import CanEdgeError


def test_open_bus_wraps_errors():
    with pytest.raises(CanEdgeError, match=r"interface='nosuchdriver' channel='x'"):
        open_bus({"interface": "nosuchdriver", "channel": "x"})
    bus = open_bus({"interface": "virtual", "channel": "gyrostand-open-test"})
    bus.shutdown()


def test_result_and_summary_frames_round_trip_over_the_bus(demo_cfg):
    db = demo_cfg.db
    tx = open_bus({"interface": "virtual", "channel": "gyrostand-resp"})
    rx = open_bus({"interface": "virtual", "channel": "gyrostand-resp"})
    try:
        enc = FrameEncoder(db, tx)
        values, stds = [0.0333, -0.001, 0.1], [0.004, 1.5e-4, 0.01]
        frames = enc.result_frames("GS_RESULT_1", "lsq", values, stds, counter=258)
        frames.append(enc.summary_frame("GS_SUMMARY_1", "lsq", "ok", ["markov", "temp", "bias"],
                                        2000, 0.01234))
        enc.send(frames)
        got = [rx.recv(1.0) for _ in frames]
    finally:
        tx.shutdown()
        rx.shutdown()
    msg = db.get_message_by_name("GS_RESULT_1")
    dec = [msg.decode(f.data, decode_choices=False) for f in got[:-1]]
    assert [(d["Kind"], d["Param"], d["Identifier"], d["NParams"], d["Counter"]) for d in dec] \
        == [(k, i, 1, 3, 2) for i in range(3) for k in (0, 1)]
    f32 = [float(np.float32(x)) for x in values + stds]
    assert [d["Value"] for d in dec[0::2]] + [d["Std"] for d in dec[1::2]] == f32
    summ = db.get_message_by_name("GS_SUMMARY_1").decode(got[-1].data, decode_choices=False)
    assert summ["ModelTerms"] == 0b1011 == model_terms_mask(["markov", "temp", "bias"])
    assert summ["Samples"] == 2000 and summ["ResidualRms"] == pytest.approx(0.01234, abs=1e-5)


def test_status_ack_command_and_saturation(demo_cfg):
    db = demo_cfg.db
    enc = FrameEncoder(db)
    pages = enc.status_frames("GS_STATUS", "running", counter=17, bins=2**24 + 5, gaps=3,
                              decoded=123456, rejected=7, bus_errors=1, late=2)
    st = db.get_message_by_name("GS_STATUS")
    dec = [st.decode(p.data, decode_choices=False) for p in pages]
    assert dec[0] == {"Page": 0, "Counter": 1, "State": 1, "Bins": 5, "Gaps": 3}
    assert dec[1] == {"Page": 1, "Counter": 1, "FramesDecoded": 123456, "FramesRejected": 7}
    assert dec[2] == {"Page": 2, "Counter": 1, "BusErrors": 1, "LateFrames": 2, "Outages": 0}
    ack = enc.ack_frame("GS_ACK", command=2, sequence=9, ok=False, reason="wrong_state", node=3)
    assert db.get_message_by_name("GS_ACK").decode(ack.data, decode_choices=False) == \
        {"Command": 2, "Sequence": 9, "Result": 1, "Reason": 2, "Node": 3}
    # saturation at the DBC range; NaN kept in float signals
    s = enc.summary_frame("GS_SUMMARY_1", "ml", "warning", ["markov"], 5_000_000, 99.0)
    d = db.get_message_by_name("GS_SUMMARY_1").decode(s.data, decode_choices=False)
    assert d["Samples"] == 1048575 and d["ResidualRms"] == pytest.approx(10.48575)
    (v, _) = enc.result_frames("GS_RESULT_1", "lkf", [math.nan], [1.0], counter=0)
    assert math.isnan(db.get_message_by_name("GS_RESULT_1").decode(v.data)["Value"])
    with pytest.raises(CanEdgeError, match=r"GS_ACK has no signal\(s\) \['Bogus'\]"):
        enc.encode("GS_ACK", {"Bogus": 1})
    with pytest.raises(CanEdgeError, match="no bus"):
        enc.send(ack)
    assert isinstance(enc.command_frame("GS_COMMAND", "snapshot", 1), can.Message)
