"""A full disk is a fault, said once and named (issue 28, finding 12 and the exit codes):
``gyrostand replay`` onto a 160 KiB tmpfs fills it, exits 74 naming the run folder and
"No space left on device" and prints "result: not written" where only the provisional
``result.json`` (``"state": "running"``) is there (before: "result: .../result.json"
printed over the provisional file, exit 0). Onto a disk full at start: one error line naming the file,
exit 74, no "--- Logging error ---" traceback (before: six). Root only (a tmpfs is
mounted); skipped otherwise."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import can
import pytest

from gyrostand import exitcodes

from .procs import ROOT, simulated_session


@pytest.fixture
def tmpfs(tmp_path):
    made: list[Path] = []

    def mount(name: str, size: str) -> Path:
        p = Path(f"/tmp/hard_full_{os.getpid()}_{name}")
        p.mkdir(parents=True, exist_ok=True)
        if os.geteuid() != 0 or subprocess.run(
                ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(p)],
                capture_output=True).returncode:
            pytest.skip("cannot mount a tmpfs here (needs root)")
        made.append(p)
        return p

    yield mount
    for p in made:
        subprocess.run(["umount", "-l", str(p)], capture_output=True)
        try:
            p.rmdir()
        except OSError:
            pass


@pytest.fixture(scope="module")
def stand(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("full")
    cfg_path, frames = simulated_session(tmp, duration=1500.0)
    log = tmp / "stand.blf"
    with can.Logger(str(log)) as lg:
        for f in frames:
            lg.on_message_received(f)
    return cfg_path, log


def _replay(cfg_path, log, out):
    return subprocess.run([sys.executable, "-m", "gyrostand", "replay", str(cfg_path),
                           str(log), "--out", str(out)], capture_output=True, text=True,
                          cwd=ROOT, timeout=300)


def test_replay_filling_the_disk_exits_1_and_claims_no_result(stand, tmpfs):
    cfg_path, log = stand
    disk = tmpfs("fill", "160k")
    r = _replay(cfg_path, log, disk)
    assert r.returncode == exitcodes.IOERR, (r.stdout[-2000:], r.stderr[-2000:])
    (run_dir,) = [p for p in disk.iterdir() if p.is_dir()]
    assert f"error: {run_dir}: " in r.stderr and "No space left on device" in r.stderr
    assert "result:     not written" in r.stdout
    # result.json, if any, is the provisional one (a crashed folder's, for diagnose)
    result = run_dir / "result.json"
    assert not result.exists() or json.loads(result.read_text())["state"] == "running"
    assert "Traceback" not in r.stderr and "Logging error" not in r.stderr


def test_replay_onto_a_full_disk_at_start_is_one_error(stand, tmpfs):
    cfg_path, log = stand
    disk = tmpfs("atstart", "64k")
    with open(disk / "filler", "wb") as fh:
        try:
            fh.write(b"\0" * (1 << 20))
        except OSError:
            pass
    r = _replay(cfg_path, log, disk)
    # a failed write, not bad input
    assert r.returncode == exitcodes.IOERR, (r.stdout[-2000:], r.stderr[-2000:])
    assert "No space left on device" in r.stderr and str(disk) in r.stderr
    assert "Traceback" not in r.stderr and "Logging error" not in r.stderr
