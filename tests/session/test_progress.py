"""Progress of a long command (#14 item 4): a tqdm bar on a pseudo-terminal, one line per
finished stage in a pipe or with --quiet; the real CLI in a subprocess each time."""

from __future__ import annotations

import os
import pty
import re
import select
import subprocess
import sys
import time
from pathlib import Path

import pytest
from sessionhelpers import write_cfg_yaml

STAGE_LINE = re.compile(r"^replay: stream: [\d,]+ bins in [\d.]+ s$", re.M)


@pytest.fixture(scope="module")
def replay_args(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("progress")
    cfg = write_cfg_yaml(tmp / "s.yaml", tmp / "runs", {"interface": "virtual"},
                         duration=600.0, rates={"drift": 20, "temperature": 10})
    log = tmp / "stand.blf"
    subprocess.run([sys.executable, "-m", "gyrostand", "simulate", str(cfg), "--log", str(log)],
                   check=True, capture_output=True, timeout=300)
    return ["replay", str(cfg), str(log), "--out", str(tmp / "runs")]


def _on_pty(args: list[str]) -> str:
    """Run with stderr (and stdout) on a pseudo-terminal; everything it printed."""
    master, slave = pty.openpty()
    p = subprocess.Popen([sys.executable, "-m", "gyrostand", *args], stdin=subprocess.DEVNULL,
                         stdout=slave, stderr=slave, close_fds=True)
    os.close(slave)
    chunks: list[bytes] = []
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        r, _, _ = select.select([master], [], [], 0.5)
        if r:
            try:
                data = os.read(master, 65536)
            except OSError:  # EIO: the child closed the terminal
                break
            if not data:
                break
            chunks.append(data)
        elif p.poll() is not None:
            break
    p.wait(30)
    os.close(master)
    assert p.returncode == 0, b"".join(chunks).decode(errors="replace")[-2000:]
    return b"".join(chunks).decode(errors="replace")


def test_a_bar_on_a_terminal(replay_args):
    out = _on_pty(replay_args)
    assert "replay: stream" in out and "bins/s" in out  # tqdm's rate
    assert "\r" in out  # redrawn in place
    assert not STAGE_LINE.search(out.replace("\r\n", "\n"))


def test_stage_lines_in_a_pipe(replay_args):
    p = subprocess.run([sys.executable, "-m", "gyrostand", *replay_args],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert STAGE_LINE.search(p.stderr), p.stderr
    assert re.search(r"^replay: final fits and report: in [\d.]+ s$", p.stderr, re.M)
    assert "\r" not in p.stderr and "bins/s" not in p.stderr
    n = int(STAGE_LINE.search(p.stderr).group(0).split()[2].replace(",", ""))
    assert 590 <= n <= 602  # the 600-s log's bins


def test_quiet_on_a_terminal_gives_stage_lines(replay_args):
    out = _on_pty(["-q", *replay_args]).replace("\r\n", "\n")
    assert STAGE_LINE.search(out) and "bins/s" not in out


def test_nothing_from_library_use(replay_args, capsys):
    """Imported as a library (tests, scripts), gyrostand prints no progress."""
    from gyrostand import progress
    from gyrostand.config import load_config
    from gyrostand.session.offline import run_replay

    # as in a process that never ran the CLI (an in-process CLI call earlier in the suite,
    # e.g. tests/session/test_export.py, turns progress on for the whole process)
    progress.configure(on=False)
    cfg = load_config(replay_args[1])
    run_replay(cfg, Path(replay_args[2]), out=Path(replay_args[4]))
    err = capsys.readouterr().err
    assert "replay: stream" not in err


# ---- diagnose and report: their stages (ML fit, candidates and floor, Allan tables,
# estimates over time, figures), from the workbench, not from the numerical core ---------

WORKBENCH_LINE = re.compile(
    r"^(diagnose|report): (ML fit of the current model|candidates, residual tests, "
    r"model-error floor|Allan tables|estimates over time|figures: 7 figures):? in [\d.]+ s$",
    re.M)


@pytest.fixture(scope="module")
def chamber_csv(tmp_path_factory):
    from tests.report.conftest import chamber_samples

    path = tmp_path_factory.mktemp("progress_wb") / "chamber.csv"
    chamber_samples(hours=0.5, seed=5).to_csv(path)
    return path


def test_diagnose_shows_its_stages_as_bars_on_a_terminal(chamber_csv):
    out = _on_pty(["diagnose", str(chamber_csv), "--unit", "deg/h"]).replace("\r\n", "\n")
    assert "diagnose: candidates, residual tests, model-error floor" in out
    assert "\r" in out  # tqdm redraws in place
    assert not WORKBENCH_LINE.search(out), out[-2000:]
    assert "verdict" in out and "Allan variance" in out  # the result itself, on stdout


def test_report_stage_lines_in_a_pipe_and_none_on_stdout(chamber_csv, tmp_path):
    p = subprocess.run([sys.executable, "-m", "gyrostand", "report", str(chamber_csv),
                        "--single-file", "--out", str(tmp_path / "rep")],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    names = [m.group(2) for m in WORKBENCH_LINE.finditer(p.stderr)]
    assert names == ["ML fit of the current model",
                     "candidates, residual tests, model-error floor", "Allan tables",
                     "estimates over time", "figures: 7 figures"], p.stderr
    assert all(m.group(1) == "report" for m in WORKBENCH_LINE.finditer(p.stderr))
    assert "\r" not in p.stderr
    assert p.stdout.strip() == str(tmp_path / "rep" / "report.html")  # stdout: the path only
