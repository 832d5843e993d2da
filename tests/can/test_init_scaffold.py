"""``gyrostand init DBC``: on every DBC of the tests (ours, the foreign layout, a CAN FD
IMU in rad/s and K, a J1939-style single-axis FOG in °/s and °C) it writes a session file
that ``run --check`` accepts, and the proposed mapping is the right one; the daemon's
frames come from the DBC, from dbc/gyrostand.dbc, or a chosen id range."""

from __future__ import annotations

from pathlib import Path

import cantools
import pytest
from canhelpers import DATA, ROOT

from gyrostand import exitcodes
from gyrostand.can.survey import unit_kind
from gyrostand.cli import main
from gyrostand.config import GyroConfig, load_config

OWN = ROOT / "dbc" / "gyrostand.dbc"


def mapping(g: GyroConfig) -> tuple:
    """(drift message key, signal, counter, temperature message key, signal, counter)."""
    d, t = g.drift, g.temperature
    return (d.signal.message.key, d.signal.name, d.counter.name if d.counter else None,
            t.signal.message.key, t.signal.name, t.counter.name if t.counter else None)


def _init(tmp_path: Path, dbc: Path, *extra: str) -> Path:
    out = tmp_path / "stand" / "session.yaml"
    assert main(["init", str(dbc), "-o", str(out), *extra]) == 0
    assert main(["run", str(out), "--check"]) == 0
    return out


def test_ours(tmp_path, capsys):
    cfg = load_config(_init(tmp_path, OWN))
    printed = capsys.readouterr().out
    assert "<- drift of gyro1" in printed and "valid session 'gyrostand'" in printed
    assert cfg.dbc_path == OWN.resolve()  # our DBC carries the daemon's frames: no copy
    assert not list((tmp_path / "stand").glob("*.dbc"))
    assert {g.name: mapping(g) for g in cfg.gyros} == {
        f"gyro{i}": (0x100 + i - 1, "Drift", "Counter", 0x110 + i - 1, "Temperature",
                     "Counter") for i in (1, 2, 3)}
    for i, g in enumerate(cfg.gyros, start=1):
        assert g.result is not None and g.result.values.name == f"GS_RESULT_{i}"
        assert g.result.summary is not None and g.result.summary.name == f"GS_SUMMARY_{i}"
    r = cfg.responses
    assert (r.status.name, r.ack.name, r.command.name) == ("GS_STATUS", "GS_ACK",
                                                           "GS_COMMAND")


def test_foreign_layout_matches_the_hand_written_session(tmp_path):
    """tests/data/foreign.yaml maps the foreign DBC by hand; init proposes the same."""
    cfg = load_config(_init(tmp_path, DATA / "foreign.dbc"))
    hand = load_config(DATA / "foreign.yaml")
    assert {g.name: mapping(g) for g in cfg.gyros} == \
        {g.name: mapping(g) for g in hand.gyros}
    # the daemon's frames were added at our ids into a DBC beside the session; the
    # foreign messages in it are unchanged
    assert cfg.dbc_path == tmp_path / "stand" / "session+gyrostand.dbc"
    src = cantools.database.load_file(str(DATA / "foreign.dbc"))
    for m in src.messages:
        got = cfg.db.get_message_by_name(m.name)
        assert (got.frame_id, got.is_extended_frame, got.length) == \
            (m.frame_id, m.is_extended_frame, m.length)
        assert sorted((s.name, s.start, s.length, s.byte_order, s.scale, s.offset,
                       s.multiplexer_ids or []) for s in got.signals) == \
            sorted((s.name, s.start, s.length, s.byte_order, s.scale, s.offset,
                    s.multiplexer_ids or []) for s in m.signals)
    assert cfg.responses.command.frame_id == 0x0F0 and cfg.responses.status.frame_id == 0x500
    assert [g.result.values.frame_id for g in cfg.gyros] == [0x300, 0x301]
    summary = cfg.db.get_message_by_name("GS_SUMMARY_1")
    assert summary.get_signal_by_name("ResidualRms").unit == "deg/h"


def test_can_fd_imu_in_rad_per_s_and_kelvin(tmp_path):
    """Three axes in one CAN FD frame (float32 rad/s), three temperatures in K in
    another, a board temperature in °C that is not the gyros'."""
    cfg = load_config(_init(tmp_path, DATA / "imu3f_fd.dbc", "-i", "socketcan", "-c",
                            "can1", "--fd", "-b", "1000000", "--data-bitrate", "5000000"))
    assert {g.name: mapping(g) for g in cfg.gyros} == {
        a: (0x200, f"Rate{a.upper()}", "RatesAlive", 0x201, f"Temp{a.upper()}_K",
            "TempsAlive") for a in "xyz"}
    assert dict(cfg.bus) == {"interface": "socketcan", "channel": "can1", "fd": True,
                             "bitrate": 1000000, "data_bitrate": 5000000}
    assert cfg.db.get_message_by_name("IMU_RATES").is_fd
    assert cfg.db.get_message_by_name("GS_SUMMARY_3").get_signal_by_name(
        "ResidualRms").unit == "rad/s"


def test_j1939_fog_with_a_clashing_id_needs_an_id_range(tmp_path, capsys):
    dbc = DATA / "fog1a_j1939.dbc"
    assert main(["init", str(dbc), "-o", str(tmp_path / "a.yaml")]) == exitcodes.CONFIG
    err = capsys.readouterr().err
    assert "GS_RESULT_1 would take standard id 0x300, which is ECU_DIAG" in err
    assert "--id-base" in err and not (tmp_path / "a.yaml").exists()
    cfg = load_config(_init(tmp_path, dbc, "--id-base", "0x700"))
    (g,) = cfg.gyros
    assert mapping(g) == (0xCFFED00 | 1 << 29, "Angular_Rate", "Rolling_Counter",
                          0xCFFEE00 | 1 << 29, "Sensor_Temperature", "HK_Counter")
    assert g.drift.signal.unit == "°/s" and g.temperature.signal.unit == "°C"
    ids = {cfg.responses.command.frame_id, cfg.responses.ack.frame_id,
           cfg.responses.status.frame_id, g.result.values.frame_id,
           g.result.summary.frame_id}
    assert ids == set(range(0x700, 0x705))


def test_listen_only_and_refusals(tmp_path, capsys):
    out = tmp_path / "s.yaml"
    assert main(["init", str(DATA / "foreign.dbc"), "-o", str(out), "--listen-only"]) == 0
    cfg = load_config(out)
    assert cfg.responses.status is None and cfg.responses.command is None
    assert all(g.result is None for g in cfg.gyros)
    assert cfg.dbc_path == (DATA / "foreign.dbc").resolve()
    capsys.readouterr()
    assert main(["init", str(DATA / "foreign.dbc"), "-o", str(out)]) == exitcodes.CANTCREAT
    assert "exists; pass --force" in capsys.readouterr().err
    nogyro = tmp_path / "body.dbc"
    nogyro.write_text('VERSION ""\n\nNS_ :\n\nBS_:\n\nBU_: ECU\n\n'
                      'BO_ 291 SPEED: 8 ECU\n SG_ Speed : 0|16@1+ (0.01,0) [0|300] "km/h" ECU\n')
    assert main(["init", str(nogyro), "-o", str(tmp_path / "b.yaml")]) == exitcodes.CONFIG
    assert "no signal looks like a gyro drift rate" in capsys.readouterr().err


def test_run_check_does_not_open_the_bus_and_names_errors(tmp_path, capsys):
    out = _init(tmp_path, DATA / "foreign.dbc", "-i", "remote", "-c", "ws://127.0.0.1:9/")
    capsys.readouterr()
    assert main(["run", str(out), "--check"]) == 0  # nothing listens on port 9
    assert "    interface = 'remote'  (session file)\n" in capsys.readouterr().out
    out.write_text(out.read_text().replace("signal: YRate,", "signal: YRat,"))
    assert main(["run", str(out), "--check"]) == exitcodes.CONFIG
    assert "gyros[1].drift.signal: 'YRat' is not a signal of message IMU_Y_RATE" in \
        capsys.readouterr().err


@pytest.mark.parametrize("unit, kind", [("deg/h", "rate"), ("°/h", "rate"), ("dps", "rate"),
                                        ("rad/s", "rate"), ("mrad/s", "rate"),
                                        ("deg/sec", "rate"), ("degC", "temperature"),
                                        ("°C", "temperature"), ("degK", "temperature"),
                                        ("K", "temperature"), ("km/h", None), ("V", None),
                                        ("", None), ("deg", None)])
def test_unit_kinds(unit, kind):
    assert unit_kind(unit) == kind


@pytest.mark.parametrize("dbc, extra, temps, gamma", [
    (OWN, [], (20, 45, 35), -0.001),
    (DATA / "foreign.dbc", [], (20, 45, 35), -0.001),
    (DATA / "imu3f_fd.dbc", [], (20, 45, 35), -0.001),  # K in the DBC: binned in degC
    (DATA / "fog1a_j1939.dbc", ["--id-base", "0x700"], (20, 45, 35), -0.001),
])
def test_an_initialised_session_runs_end_to_end(tmp_path, dbc, extra, temps, gamma):
    """The written session plus a simulate: section: the stand simulator encodes frames
    with the (merged) DBC, the replay decodes every one into full bins for every gyro,
    and the daemon's own result and status frames are built from it."""
    import json

    import yaml

    from gyrostand.session.offline import run_replay, simulated_frames

    out = tmp_path / "s.yaml"
    assert main(["init", str(dbc), "-o", str(out), *extra]) == 0
    d = yaml.safe_load(out.read_text())
    names = [g["name"] for g in d["gyros"]]
    d["simulate"] = {
        "seed": 1, "duration": 300, "rates": {"drift": 20, "temperature": 10},
        "temperature": [[0, temps[0]], [100, temps[1]], [300, temps[2]]],
        "gyros": {n: {"model": ["markov", "temp", "white"],
                      "params": {"markov.beta": 0.0333, "markov.sigma": 0.01,
                                 "temp.gamma": gamma, "white.sigma": 0.0}} for n in names}}
    out.write_text(yaml.safe_dump(d))
    cfg = load_config(out)
    outcome = run_replay(cfg, list(simulated_frames(cfg)), out=tmp_path / "runs")
    doc = json.loads(outcome.result_json.read_text())
    assert doc["stats"]["decoder"]["rejected_total"] == 0
    assert doc["stats"]["responses"]["result_rounds"] >= 10
    assert doc["stats"]["responses"]["frames_sent"] > 0
    for g in names:
        got = doc["gyros"][g]
        assert (got["bins"], got["gaps"]) == (301, 0), g
        # in degC, also from a DBC in K (converted both ways: simulator and decoder)
        est = got["fits"]["ml"]["parameters"]["temp.gamma"]["value"]
        assert est == pytest.approx(gamma, rel=0.10), g


ONE_SENSOR = """VERSION ""
BO_ 2566869249 TRIAD_RATES: 8 IMU
 SG_ RateX : 0|21@1- (0.001,0) [-1000|1000] "deg/h" X
 SG_ RateY : 21|21@1- (0.001,0) [-1000|1000] "deg/h" X
 SG_ RateZ : 42|21@1- (0.001,0) [-1000|1000] "deg/h" X
BO_ 2566869250 BOARD: 4 IMU
 SG_ BoardTemp : 0|16@1- (0.01,0) [-60|150] "degC" X
"""


def test_one_temperature_sensor_for_three_gyros(tmp_path, capsys):
    """A triad with one board sensor: every axis is proposed with it (a session may map
    one temperature signal to several gyros), none left out, and the file validates."""
    dbc = tmp_path / "triad.dbc"
    dbc.write_text(ONE_SENSOR)
    cfg = load_config(_init(tmp_path, dbc))
    assert [g.drift.signal.name for g in cfg.gyros] == ["RateX", "RateY", "RateZ"]
    assert {g.temperature.signal.name for g in cfg.gyros} == {"BoardTemp"}
    text = (tmp_path / "stand" / "session.yaml").read_text()
    assert "left out" not in text and text.count("shares BOARD") == 2
