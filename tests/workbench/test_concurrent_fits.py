"""Two ``fit`` commands on one run at once (issue 28, finding 5): the ledger is held for
each read-fit-append, so the second starts from the first's model and no step is lost."""

from __future__ import annotations

import subprocess
import sys

from gyrostand.core.model import Model
from gyrostand.core.profiles import TemperatureProfile
from gyrostand.core.simulation import simulate
from gyrostand.workbench.ledger import read_ledger


def test_concurrent_fits_keep_both_terms(tmp_path):
    csv = tmp_path / "run.csv"
    simulate(Model.parse("markov,temp,bias"), {
        "markov.beta": 0.02, "markov.sigma": 0.05, "temp.gamma": -0.001,
        "white.sigma": 0.02, "bias.b": 0.3},
        TemperatureProfile.from_breakpoints([[0, 20], [400, 45], [800, 45], [1200, 30]]),
        seed=3).to_csv(csv)
    cmd = [sys.executable, "-m", "gyrostand", "fit", str(csv), "-q", "--add"]
    procs = [subprocess.Popen(cmd + [term], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for term in ("trend", "temp2")]
    outs = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [o[1][-2000:] for o in outs]
    steps = read_ledger(tmp_path / "run.ledger.jsonl")
    assert [s["step"] for s in steps] == [1, 2]
    assert sorted(s["added"][0] for s in steps) == ["temp2", "trend"]
    # the second step's model holds the first's term: nothing was dropped
    assert {"trend", "temp2"} <= set(steps[-1]["model"])
    assert set(steps[0]["model"]) < set(steps[1]["model"])
