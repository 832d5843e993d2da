"""Advice that runs (issue 24): the ``next:`` line of ``diagnose`` is a command that works
pasted as is: the real path of the data, gyrostand as it was invoked, the same options."""

from __future__ import annotations

import shlex
import subprocess
import sys

from gyrostand.cli import common
from gyrostand.core.model import Model
from gyrostand.core.profiles import TemperatureProfile
from gyrostand.core.simulation import simulate


def test_the_next_line_of_diagnose_runs_as_pasted(tmp_path):
    folder = tmp_path / "a folder with spaces"
    folder.mkdir()
    csv = folder / "run.csv"
    truth = Model.parse("markov,temp,temp2")
    p = {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.001,
         "white.sigma": 0.0, "temp2.gamma2": -2e-4}
    prof = TemperatureProfile.from_breakpoints([[0, 20], [500, 45], [1000, 45], [2000, 35]])
    simulate(truth, p, prof, seed=42).to_csv(csv)
    r = subprocess.run([sys.executable, "-m", "gyrostand", "diagnose", str(csv), "--model",
                        "markov,temp", "-q"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    (line,) = [x for x in r.stdout.splitlines() if x.startswith("next: ")]
    cmd = shlex.split(line[len("next: "):])
    assert cmd[:5] == [sys.executable, "-m", "gyrostand", "fit", str(csv)]
    assert cmd[5:] == ["--model", "markov,temp", "--add", "temp2"]
    r2 = subprocess.run(cmd + ["-q"], capture_output=True, text=True, timeout=300)
    assert r2.returncode == 0, r2.stderr
    assert "adding temp2 improves the fit" in r2.stdout


def test_gyrostand_is_named_as_the_user_invoked_it(monkeypatch, tmp_path):
    script = tmp_path / "venv" / "bin" / "gyrostand"
    monkeypatch.setattr(sys, "argv", [str(script), "diagnose"])
    assert common.invocation() == str(script)
    monkeypatch.setattr(sys, "argv", ["/x/gyrostand/__main__.py", "diagnose"])
    assert common.invocation() == f"{shlex.quote(sys.executable)} -m gyrostand"
