"""``run --resume`` (issue 11, items 5 and 8): a session whose dt, epoch, model or online
identifiers differ from the run folder's is refused, naming the key, before anything in
the folder is touched; ``--resume`` without a folder picks the newest *live* run, never a
newer replay folder."""

from __future__ import annotations

import copy

import pytest
from sessionhelpers import DEMO, demo_dict, make_cfg, run_virtual

from gyrostand.config import parse_config
from gyrostand.errors import ConfigError
from gyrostand.session.live import run_live
from gyrostand.session.offline import run_replay, simulated_frames
from gyrostand.session.resume import find_resume_dir


@pytest.fixture(scope="module")
def live_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("resume-checks")
    cfg = make_cfg(out, duration=60.0)
    outcome, _, _ = run_virtual(cfg, list(simulated_frames(cfg)))
    return cfg, outcome, out


def _variant(cfg, out, change):
    d = copy.deepcopy(demo_dict())
    d["session"]["output"] = str(out)
    d["bus"] = dict(cfg.bus)
    d["simulate"]["rates"] = {"drift": 10.0, "temperature": 10.0}
    change(d)
    return parse_config(d, source="changed.yaml", base_dir=DEMO.parent)


@pytest.mark.parametrize("key,change", [
    ("sampling.dt", lambda d: d.setdefault("sampling", {}).update(dt=0.5)),
    ("sampling.epoch", lambda d: d.setdefault("sampling", {}).update(epoch=1.0e9)),
    (r"gyros\[0\].model", lambda d: d["gyros"][0].update(model=["markov", "temp", "bias"])),
    (r"gyros\[0\].identifiers", lambda d: d["gyros"][0].update(identifiers=["lsq"])),
])
def test_resume_with_a_changed_session_is_refused_naming_the_key(live_run, key, change):
    cfg, outcome, out = live_run
    before = {p: p.read_bytes() for p in outcome.run_dir.rglob("*") if p.is_file()
              and p.name != "run.log"}
    changed = _variant(cfg, out, change)
    with pytest.raises(ConfigError, match=rf"changed\.yaml: {key}: .*run folder"):
        run_live(changed, resume=outcome.run_dir, handle_signals=False, duration=0.5)
    after = {p: p.read_bytes() for p in before}
    assert after == before  # nothing cut, nothing appended


def test_resume_without_a_folder_never_picks_a_replay_folder(live_run, tmp_path):
    cfg, outcome, out = live_run
    rep = run_replay(cfg, outcome.run_dir / "raw.blf", out=out)  # newer, same session
    assert rep.run_dir != outcome.run_dir and rep.run_dir.parent == outcome.run_dir.parent
    assert find_resume_dir(cfg, None, out) == outcome.run_dir
