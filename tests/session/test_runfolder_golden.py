"""A replay of a fixed raw log writes the same bytes as before the run-folder module.

``tests/data/runfolder/replay.blf`` is a stored log (600 s of the demo stand, gap bins in
[200 s, 205 s)); ``golden.json`` holds the sha256 of ``az/samples.csv`` and
``az/estimates.csv`` of its replay, recorded on main c05478b by ``make_golden.py`` beside
them, before the run folder's writers moved into :mod:`gyrostand.runfolder`.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parents[1] / "data" / "runfolder"


@pytest.fixture(scope="module")
def golden_tools():
    sys.path.insert(0, str(DATA))
    try:
        import make_golden
    finally:
        sys.path.remove(str(DATA))
    return make_golden


def test_a_replay_of_the_fixed_log_gives_the_golden_bytes(golden_tools, tmp_path):
    want = json.loads((DATA / "golden.json").read_text())
    got = golden_tools.replay_digests(DATA / "replay.blf", tmp_path)
    for name in ("samples.csv", "estimates.csv"):
        # first and last rows first: a mismatch then shows what changed
        assert (got[name]["first"], got[name]["last"], got[name]["rows"]) == \
            (want[name]["first"], want[name]["last"], want[name]["rows"]), name
        assert got[name] == want[name], name
    assert want["samples.csv"]["rows"] == 601  # 600 s: bins 0..600 s, 5 of them gaps
