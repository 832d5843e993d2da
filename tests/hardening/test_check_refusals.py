"""Exit codes of the third hostile round (issue 28, "Exit codes"), through the command
line: ``run --check`` refuses ``counter: Drift`` (the channel's own signal), two gyros'
results in one frame and a drift signal of scale 0, naming the key (before: all three
passed); ``sampling.dt: 1e0`` is the number it says (before: "expected a number, got
str"); ``fit --remove bias --remove bias`` is refused (before: recorded twice); a full
command queue is counted ``command_overflow``, not as the samples' ``overflow``."""

from __future__ import annotations

import can
import pytest
import yaml

from gyrostand import exitcodes
from gyrostand.can.bus import FrameEncoder
from gyrostand.can.receive.listener import DecodingListener
from gyrostand.can.routes import ChannelMap
from gyrostand.cli import main as cli_main
from gyrostand.config import load_config

from .procs import DBC, write_config


def _check(tmp_path, capsys, edit, dbc_text=None):
    cfg = write_config(tmp_path / "s.yaml", tmp_path / "runs", {"interface": "virtual"})
    d = yaml.safe_load(cfg.read_text())
    if dbc_text is not None:
        (tmp_path / "x.dbc").write_text(dbc_text)
        d["dbc"] = str(tmp_path / "x.dbc")
    edit(d)
    cfg.write_text(yaml.safe_dump(d))
    rc = cli_main(["run", str(cfg), "--check"])
    return rc, capsys.readouterr()


def test_counter_is_the_channels_own_signal(tmp_path, capsys):
    def edit(d):
        d["gyros"][0]["drift"]["counter"] = "Drift"
    rc, out = _check(tmp_path, capsys, edit)
    assert rc == exitcodes.CONFIG
    assert "gyros[0].drift.counter: Drift is the channel's own signal" in out.err


def test_two_gyros_in_one_result_frame(tmp_path, capsys):
    def edit(d):
        g2 = yaml.safe_load(yaml.safe_dump(d["gyros"][0]))
        g2["name"] = "b"
        g2["drift"]["message"], g2["temperature"]["message"] = "GYRO_DRIFT_2", "GYRO_TEMP_2"
        g2["result"] = {"message": "GS_RESULT_1"}
        d["gyros"].append(g2)
    rc, out = _check(tmp_path, capsys, edit)
    assert rc == exitcodes.CONFIG
    assert "gyros[1].result.message: GS_RESULT_1 is already gyros[0].result.message" \
        in out.err


def test_a_drift_signal_of_scale_zero(tmp_path, capsys):
    text = DBC.read_text(encoding="cp1252").replace(
        ' SG_ Drift : 0|32@1- (1E-005,0) [-1000|1000] "deg/h"',
        ' SG_ Drift : 0|32@1- (0,0) [-1000|1000] "deg/h"')
    rc, out = _check(tmp_path, capsys, lambda d: None, text)
    assert rc == exitcodes.CONFIG
    assert "gyros[0].drift.signal: GYRO_DRIFT_1.Drift has scale 0 in the DBC" in out.err


@pytest.mark.parametrize("dt, want", [("1e0", 1.0), ("5E-1", 0.5), ("2", 2.0)])
def test_dt_in_exponent_notation(tmp_path, capsys, dt, want):
    cfg = write_config(tmp_path / "s.yaml", tmp_path / "runs", {"interface": "virtual"})
    d = yaml.safe_load(cfg.read_text())
    d["sampling"].pop("dt", None)
    # written by hand: YAML 1.1 reads 1e0 (no dot) as a string
    cfg.write_text(yaml.safe_dump(d).replace("sampling:\n", f"sampling:\n  dt: {dt}\n", 1))
    assert cli_main(["run", str(cfg), "--check"]) == 0, capsys.readouterr().err
    assert f"sampling: dt {want:g} s" in capsys.readouterr().out
    assert load_config(cfg).sampling.dt == want


def test_fit_with_a_term_twice_is_refused(tmp_path, capsys):
    csv = tmp_path / "s.csv"
    csv.write_text("t,drift,temp\n" + "".join(f"{i}.0,0.1,{20 + 0.01 * i}\n"
                                              for i in range(200)))
    for argv, msg in ((["--remove", "bias", "--remove", "bias"],
                       "--remove bias is given 2 times"),
                      (["--add", "temp", "--remove", "temp"],
                       "temp is both added (--add) and removed (--remove)")):
        assert cli_main(["fit", str(csv), *argv]) == exitcodes.USAGE
        assert f"error: {msg}" in capsys.readouterr().err


def test_a_full_command_queue_is_its_own_count(tmp_path):
    cfg = load_config(write_config(tmp_path / "s.yaml", tmp_path / "runs",
                                   {"interface": "virtual"}))
    lst = DecodingListener(cfg.db, ChannelMap.from_config(cfg), command=cfg.responses.command,
                           command_capacity=4)
    enc = FrameEncoder(cfg.db)
    for i in range(10):
        f = enc.command_frame(cfg.responses.command, "reset", i, 255, timestamp=1.0 + i)
        lst.on_message_received(can.Message(timestamp=f.timestamp,
                                            arbitration_id=f.arbitration_id,
                                            is_extended_id=False, data=f.data))
    st = lst.stats()
    assert st.rejected["command_overflow"] == 6 and st.rejected["overflow"] == 0
    assert st.commands == 4
