"""``gyrostand init`` on real DBCs: a UTF-8 DBC with ``°/h``/``°C`` units, name-only
signals and a board temperature beside the gyro (tests/data/kp3_utf8.dbc), a J1939 DBC
whose messages are marked ``VFrameFormat`` ``J1939PG`` (tests/data/fog2_j1939pg.dbc), and
the bus the scaffold writes (one that exists on this machine)."""

from __future__ import annotations

import json

import can
import cantools
import yaml
from canhelpers import DATA

from gyrostand.can.dbc import text_encoding
from gyrostand.cli import main
from gyrostand.config import load_config

KP3 = DATA / "kp3_utf8.dbc"
FOG2 = DATA / "fog2_j1939pg.dbc"


def _init(tmp_path, dbc, *extra: str):
    out = tmp_path / "stand" / "s.yaml"
    assert main(["init", str(dbc), "-o", str(out), *extra]) == 0
    assert main(["run", str(out), "--check"]) == 0
    return out


def _mapping(cfg) -> dict:
    return {g.name: (g.drift.signal.message.name, g.drift.signal.name,
                     g.drift.counter.name if g.drift.counter else None,
                     g.temperature.signal.message.name, g.temperature.signal.name)
            for g in cfg.gyros}


def test_utf8_dbc_units_names_alone_and_the_case_over_the_board(tmp_path, capsys):
    # the file is UTF-8: cantools' default (cp1252) reads its degree sign as 'Â°'
    assert cantools.database.load_file(str(KP3)).get_message_by_name(
        "GYRO_X").get_signal_by_name("XDrift").unit == "Â°/h"
    assert text_encoding(KP3) == "utf-8" and text_encoding(DATA / "fog1a_j1939.dbc") == \
        "cp1252"
    out = _init(tmp_path, KP3)
    printed = capsys.readouterr().out
    assert "      XDrift               °/h            rate        <- drift of x" in printed
    cfg = load_config(out)
    assert _mapping(cfg) == {
        # the case temperature wins over the board temperature of the drift's own frame
        "x": ("GYRO_X", "XDrift", "XCnt", "GYRO_X_CASE", "CaseTemp"),
        # no unit: proposed by name alone; YStatus (a status word) is no measurement
        "y": ("GYRO_Y", "YawRate", "YCounter", "GYRO_Y", "Y_Temperature"),
        "z": ("IMU_Z", "GyroRate", "ZSeq", "IMU_Z", "ZTemp"),
    }
    x = cfg.gyro("x")
    assert (x.drift.signal.unit, x.temperature.signal.unit) == ("°/h", "°C")
    text = out.read_text(encoding="utf-8")
    assert "# CHECK: GYRO_Y.YawRate has no rate unit (''): proposed by name" in text
    assert "# CHECK: IMU_Z.ZTemp has no temperature unit (''): proposed by name" in text
    # the merged DBC keeps the user's encoding: UTF-8, every degree sign intact
    merged = out.with_name("s+gyrostand.dbc").read_bytes()
    assert '"°/h"'.encode() in merged and "Kreiselprüfstand".encode() in merged
    assert cfg.db.get_message_by_name("GS_SUMMARY_1").get_signal_by_name(
        "ResidualRms").unit == "°/h"


def _fog2_frames(sa: int, seconds: int = 40) -> list[can.Message]:
    """FOG-2's two parameter groups at 10 Hz from source address ``sa`` (the DBC's is
    0x80) and priorities 3 and 6, encoded by cantools from the DBC."""
    db = cantools.database.load_file(str(FOG2))
    rate, temp = db.get_message_by_name("FOG2_RATE"), db.get_message_by_name("FOG2_TEMP")
    out = []
    for k in range(seconds * 10):
        t = 100.0 + k / 10
        out.append(can.Message(timestamp=t, arbitration_id=(rate.frame_id & ~0xFF) | sa,
                               is_extended_id=True, data=rate.encode(
                                   {"AngularRate": 0.5 + 0.01 * (k % 7),
                                    "RateCounter": k % 16})))
        out.append(can.Message(timestamp=t + 0.05, arbitration_id=(temp.frame_id & ~0xFF)
                               | sa, is_extended_id=True,
                               data=temp.encode({"FogTemp": 20 + k / 100})))
    return out


def test_j1939pg_messages_are_matched_by_pgn_from_any_source_address(tmp_path, capsys):
    assert cantools.database.load_file(str(FOG2)).get_message_by_name(
        "FOG2_RATE").protocol == "j1939"
    out = _init(tmp_path, FOG2)
    d = yaml.safe_load(out.read_text())
    (g,) = d["gyros"]
    assert g["drift"] == {"message": "FOG2_RATE", "signal": "AngularRate",
                          "counter": "RateCounter", "match": "pgn"}
    assert g["temperature"] == {"message": "FOG2_TEMP", "signal": "FogTemp", "match": "pgn"}
    assert "    drift        FOG2_RATE (0xCFF2180, extended).AngularRate [deg/h], counter " \
        "RateCounter, matched by J1939 PGN" in capsys.readouterr().out
    # another FOG-2 at source address 0x81: every frame decodes, 40 full bins
    log = tmp_path / "fog2-sa81.blf"
    frames = _fog2_frames(0x81)
    with can.Logger(str(log)) as w:
        for f in frames:
            w.on_message_received(f)
    assert main(["replay", str(out), str(log), "--out", str(tmp_path / "r")]) == 0
    (run_dir,) = (tmp_path / "r").iterdir()
    doc = json.loads((run_dir / "result.json").read_text())
    assert doc["stats"]["decoder"]["decoded"] == len(frames) == 800
    assert doc["stats"]["decoder"]["rejected_total"] == 0
    assert doc["gyros"][g["name"]]["bins"] == 40


def test_the_scaffold_writes_a_bus_that_exists_here(tmp_path, monkeypatch):
    from gyrostand.can import busconfig

    cfg = load_config(_init(tmp_path, KP3, "--listen-only"))
    if busconfig.socketcan_available("can0"):
        assert dict(cfg.bus) == {"interface": "socketcan", "channel": "can0"}
    else:  # SocketCAN absent: python-can's virtual bus, and how to switch
        assert dict(cfg.bus) == {"interface": "virtual", "channel": "kp3_utf8",
                                 "preserve_timestamps": True}  # the demo's frame times
        text = cfg.path.read_text(encoding="utf-8")
        assert "# SocketCAN is absent here (no AF_CAN socket or no can0)" in text
        assert "run with -i socketcan -c can0" in text
    with can.Bus(**cfg.bus):  # it opens
        pass
    monkeypatch.setattr(busconfig, "socketcan_available", lambda channel="can0": True)
    cfg = load_config(_init(tmp_path / "sc", KP3, "--listen-only"))
    assert dict(cfg.bus) == {"interface": "socketcan", "channel": "can0"}
    assert "  # SocketCAN's can0 (found here); -i/-c/-b override it\n" in \
        cfg.path.read_text(encoding="utf-8")
