"""``replay`` of runs recorded days apart: one run folder per run, nothing rejected."""

from __future__ import annotations

import copy
import dataclasses
import json
from pathlib import Path

import pytest

from gyrostand.can.framesim import write_log
from gyrostand.cli import main
from gyrostand.config import load_config
from gyrostand.runfolder import samples_path
from gyrostand.session.offline import run_replay, run_replays, simulated_frames, split_runs

ROOT = Path(__file__).resolve().parents[2]
DAYS = 3 * 86400.0


@pytest.fixture(scope="module")
def two_days(tmp_path_factory):
    """Two BLF logs written by python-can: the demo stand for 200 s, and again (another
    seed) three days later."""
    base = load_config(ROOT / "configs" / "demo.yaml")
    tmp = tmp_path_factory.mktemp("days")
    logs = []
    for k, (seed, shift) in enumerate(((42, 0.0), (43, DAYS))):
        sim = dataclasses.replace(base.simulate, duration=200.0, seed=seed)
        frames = []
        for m in simulated_frames(dataclasses.replace(base, simulate=sim)):
            m2 = copy.copy(m)
            m2.timestamp = m.timestamp + shift
            frames.append(m2)
        logs.append(tmp / f"day{k + 1}.blf")
        assert write_log(logs[-1], frames) == len(frames)
    return base, logs, tmp


def test_logs_days_apart_are_two_runs_each_as_if_replayed_alone(two_days):
    cfg, (a, b), tmp = two_days
    assert split_runs([[a], [b]], cfg.sampling.max_gap) == [[a], [b]]
    both = run_replays(cfg, [[a], [b]], out=tmp / "both")
    assert len(both) == 2 and both[0].run_dir != both[1].run_dir
    for outcome, log in zip(both, (a, b), strict=True):
        alone = run_replay(cfg, log, out=tmp / f"alone-{log.stem}")
        got = samples_path(outcome.run_dir, "az").read_bytes()
        assert got == samples_path(alone.run_dir, "az").read_bytes()
        assert got.count(b"\n") > 150
        stats = json.loads((outcome.run_dir / "result.json").read_text())["stats"]
        text = json.dumps(stats)
        assert '"time_jump": 0' in text and '"clock_steps": 0' in text, text[:400]


def test_the_cli_makes_one_run_folder_per_day(two_days, capsys):
    cfg, (a, b), tmp = two_days
    out = tmp / "cli"
    assert main(["replay", str(cfg.path), str(a), str(b), "--out", str(out),
                 "--format", "json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["runs"]) == 2
    assert len([p for p in out.iterdir() if p.is_dir()]) == 2


def test_logs_that_continue_each_other_stay_one_run(two_days):
    """A log whose frames follow the previous one's within sampling.max_gap (a resumed
    run's next segment) continues that run."""
    cfg, (a, _), tmp = two_days
    base = load_config(ROOT / "configs" / "demo.yaml")
    sim = dataclasses.replace(base.simulate, duration=100.0, seed=44, start=1_700_000_260.0)
    later = tmp / "later.blf"
    write_log(later, list(simulated_frames(dataclasses.replace(base, simulate=sim))))
    assert split_runs([[a], [later]], cfg.sampling.max_gap) == [[a, later]]
    # ... and an earlier log after a later one is a run of its own
    assert split_runs([[later], [a]], cfg.sampling.max_gap) == [[later], [a]]
