"""``gyrostand adopt RUN`` (issue 24, item 2): the run's current model written into its
session file as a minimal text edit (comments kept, a backup, the diff printed), checked
as ``run --check`` checks it, and used by the daemon's next run on the bus.

The session is configs/demo.yaml's text (its comments included) with its paths made
absolute, a 400-s stand record at 10 Hz, and a hidden temp2 in the simulator's truth."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

from sessionhelpers import ROOT, run_virtual

from gyrostand import exitcodes
from gyrostand.cli import main
from gyrostand.config import load_config
from gyrostand.session.offline import simulated_frames
from gyrostand.workbench import append_ledger

_channels = itertools.count()


def _session(tmp: Path, *, lkf: str = "") -> Path:
    """configs/demo.yaml, edited as text: absolute paths, its own virtual channel, a short
    record, temp2 in the truth (and ``lkf``, a line added to the gyro)."""
    text = (ROOT / "configs" / "demo.yaml").read_text()
    reps = [("output: ../runs", f"output: {tmp / 'runs'}"),
            ("dbc: ../dbc/gyrostand.dbc", f"dbc: {ROOT / 'dbc' / 'gyrostand.dbc'}"),
            ("channel: gyrostand-demo", f"channel: gyrostand-adopt-{next(_channels)}"),
            ("rates: {drift: 100, temperature: 10}", "rates: {drift: 10, temperature: 10}\n"
                                                     "  duration: 400"),
            ("model: [markov, temp, white]", "model: [markov, temp, white, temp2]"),
            ("white.sigma: 0.0}", "white.sigma: 0.0, temp2.gamma2: -0.0002}"),
            ("    result: {message: GS_RESULT_1", lkf + "    result: {message: GS_RESULT_1")]
    for old, new in reps:
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    path = tmp / "stand.yaml"
    path.write_text(text)
    return path


def _daemon_run(session: Path) -> tuple[Path, dict]:
    """One daemon run on the session file (virtual bus, the simulated stand)."""
    cfg = load_config(session)
    outcome, _, _ = run_virtual(cfg, simulated_frames(cfg))
    assert outcome.ok
    return outcome.run_dir, json.loads(outcome.result_json.read_text())


def test_adopt_edits_the_model_line_only_and_the_daemon_s_next_run_uses_it(tmp_path, capsys):
    session = _session(tmp_path)
    original = session.read_text()
    run, result = _daemon_run(session)
    assert result["config"] == str(session)
    assert result["gyros"]["az"]["model"] == ["markov", "temp", "white"]

    capsys.readouterr()
    assert main(["adopt", str(run)]) == 0  # no workbench step yet: nothing to adopt
    assert "its ledger has no model step" in capsys.readouterr().out
    assert main(["fit", str(run), "--add", "temp2", "-q"]) == 0
    out = capsys.readouterr().out
    assert f"gyrostand diagnose {run}\n" in out  # the verdict first ...
    assert "once ADEQUATE: " in out and f"gyrostand adopt {run})" in out  # ... then adopt

    assert main(["adopt", str(run), "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert session.read_text() == original and not session.with_name("stand.yaml.bak").exists()
    diff = [x for x in out.splitlines() if x[:1] in "+-" and x[:3] not in ("---", "+++")]
    assert diff == ["-    model: [markov, temp]", "-    identifiers: [lkf, lsq, ml]",
                    "+    model: [markov, temp, temp2]", "+    identifiers: [lkf, ml]"]
    assert "lsq does not support the term(s) temp2" in out

    assert main(["adopt", str(run)]) == 0
    out = capsys.readouterr().out
    edited = session.read_text()
    assert session.with_name("stand.yaml.bak").read_text() == original
    old_lines, new_lines = original.splitlines(), edited.splitlines()
    assert len(old_lines) == len(new_lines)
    changed = [(a, b) for a, b in zip(old_lines, new_lines, strict=True) if a != b]
    assert changed == [("    model: [markov, temp]", "    model: [markov, temp, temp2]"),
                       ("    identifiers: [lkf, lsq, ml]", "    identifiers: [lkf, ml]")]
    assert "valid as `run --check`" in out and "from its next run" not in out
    assert "the next run uses the adopted one" in out
    assert f"run {session} --check" in out
    assert main(["run", str(session), "--check"]) == 0
    capsys.readouterr()
    assert main(["adopt", str(run)]) == 0  # again: nothing to do, no second backup
    assert "nothing to adopt" in capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.glob("stand.yaml*")) == ["stand.yaml",
                                                                    "stand.yaml.bak"]

    # the daemon's next run on the edited file: the adopted term identified online and
    # at the end (result.json)
    _, result2 = _daemon_run(session)
    az = result2["gyros"]["az"]
    assert az["model"] == ["markov", "temp", "white", "temp2"]
    assert "temp2.gamma2" in az["fits"]["ml"]["parameters"]
    assert "temp2.gamma2" in az["fits"]["lkf"]["parameters"]  # the online LKF's at stop
    assert "lsq" not in az["fits"]


def test_an_edit_that_does_not_validate_is_undone_exit_78(tmp_path, capsys):
    # the gyro holds bias.b in its LKF: a model without bias makes that key invalid
    session = _session(tmp_path, lkf="    lkf: {held: {bias.b: 0.0}}   # held bias\n")
    text = session.read_text().replace("model: [markov, temp]", "model: [markov, temp, bias]")
    session.write_text(text)
    run, _ = _daemon_run(session)
    append_ledger(run / "ledger.jsonl", {"gyro": "az", "action": "fit",
                                         "model": ["markov", "temp", "white"]})
    capsys.readouterr()
    assert main(["adopt", str(run)]) == exitcodes.CONFIG
    err = capsys.readouterr().err
    assert "does not validate as `run --check` does" in err and "lkf.held.bias.b" in err
    assert "restored it" in err
    assert session.read_text() == text  # as it was
    assert session.with_name("stand.yaml.bak").read_text() == text


def test_adopt_names_a_missing_session_file(tmp_path, capsys):
    session = _session(tmp_path)
    run, _ = _daemon_run(session)
    assert main(["adopt", str(run), "--config", str(tmp_path / "nope.yaml")]) == exitcodes.NOINPUT
    assert "nope.yaml" in capsys.readouterr().err
