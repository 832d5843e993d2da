"""One number, one meaning (issue 24): a candidate's LR, df and p are the same in
``diagnose``, in the ``fit`` that adds it, in the ledger and in the JSON; the table's order
never puts an insignificant candidate above a significant one; near-equal candidates get
the look-alike note."""

from __future__ import annotations

import json

from gyrostand.cli import main
from gyrostand.report.text import diagnosis
from gyrostand.workbench.ledger import read_ledger
from gyrostand.workbench.steps import run_diagnose
from gyrostand.workbench.subject import open_subject

from .test_hidden_effects import chamber_run


def test_a_shaped_candidate_has_one_lr_df_and_p_everywhere(tmp_path, capsys):
    # a hidden temp_rate on a 4-h cycle: temp_rate (a shape, tested by the sup over its
    # lag) and hysteresis (a search bound on its width) explain it about equally well
    path = chamber_run(tmp_path, ["temp_rate"], {"temp_rate.k": 5.0}, seed=3)
    rep = run_diagnose(open_subject(path))
    d = json.loads(json.dumps(rep.to_dict()))
    cands = d["candidates"]
    top = cands[0]
    assert top["term"] == "temp_rate" and top["df"] == 1 and top["test"] == "sup over shape"
    # significant first, by ΔBIC; never an insignificant one above a significant one
    alpha_each = 0.05 / len(cands)
    sig = [c["ranked"] and c["p_value"] < alpha_each for c in cands]
    assert sig == sorted(sig, reverse=True), [(c["term"], c["p_value"]) for c in cands]
    assert [c["delta_bic"] for c in cands if c["ranked"] and c["p_value"] < alpha_each] == \
        sorted(c["delta_bic"] for c in cands if c["ranked"] and c["p_value"] < alpha_each)
    # the look-alike: hysteresis fits as well, its width at a bound, and the note says so
    la = [x for x in d["look_alikes"] if x["terms"] == ["temp_rate", "hysteresis"]]
    assert la and "search bound" in la[0]["note"], d["look_alikes"]
    text = diagnosis(rep, str(path))
    assert "look-alikes: temp_rate and hysteresis" in text

    shown = main(["fit", str(path), "--add", "temp_rate"]) == 0 and capsys.readouterr().out
    # the ledger's step is the fit's JSON (FitStep.to_dict)
    step = read_ledger(open_subject(path).ledger_path)[-1]
    assert step["action"] == "fit" and step["test"] == top["test"]
    assert (step["lr_stat"], step["df"], step["p_value"]) == pytest_approx(
        (top["lr_stat"], top["df"], top["p_value"]))
    assert f"LR = {top['lr_stat']:.2f} on 1 df (sup over its shape), p = " in shown


def pytest_approx(values):
    """Equal to 1e-6 relative: the fit refits from the same start as the candidate."""
    import pytest

    return pytest.approx(values, rel=1e-6)
