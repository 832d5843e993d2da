"""Hostile input (issue 11, "crashes and hangs", "wrong results without a warning"): every
case is a clean ``error: ...`` naming the input (an exit status by its kind, 64..78),
never a traceback, a hang or a silently wrong answer. Random bytes as session files and ledgers (hypothesis) give a
ConfigError / DataError and nothing else."""

from __future__ import annotations

import copy
import json
import os
import shutil
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gyrostand import exitcodes
from gyrostand.cli import main as cli_main
from gyrostand.config import load_config
from gyrostand.errors import ConfigError, DataError
from gyrostand.session.offline import run_replay, simulated_frames
from gyrostand.workbench import read_ledger

from .procs import DBC, DEMO

BASE = DEMO.read_text().replace("dbc: ../dbc/gyrostand.dbc", f"dbc: {DBC}")


def _write(tmp: Path, text: str | bytes, name: str = "s.yaml") -> Path:
    p = tmp / name
    p.write_bytes(text if isinstance(text, bytes) else text.encode())
    return p


def _gyro_line(extra: str) -> str:
    return BASE.replace("    model: [markov, temp]\n", f"    model: [markov, temp]\n{extra}", 1)


CASES = {
    "latin-1": (b"session: {name: caf\xe9}\n", r"not UTF-8 text \(byte 19"),
    "utf-16": (BASE.encode("utf-16"), "UTF-16 text; save it as UTF-8"),
    "held list": (_gyro_line("    lkf: {held: [1, 2]}\n"),
                  r"gyros\[0\]\.lkf\.held: expected a mapping, got list"),
    "held string": (_gyro_line("    lkf: {held: abc}\n"),
                    r"gyros\[0\]\.lkf\.held: expected a mapping, got str"),
    "held typo": (_gyro_line("    lkf: {held: {markov.betaa: 1}}\n"),
                  r"lkf\.held\.markov\.betaa: not a parameter of this gyro's model"),
    "400 digits": (BASE.replace("dt: 1.0", "dt: " + "9" * 400, 1),
                   r"sampling\.dt: too large \(400-digit integer\)"),
    "dt 1e-9": (BASE.replace("dt: 1.0", "dt: 1.0e-9", 1), r"sampling\.dt: must be >= 0\.01"),
    "max_gap bins": (BASE.replace("max_gap: 3600", "max_gap: 1.0e+7", 1),
                     r"sampling\.max_gap: must be <= 1e\+06"),
    "huge epoch": (BASE.replace("dt: 1.0", "dt: 1.0\n  epoch: 1.0e+20", 1),
                   r"sampling\.epoch: must be <= 1e\+11"),
    "beta0 30": (_gyro_line("    lkf: {beta0: 30}\n"),
                 r"gyros\[0\]\.lkf\.beta0: 30 1/s must be below 1/sampling\.dt"),
    "beta0 1e300": (_gyro_line("    lkf: {beta0: 1.0e+300}\n"), r"lkf\.beta0: 1e\+300"),
    "beta0 0": (_gyro_line("    lkf: {beta0: 0}\n"), r"lkf\.beta0: must be > 0"),
    "sigma 0": (_gyro_line("    lkf: {sigma: 0}\n"), r"lkf\.sigma: must be > 0"),
    "no markov, explicit lkf": (
        BASE.replace("    model: [markov, temp]\n", "    model: [random_walk, white]\n", 1),
        r"gyros\[0\]\.identifiers: lkf, lsq need\(s\) 'markov'"),
    "not a model": (BASE.replace("    model: [markov, temp]\n", "    model: [temp]\n", 1),
                    r"gyros\[0\]\.model: model term 'temp' needs 'markov'"),
    "duplicate key": (BASE.replace("sampling:\n", "sampling:\n  dt: 2.0\n", 1),
                      r"duplicate key 'dt'"),
    "alias bomb": ("a: &a [x,x,x,x,x,x,x,x,x]\nb: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]\n"
                   "c: [*b,*b,*b,*b,*b,*b,*b,*b,*b]\nsession: *a\n",
                   r"aliases \(\*a\) are not accepted"),
    "alias under bus": (BASE.replace("bus:", "x: &big [1, 2, 3]\nbus:", 1).replace(
        "  channel: gyrostand-demo\n", "  channel: gyrostand-demo\n  extra: *big\n", 1),
        r"aliases \(\*big\)"),
    "sim beta <= 0": (BASE.replace("markov.beta: 0.0333", "markov.beta: -1", 1),
                      r"simulate\.gyros\.az\.params\.markov\.beta: must be > 0"),
    "sim param typo": (BASE.replace("markov.beta: 0.0333", "markov.betta: 0.0333", 1),
                       r"params\.markov\.betta: not a parameter"),
    "sim start 1e300": (BASE.replace("start: 1700000000.0", "start: 1.0e+300", 1),
                        r"simulate\.start: must be <= 1e\+11"),
    "drift on command": (BASE.replace(
        "drift: {message: GYRO_DRIFT_1, signal: Drift, counter: Counter}",
        "drift: {message: GS_COMMAND, signal: Command}", 1),
        r"gyros\[0\]\.drift\.message: GS_COMMAND is the daemon's own message "
        r"\(responses\.command\)"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_session_file_errors_name_the_input(tmp_path, case, capsys):
    text, match = CASES[case]
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError, match=match) as err:
        load_config(path)
    assert str(err.value).startswith(str(path)) and len(str(err.value)) < 1500
    assert cli_main(["simulate", str(path), "--out", str(tmp_path / "x.blf")]) == exitcodes.CONFIG
    assert capsys.readouterr().err.startswith("error: ")


def test_a_model_without_markov_by_default_runs_ml_only_and_says_so(tmp_path, caplog):
    d = yaml.safe_load(BASE)
    d["gyros"][0]["model"] = ["random_walk", "white"]
    del d["gyros"][0]["identifiers"]
    d["session"]["output"] = str(tmp_path / "runs")
    d["simulate"]["duration"] = 300.0
    d["simulate"]["rates"] = {"drift": 10, "temperature": 10}
    cfg = load_config(_write(tmp_path, yaml.safe_dump(d)))
    assert cfg.gyros[0].identifiers == ()
    assert "has no markov term: lkf and lsq need it, so only ml" in caplog.text
    out = run_replay(cfg, simulated_frames(cfg), out=tmp_path / "runs")
    doc = json.loads(out.result_json.read_text())
    assert doc["state"] == "finished"
    assert set(doc["gyros"]["az"]["fits"]) == {"ml"}
    assert "random_walk.q" in doc["gyros"]["az"]["fits"]["ml"]["parameters"]


@settings(max_examples=300, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.one_of(st.binary(max_size=600),
                 st.builds(lambda a, b, c: (BASE.encode()[:a] + c + BASE.encode()[a + b:]),
                           st.integers(0, len(BASE)), st.integers(0, 50),
                           st.binary(max_size=40))))
def test_random_bytes_as_a_session_file_are_a_config_error(tmp_path_factory, raw):
    path = tmp_path_factory.mktemp("rnd") / "r.yaml"
    path.write_bytes(raw)
    try:
        load_config(path)
    except ConfigError as exc:
        assert str(exc).startswith(str(path)) and len(str(exc)) < 2000
    # a mangled session may still be valid: then it loaded, which is fine


@settings(max_examples=300, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.one_of(st.binary(max_size=400),
                 st.lists(st.one_of(st.just('{"model": ["markov", "temp"], "gyro": "az"}'),
                                    st.just("[1, 2]"), st.just('"x"'), st.just("3"),
                                    st.just('{"model": 5}'), st.text(max_size=30)),
                          max_size=6).map(lambda ls: "\n".join(ls).encode())))
def test_random_bytes_as_a_ledger_are_a_data_error(tmp_path_factory, raw):
    path = tmp_path_factory.mktemp("led") / "ledger.jsonl"
    path.write_bytes(raw)
    try:
        entries = read_ledger(path)
    except DataError as exc:
        assert str(path) in str(exc)
    else:
        assert all(isinstance(e, dict) for e in entries)


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("wb")
    d = yaml.safe_load(BASE)
    d["session"]["output"] = str(tmp / "runs")
    d["simulate"]["duration"] = 400.0
    d["simulate"]["rates"] = {"drift": 10, "temperature": 10}
    p = tmp / "s.yaml"
    p.write_text(yaml.safe_dump(d))
    cfg = load_config(p)
    return run_replay(cfg, simulated_frames(cfg), out=tmp / "runs").run_dir


def _copy(run_folder: Path, tmp: Path) -> Path:
    dst = tmp / "run"
    shutil.copytree(run_folder, dst)
    return dst


@pytest.mark.parametrize("case,edit,match", [
    ("result list", lambda r: (r / "result.json").write_text("[1, 2]"),
     r"result\.json: expected a JSON object, got list"),
    ("dt string", lambda r: (r / "result.json").write_text(json.dumps(
        {**json.loads((r / "result.json").read_text()), "dt": "1"})),
     r"result\.json: dt: expected a positive number"),
    ("result not utf-8", lambda r: (r / "result.json").write_bytes(b'{"dt": "\xff"}'),
     r"result\.json: not UTF-8"),
    ("ledger list", lambda r: (r / "ledger.jsonl").write_text("[1]\n"),
     r"ledger\.jsonl: line 1: a ledger entry is a JSON object"),
    ("ledger number", lambda r: (r / "ledger.jsonl").write_text('{"model": ["markov"]}\n3\n'),
     r"ledger\.jsonl: line 2: a ledger entry is a JSON object"),
    ("ledger utf-16", lambda r: (r / "ledger.jsonl").write_bytes('{"a": 1}\n'.encode("utf-16")),
     r"ledger\.jsonl: not UTF-8"),
])
def test_damaged_run_folder_files_are_errors_naming_them(run_folder, tmp_path, capsys, case,
                                                         edit, match):
    run = _copy(run_folder, tmp_path)
    edit(run)
    assert cli_main(["diagnose", str(run)]) == exitcodes.DATAERR
    err = capsys.readouterr().err
    assert err.startswith("error: ") and __import__("re").search(match, err), err


def test_report_where_it_cannot_write_is_an_error_naming_the_path(run_folder, tmp_path,
                                                                   capsys):
    run = _copy(run_folder, tmp_path)
    (run / "report-az").write_text("a file where the report folder goes")
    os.chmod(run, 0o555)
    try:
        assert cli_main(["report", str(run)]) == exitcodes.CANTCREAT
    finally:
        os.chmod(run, 0o755)
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "report-az" in err, err


@pytest.mark.parametrize("argv,match", [
    (["identify", "{csv}", "--method", "lkf", "--gamma0", "inf"], "--gamma0: must be finite"),
    (["identify", "{csv}", "--sigma", "nan"], "--sigma: must be finite"),
    (["identify", "{csv}", "--sigma", "0"], "--sigma: must be > 0"),
    (["identify", "{csv}", "--method", "lkf", "--beta0", "30"],
     "--beta0 30 1/s must be below 1/dt"),
    (["replay", "{cfg}", "{csv}", "--realtime", "--speed", "0"], "--speed: must be > 0"),
    (["run", "{cfg}", "--duration", "-5"], "--duration: must be > 0"),
    (["run", "{cfg}", "--duration", "nan"], "--duration: must be finite"),
    (["simulate", "{cfg}", "--realtime", "--speed", "-1"], "--speed: must be > 0"),
])
def test_cli_numbers_are_checked(run_folder, tmp_path, capsys, argv, match):
    csv = run_folder / "az" / "samples.csv"
    cfg = _write(tmp_path, BASE)
    argv = [a.format(csv=csv, cfg=cfg) for a in argv]
    try:
        rc = cli_main(argv)
    except SystemExit as exc:  # argparse's usage error
        rc = exc.code
    assert rc == exitcodes.USAGE
    assert match in capsys.readouterr().err


def test_error_messages_quote_only_a_bit_of_the_input(tmp_path):
    d = yaml.safe_load(BASE)
    d = copy.deepcopy(d)
    d["gyros"][0]["name"] = "x" * 100_000
    with pytest.raises(ConfigError) as err:
        load_config(_write(tmp_path, yaml.safe_dump(d)))
    assert len(str(err.value)) < 1500
