"""Advice that runs (issue 24): the ``next:`` line of ``diagnose`` is a command that works
pasted as is: the real path of the data, gyrostand as it was invoked, the same options."""

from __future__ import annotations

import shlex
import subprocess
import sys
from pathlib import Path

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


#: a one-gyro stand's DBC (a rate with a rolling counter, the gyro's case temperature)
ONE_GYRO = """VERSION ""
BO_ 272 GYRO_RATE: 8 FOG
 SG_ Rate : 0|32@1- (1e-05,0) [-1000|1000] "deg/h" X
 SG_ RateCnt : 32|4@1+ (1,0) [0|15] "" X
BO_ 273 GYRO_TEMP: 8 FOG
 SG_ CaseTemp : 0|16@1- (0.01,0) [-40|125] "degC" X
"""


def _pasted(line: str, prefix: str) -> list[str]:
    assert line.startswith(prefix), line
    cmd = shlex.split(line[len(prefix):])
    assert cmd[:3] == [sys.executable, "-m", "gyrostand"], cmd  # as invoked: not on PATH
    return cmd


def test_init_s_hints_run_as_pasted(tmp_path):
    """``init``'s printed hints (and the one in the file it writes) run as pasted, from a
    folder with spaces: ``run --check`` and the demo on the file's simulated stand, on a
    bus this machine has (virtual where SocketCAN is absent)."""
    folder = tmp_path / "my stand"
    folder.mkdir()
    dbc = folder / "fog.dbc"
    dbc.write_text(ONE_GYRO)
    out = folder / "stand.yaml"
    r = subprocess.run([sys.executable, "-m", "gyrostand", "init", str(dbc), "-o", str(out)],
                       capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    check = _pasted(next(x for x in lines if x.startswith("check it")), "check it, then: ")
    assert check[3:] == ["run", str(out), "--check"]
    demo = _pasted(next(x for x in lines if x.startswith("try it")),
                   "try it without the stand (its simulate: section): ")
    assert demo[3:6] == ["demo", "--clean", "--config"] and demo[6] == str(out)
    in_file = [x.removeprefix("#     ") for x in out.read_text().splitlines()
               if x.startswith("#     ") and " -m gyrostand " in x]
    assert [shlex.split(x)[3] for x in in_file] == ["run", "demo"]
    outs = []
    for cmd in (check, shlex.split(in_file[0]), demo):
        r = subprocess.run([*cmd, "-q"], capture_output=True, text=True, timeout=300,
                           cwd=tmp_path)
        assert r.returncode == 0, (cmd, r.stdout[-2000:], r.stderr[-2000:])
        outs.append(r.stdout)
    assert "valid session 'fog'" in outs[0] and "valid session 'fog'" in outs[1]
    assert "601 bins, 0 gaps" in outs[2]  # the simulated stand's 600 s, every bin full


def test_the_demo_hint_of_a_socketcan_scaffold_stays_off_the_stand_s_bus():
    from gyrostand.session.scaffold import try_it_command

    cmd = shlex.split(try_it_command("s.yaml", {"interface": "socketcan", "channel": "can0"}))
    assert cmd[3:] == ["demo", "--clean", "--config", "s.yaml", "-i", "virtual", "-c",
                       "gyrostand-try", "--bus-kwargs", "preserve_timestamps=true"]


def test_the_report_s_next_step_runs_as_pasted(tmp_path):
    import html
    import re

    folder = tmp_path / "a folder with spaces"
    folder.mkdir()
    csv = folder / "run.csv"
    truth = Model.parse("markov,temp,temp2")
    p = {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.001,
         "white.sigma": 0.0, "temp2.gamma2": -2e-4}
    prof = TemperatureProfile.from_breakpoints([[0, 20], [400, 45], [700, 45], [1000, 35]])
    simulate(truth, p, prof, seed=42).to_csv(csv)
    r = subprocess.run([sys.executable, "-m", "gyrostand", "report", str(csv), "--model",
                        "markov,temp", "-q"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    page = Path(r.stdout.strip()).read_text()
    codes = [html.unescape(c) for c in re.findall(r"<code>([^<]*)</code>", page)]
    (nxt,) = re.findall(r"Next step: <code>([^<]*)</code>", page)
    cmd = shlex.split(html.unescape(nxt))
    assert cmd[:5] == [sys.executable, "-m", "gyrostand", "fit", str(csv)]
    assert cmd[5:] == ["--model", "markov,temp", "--add", "temp2"]
    assert f"{shlex.join([sys.executable, '-m', 'gyrostand', 'diagnose', str(csv)])} " \
           "--model markov,temp" in codes  # the empty ledger's hint
    r2 = subprocess.run(cmd + ["-q"], capture_output=True, text=True, timeout=300)
    assert r2.returncode == 0, r2.stderr
    assert "adding temp2 improves the fit" in r2.stdout


def test_a_report_of_a_named_model_advises_on_that_model(tmp_path):
    """``report RUN --model M`` speaks of M: its advice repeats ``--model M`` (the ledger's
    model may already hold the effect it proposes)."""
    from gyrostand.workbench.advice import subject_command
    from gyrostand.workbench.subject import open_subject

    csv = tmp_path / "run.csv"
    simulate(Model.parse("markov,temp"), {"markov.beta": 0.0333, "markov.sigma": 0.1,
                                          "temp.gamma": -0.001, "white.sigma": 0.0},
             TemperatureProfile.from_breakpoints([[0, 20], [500, 45]]), seed=1).to_csv(csv)
    named = open_subject(csv, model="markov,temp")
    assert shlex.split(subject_command(named, "fit"))[-2:] == ["--model", "markov,temp,white"]
    assert "--model" not in subject_command(open_subject(csv), "fit")
