"""Absurd limits are refused, not computed (issue 28, finding 11), through the command
line: ``design --t-min=-1e308 --t-max=1e308`` is exit 64 naming the option (before:
``time_s=inf``, every std inf, exit 0); a simulated temperature profile beyond the DBC
signal's range is exit 78 naming the breakpoint (before: a 200 °C profile saturated at
150 °C without a word), and any value the simulator must saturate is logged."""

from __future__ import annotations

import pytest
import yaml

from gyrostand import exitcodes
from gyrostand.cli import main as cli_main

from .procs import write_config

MODEL = ["--model", "markov,temp", "--param", "markov.beta=0.03", "--param",
         "markov.sigma=0.1", "--param", "temp.gamma=-0.001", "--hours", "1"]


@pytest.mark.parametrize("args, msg", [
    (["--t-min=-1e308", "--t-max=1e308"],
     "--t-min -1e+308: a chamber temperature is between -273.15 and 1000 °C"),
    (["--t-min=0", "--t-max=inf"], "--t-max inf: a chamber temperature is between"),
    (["--t-min=nan"], "--t-min nan: a chamber temperature is between"),
    (["--t-min=40", "--t-max=10"], "--t-min 40 must be below --t-max 10"),
    (["--start=90"], "--start 90 is outside --t-min .. --t-max (0 .. 50 °C)"),
    (["--legs=0"], "--legs 0: expected 1 .. 1000"),
])
def test_design_with_absurd_limits_is_exit_64(tmp_path, capsys, args, msg):
    assert cli_main(["design", *MODEL, *args, "--out", str(tmp_path)]) == exitcodes.USAGE
    err = capsys.readouterr().err
    assert err.startswith(f"error: {msg}") and err.count("\n") == 1, err
    assert not any(tmp_path.iterdir())


def test_a_profile_beyond_the_dbc_range_is_refused(tmp_path, capsys):
    cfg = write_config(tmp_path / "hot.yaml", tmp_path / "runs", {"interface": "virtual"},
                       sim={"temperature": [[0, 20], [100, 200], [200, 30]]})
    assert cli_main(["run", str(cfg), "--check"]) == exitcodes.CONFIG
    assert ("simulate.temperature[1]: 200 degC is outside the range of "
            "GYRO_TEMP_1.Temperature (-60 .. 150 degC)") in capsys.readouterr().err


def test_a_saturated_drift_is_logged(tmp_path, capsys, caplog):
    cfg = write_config(tmp_path / "big.yaml", tmp_path / "runs", {"interface": "virtual"},
                       sim={"duration": 30, "gyros": {"az": {
                           "model": ["markov", "bias"],
                           "params": {"markov.beta": 0.03, "markov.sigma": 0.1,
                                      "bias.b": 5000.0}}}})
    d = yaml.safe_load(cfg.read_text())
    d["gyros"][0]["model"] = ["markov", "bias"]
    cfg.write_text(yaml.safe_dump(d))
    assert cli_main(["simulate", str(cfg), "--log", str(tmp_path / "s.blf")]) == 0
    assert "simulated GYRO_DRIFT_1.Drift: " in caplog.text
    assert "outside its DBC range [-1000, 1000]" in caplog.text and "saturated" in caplog.text
