"""A replay or run that decodes nothing exits non-zero with one line saying why: frames
none of which is a mapped message are bad input (2), naming the ids seen most often; a
live run that received no frame at all is a fault (1). The run folder is kept."""

from __future__ import annotations

import json
import os
import re
import threading
import time
from pathlib import Path

import can
import pytest
import yaml

from gyrostand import exitcodes
from gyrostand.cli import main

DATA = Path(__file__).resolve().parents[1] / "data"
MAPPED = ("the mapped messages are IMU_X_MUX 0x18FF5001, IMU_Y_RATE 0x18FF5102, "
          "IMU_Y_TEMP 0x321")


def _session(tmp_path: Path, channel: str = "unused") -> Path:
    d = yaml.safe_load((DATA / "foreign.yaml").read_text())
    d["bus"] = {"interface": "virtual", "channel": channel}
    d["dbc"] = str(DATA / "foreign.dbc")
    d["session"]["output"] = str(tmp_path / "runs")
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


def _strangers(i: int) -> can.Message:
    """Frame i of a stand the session does not describe: 0x123 twice as often as 0x456,
    and every 61st an extended 0x18FEF100."""
    if i % 61 == 60:
        return can.Message(timestamp=1000 + i * 0.01, arbitration_id=0x18FEF100,
                           is_extended_id=True, data=bytes(8))
    return can.Message(timestamp=1000 + i * 0.01, arbitration_id=0x456 if i % 3 == 2 else
                       0x123, is_extended_id=False, data=bytes(8))


@pytest.mark.parametrize("extra", [[], ["--per-frame"]])
def test_a_replay_that_decodes_nothing_is_bad_input_naming_the_ids_seen(tmp_path, capsys,
                                                                        extra, monkeypatch):
    monkeypatch.setenv("GYROSTAND_PER_FRAME", "0")  # restored after (--per-frame sets it)
    log = tmp_path / "other-stand.blf"
    with can.Logger(str(log)) as w:
        for i in range(3050):
            w.on_message_received(_strangers(i))
    path = _session(tmp_path)
    assert main(["replay", str(path), str(log), "--out", str(tmp_path / "r"), *extra]) == \
        exitcodes.DATAERR
    err = capsys.readouterr().err.splitlines()
    (run_dir,) = (tmp_path / "r").iterdir()
    # 3050 frames: 50 extended; of the other 3000, 1000 are 0x456
    assert err[-1] == ("error: replay decoded none of 3,050 frames (unknown_id 3,050); "
                       f"{MAPPED}; ids seen most: 0x123 (2,000 frames), 0x456 (1,000 frames),"
                       f" 0x18FEF100 (50 frames); the run folder is kept: {run_dir}")
    doc = json.loads((run_dir / "result.json").read_text())  # the folder's files are kept
    assert doc["stats"]["decoder"]["unknown_ids"] == {"0x123": 2000, "0x456": 1000,
                                                      "0x18FEF100": 50}
    assert (run_dir / "report.txt").is_file() and (run_dir / "x" / "samples.csv").is_file()


def test_a_replay_of_an_empty_log_is_bad_input(tmp_path, capsys):
    log = tmp_path / "empty.blf"
    with can.Logger(str(log)):
        pass
    assert main(["replay", str(_session(tmp_path)), str(log), "--out",
                 str(tmp_path / "r")]) == exitcodes.DATAERR
    (run_dir,) = (tmp_path / "r").iterdir()
    assert capsys.readouterr().err.splitlines()[-1] == (
        f"error: replay: no CAN frame in the log, nothing measured; the run folder is kept: "
        f"{run_dir}")


def test_a_run_on_a_bus_of_strangers_is_bad_input_and_a_silent_bus_a_fault(tmp_path,
                                                                          capsys):
    channel = f"strangers-{os.getpid()}"
    path = _session(tmp_path, channel)
    stop = threading.Event()

    def stand() -> None:  # sends until the daemon is done (it listens after start-up)
        with can.Bus(interface="virtual", channel=channel) as bus:
            i = 0
            while not stop.is_set():
                bus.send(_strangers(i % 60))  # standard ids only: 0x123 and 0x456
                i += 1
                time.sleep(0.002)

    t = threading.Thread(target=stand, daemon=True)
    t.start()
    try:
        rc = main(["run", str(path), "--duration", "0.5", "--out", str(tmp_path / "a")])
    finally:
        stop.set()
        t.join(5)
    err = capsys.readouterr().err.splitlines()[-1]
    (run_dir,) = (tmp_path / "a").iterdir()
    assert rc == exitcodes.DATAERR, err
    assert re.fullmatch(r"error: run decoded none of ([\d,]+) frames \(unknown_id \1\); "
                        + re.escape(MAPPED) + r"; ids seen most: 0x123 \([\d,]+ frames\), "
                        r"0x456 \([\d,]+ frames\); the run folder is kept: "
                        + re.escape(str(run_dir)), err), err
    doc = json.loads((run_dir / "result.json").read_text())
    dec = doc["stats"]["decoder"]
    assert dec["decoded"] == 0 and dec["received"] == sum(dec["unknown_ids"].values()) > 0
    assert set(dec["unknown_ids"]) == {"0x123", "0x456"}
    # nobody on the bus: nothing received, a fault
    silent = _session(tmp_path, f"silent-{os.getpid()}")
    assert main(["run", str(silent), "--duration", "0.2", "--out", str(tmp_path / "b")]) == \
        exitcodes.UNAVAILABLE
    (run_dir,) = (tmp_path / "b").iterdir()
    assert capsys.readouterr().err.splitlines()[-1] == (
        f"error: run: no CAN frame received on the bus, nothing measured; the run folder "
        f"is kept: {run_dir}")
