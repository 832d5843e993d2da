"""J1939 devices: frames matched by PGN (``match: pgn``) whatever their priority and source
address; matched by full id they are counted unknown and the log says why once. Plus the
config errors of item 7 of #14 and a temperature shared by several gyros."""

from __future__ import annotations

import logging
import time
from pathlib import Path

import can
import cantools
import pytest

from gyrostand.can.dbc import j1939_pgn
from gyrostand.can.receive.listener import DecodingListener
from gyrostand.can.routes import ChannelMap
from gyrostand.config import parse_config
from gyrostand.errors import ConfigError

DATA = Path(__file__).resolve().parents[1] / "data"
FOG = DATA / "fog1a_j1939.dbc"


def _cfg(match: str | None = None, per_channel: str | None = None, **extra):
    ch = {} if per_channel is None else {"match": per_channel}
    d = {"session": {"name": "fog"}, "bus": {"interface": "virtual"}, "dbc": str(FOG),
         "gyros": [{"name": "fog",
                    "drift": {"message": "FOG_RATE", "signal": "Angular_Rate",
                              "counter": "Rolling_Counter", **ch},
                    "temperature": {"message": "FOG_HOUSEKEEPING",
                                    "signal": "Sensor_Temperature", **ch},
                    "model": ["markov", "temp"]}], **extra}
    if match is not None:
        d["match"] = match
    return parse_config(d, source="fog.yaml", base_dir=DATA)


def test_pgn_agrees_with_cantools_j1939():
    for fid in (0x0CFFED00, 0x18FEF000, 0x0CFFED42, 0x18EA00FE, 0x1CEBFF80, 0x00F00417,
                0x18DA10F1, 0x1FFFFFFF, 0):
        assert j1939_pgn(fid) == cantools.j1939.pgn_from_frame_id(fid), hex(fid)


def _send(frames, cfg):
    """Frames from another source address (0x42) and priority 6, through a real virtual
    bus into the listener; returns the listener."""
    listener = DecodingListener(cfg.db, ChannelMap.from_config(cfg))
    chan = f"j1939-{time.monotonic_ns()}"
    rx = can.Bus(interface="virtual", channel=chan, receive_own_messages=False)
    tx = can.Bus(interface="virtual", channel=chan)
    notifier = can.Notifier(rx, [listener])
    try:
        for m in frames:
            tx.send(m)
        deadline = time.monotonic() + 5
        while listener.stats().received < len(frames) and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        notifier.stop()
        tx.shutdown()
        rx.shutdown()
    return listener


def _frames(db):
    rate = db.get_message_by_name("FOG_RATE")
    hk = db.get_message_by_name("FOG_HOUSEKEEPING")
    out = []
    for k in range(20):
        for msg, values in ((rate, {"Angular_Rate": 0.01 * k, "Rate_Status": 0,
                                    "Rolling_Counter": k % 16}),
                            (hk, {"Sensor_Temperature": 25.0 + k / 8, "Light_Source_Current": 1,
                                  "HK_Counter": k})):
            fid = (msg.frame_id & ~0xFF & ~(0x7 << 26)) | (6 << 26) | 0x42  # prio 6, SA 0x42
            out.append(can.Message(timestamp=100.0 + 0.1 * k, arbitration_id=fid,
                                   is_extended_id=True, data=msg.encode(values)))
    return out


def test_frames_from_another_source_address_decode_with_match_pgn():
    cfg = _cfg("pgn")
    assert all(c.match == "pgn" for c in (cfg.gyros[0].drift, cfg.gyros[0].temperature))
    listener = _send(_frames(cfg.db), cfg)
    st = listener.stats()
    assert st.received == 40 and st.rejected_total == 0, st
    samples = listener.drain()
    drift = [v for _, c, _, v in samples if c == 0]
    temp = [v for _, c, _, v in samples if c == 1]
    assert drift == pytest.approx([0.01 * k for k in range(20)], abs=1e-4)
    assert temp == pytest.approx([25.0 + k / 8 for k in range(20)], abs=0.008)


def test_per_channel_match_equals_the_session_default():
    assert _cfg(per_channel="pgn").gyros[0].drift.match == "pgn"
    assert _cfg().gyros[0].drift.match == "id"


def test_matched_by_id_they_are_unknown_and_the_log_says_why_once(caplog):
    cfg = _cfg()
    with caplog.at_level(logging.WARNING, logger="gyrostand.can.receive.state"):
        listener = _send(_frames(cfg.db), cfg)
    st = listener.stats()
    assert st.decoded == 0 and st.rejected["unknown_id"] == 40
    hints = [r.getMessage() for r in caplog.records if "match: pgn" in r.getMessage()]
    assert len(hints) == 2, hints  # once per id: the rate and the housekeeping frames
    assert any("FOG_RATE" in h and "0x18FFED42" in h for h in hints)


def test_config_errors_name_the_key():
    with pytest.raises(ConfigError, match=r"gyros\[0\]\.drift\.match.*'sa' is not one of"):
        _cfg(per_channel="sa")
    with pytest.raises(ConfigError, match=r"match.*'pgn ' is not one of"):
        _cfg("pgn ")


def test_pgn_match_refused_for_a_standard_id(tmp_path):
    d = {"session": {"name": "x"}, "bus": {"interface": "virtual"}, "dbc": str(FOG),
         "gyros": [{"name": "g", "drift": {"message": "ECU_DIAG", "signal": "Dtc_Count",
                                           "match": "pgn"},
                    "temperature": {"message": "FOG_HOUSEKEEPING",
                                    "signal": "Sensor_Temperature"},
                    "model": ["markov"]}]}
    with pytest.raises(ConfigError, match=r"gyros\[0\]\.drift\.match.*needs a 29-bit"):
        parse_config(d, source="x.yaml", base_dir=DATA)


MULTI = """VERSION ""
BO_ 291 LONG_RATE: 16 IMU
 SG_ Rate : 0|32@1- (1e-05,0) [-1000|1000] "deg/h" X
 SG_ Temp : 64|16@1- (0.01,0) [-60|150] "degC" X
"""


def test_a_signal_in_a_multi_frame_message_is_a_config_error(tmp_path):
    (tmp_path / "long.dbc").write_text(MULTI)
    d = {"session": {"name": "x"}, "bus": {"interface": "virtual"}, "dbc": "long.dbc",
         "gyros": [{"name": "g", "drift": {"message": "LONG_RATE", "signal": "Rate"},
                    "temperature": {"message": "LONG_RATE", "signal": "Temp"},
                    "model": ["markov"]}]}
    with pytest.raises(ConfigError, match=r"gyros\[0\]\.drift\.message.*16 bytes: classic "
                                          r"CAN carries at most 8"):
        parse_config(d, source="x.yaml", base_dir=tmp_path)


def test_one_temperature_sensor_serves_several_gyros_but_a_drift_only_one():
    base = {"session": {"name": "x"}, "bus": {"interface": "virtual"},
            "dbc": str(DATA / "imu3f_fd.dbc")}
    db = cantools.database.load_file(str(DATA / "imu3f_fd.dbc"))
    rates = [s.name for s in db.get_message_by_name("IMU_RATES").signals][:3]
    temp = db.get_message_by_name("IMU_TEMPS").signals[0].name
    gyros = [{"name": f"g{i}", "drift": {"message": "IMU_RATES", "signal": r},
              "temperature": {"message": "IMU_TEMPS", "signal": temp},
              "model": ["markov", "temp"]} for i, r in enumerate(rates)]
    cfg = parse_config({**base, "gyros": gyros}, source="x.yaml", base_dir=DATA)
    assert len({g.temperature.signal for g in cfg.gyros}) == 1
    gyros[1]["drift"] = dict(gyros[0]["drift"])
    with pytest.raises(ConfigError, match=r"gyros\[1\]\.drift\.signal.*already mapped by "
                                          r"gyros\[0\]\.drift"):
        parse_config({**base, "gyros": gyros}, source="x.yaml", base_dir=DATA)
    gyros[1]["drift"] = {"message": "IMU_TEMPS", "signal": temp}  # a temperature in K
    with pytest.raises(ConfigError, match=r"gyros\[1\]\.drift\.signal: IMU_TEMPS.TempX_K: "
                                          r"unit 'K' is not an angular rate"):
        parse_config({**base, "gyros": gyros}, source="x.yaml", base_dir=DATA)
    gyros[1]["drift"] = {"message": "IMU_TEMPS", "signal": temp, "unit": "rad/s"}
    with pytest.raises(ConfigError, match=r"gyros\[1\]\.drift\.signal.*already mapped"):
        parse_config({**base, "gyros": gyros}, source="x.yaml", base_dir=DATA)
    # and the listener gives each of the three gyros the shared sensor's reading
    gyros[1]["drift"] = {"message": "IMU_RATES", "signal": rates[1]}
    cfg = parse_config({**base, "gyros": gyros}, source="x.yaml", base_dir=DATA)
    msg = cfg.db.get_message_by_name("IMU_TEMPS")
    values = {s.name: (s.minimum or 0) + 1 for s in msg.signals}
    values[temp] = 304.65  # K
    frames = [can.Message(timestamp=10.0 + k, arbitration_id=msg.frame_id, is_fd=msg.is_fd,
                          is_extended_id=msg.is_extended_frame, data=msg.encode(values))
              for k in range(3)]
    samples = _send(frames, cfg).drain()
    assert sorted((g, c) for g, c, _, _ in samples) == sorted([(0, 1), (1, 1), (2, 1)] * 3)
    assert all(abs(v - 31.5) < 0.05 for *_, v in samples)  # K converted to degC
