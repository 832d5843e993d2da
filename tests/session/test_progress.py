"""Progress of a long command (#14 item 4, #27 item 4): a tqdm bar on a pseudo-terminal
with a total and an ETA where the total is known (a BLF's time span), nothing in a pipe or
with --quiet; the real CLI in a subprocess each time."""

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

STAGE_LINE = re.compile(r"^replay: stream: .* in [\d.]+ s$", re.M)


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


def test_a_bar_with_its_total_and_eta_on_a_terminal(replay_args):
    out = _on_pty(replay_args)
    assert "replay: stream" in out and "\r" in out  # redrawn in place
    # the BLF header's 600 s as the total, the log's time read so far, the ETA
    bar = re.findall(r"replay: stream: +(\d+)%[^\r\n]*? (\d+)/(\d+) "
                     r"\[\d\d:\d\d<\d\d:\d\d, +[\d.?]+ s of log/s\]", out)
    assert bar and bar[-1][0] == "100" and bar[-1][1] == bar[-1][2], out[-1500:]
    assert 600 <= int(bar[-1][2]) <= 602
    assert not STAGE_LINE.search(out.replace("\r\n", "\n"))


def test_nothing_in_a_pipe(replay_args):
    p = subprocess.run([sys.executable, "-m", "gyrostand", *replay_args],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert "replay:" not in p.stderr and "\r" not in p.stderr, p.stderr
    assert "stopped: end of log" in p.stdout


def test_quiet_on_a_terminal_draws_nothing(replay_args):
    out = _on_pty(["-q", *replay_args]).replace("\r\n", "\n")
    assert "replay: stream" not in out and "\r" not in out
    assert "stopped: end of log" in out


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
    r"^(diagnose|report): (ML fit of [a-z0-9_,]+|candidates, reference, residuals, floor"
    r"|Allan tables|estimates over time|figures: 7 figures):? in [\d.]+ s$",
    re.M)


@pytest.fixture(scope="module")
def chamber_csv(tmp_path_factory):
    from tests.report.conftest import chamber_samples

    path = tmp_path_factory.mktemp("progress_wb") / "chamber.csv"
    chamber_samples(hours=0.5, seed=5).to_csv(path)
    return path


def test_diagnose_shows_its_stages_as_bars_on_a_terminal(chamber_csv):
    out = _on_pty(["diagnose", str(chamber_csv), "--unit", "deg/h"]).replace("\r\n", "\n")
    assert "diagnose: candidates, reference, residuals, floor" in out
    # the candidates counted: all 8 of the vocabulary's for markov,temp,bias
    assert re.search(r"\| ?8/8", out), out[-2000:]
    assert "\r" in out  # tqdm redraws in place
    assert not WORKBENCH_LINE.search(out), out[-2000:]
    assert "verdict" in out and "Allan variance" in out  # the result itself, on stdout


def test_report_in_a_pipe_prints_its_path_only(chamber_csv, tmp_path):
    p = subprocess.run([sys.executable, "-m", "gyrostand", "report", str(chamber_csv),
                        "--single-file", "--out", str(tmp_path / "rep")],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert not WORKBENCH_LINE.search(p.stderr) and "report:" not in p.stderr, p.stderr
    assert "\r" not in p.stderr
    assert p.stdout.strip() == str(tmp_path / "rep" / "report.html")  # stdout: the path only


def test_a_stage_without_updates_still_shows_its_time(monkeypatch):
    """A bar whose caller never updates it (diagnose's candidate stage) is redrawn by its
    own ticker: its elapsed time moves (issue 27: it sat at [00:00])."""
    import io

    from gyrostand import progress

    class Tty(io.StringIO):
        def isatty(self) -> bool:
            return True

    tty = Tty()
    monkeypatch.setattr(progress.Stage, "TICK", 0.05)
    progress.configure(on=True, stream=tty)
    try:
        with progress.stage("diagnose", "candidates") as st:
            assert st.lines
            time.sleep(1.3)
    finally:
        progress.configure(on=False)
    assert "diagnose: candidates [00:01]" in tty.getvalue()


def test_simulate_shows_the_stand_time_it_has_made(replay_args, tmp_path):
    """simulate (silent for 22 s before, issue 27): its bar counts the stand's seconds
    against the simulate section's duration."""
    out = _on_pty(["simulate", replay_args[1], "--log", str(tmp_path / "again.blf")])
    bar = re.findall(r"simulate: frames: +(\d+)%[^\r\n]*? (\d+)/600 ", out)
    assert bar and bar[-1] == ("100", "600"), out[-1500:]
    assert "wrote " in out
