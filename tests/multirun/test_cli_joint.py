"""``identify`` and ``diagnose`` of several runs of one gyro (CSV inputs)."""

from __future__ import annotations

import json

import pytest

from gyrostand import exitcodes
from gyrostand.cli import main
from gyrostand.workbench import read_ledger

from .sets import run_set


def _csvs(tmp_path, seed: int, n: int, **kw):
    _, runs, biases = run_set(seed, n_runs=n, **kw)
    paths = []
    for r, s in enumerate(runs):
        paths.append(tmp_path / f"run{r + 1}.csv")
        s.to_csv(paths[-1])
    return paths, biases


def test_identify_several_csvs_is_the_joint_fit(tmp_path, capsys):
    paths, biases = _csvs(tmp_path, 31, 3)
    assert main(["identify", *map(str, paths), "--format", "json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc["parameters"]) == {"markov.beta", "markov.sigma", "temp.gamma",
                                      "white.sigma"}
    assert [r["parameters"]["bias.b"]["value"] for r in doc["runs"]] == pytest.approx(
        list(biases), abs=0.05)
    rep = doc["repeatability"]
    assert rep["runs"] == 3 and rep["interval"][0] <= rep["spread"] <= rep["interval"][1]
    assert all("residual_check" in r["info"] for r in doc["runs"])
    # the text table names every run and the repeatability
    assert main(["identify", *map(str, paths)]) == 0
    text = capsys.readouterr().out
    assert "turn-on repeatability of bias.b" in text and "run3.csv" in text
    # one CSV: the single-run JSON, keys unchanged
    assert main(["identify", str(paths[0]), "--format", "json"]) == 0
    one = json.loads(capsys.readouterr().out)
    assert "runs" not in one and "repeatability" not in one and "bias.b" in one["parameters"]


def test_identify_several_runs_needs_ml(tmp_path, capsys):
    paths, _ = _csvs(tmp_path, 32, 2, hours=1.0)
    assert main(["identify", *map(str, paths), "--method", "lsq"]) == exitcodes.USAGE
    assert "jointly by ml only" in capsys.readouterr().err


def test_joint_diagnose_ranks_the_hidden_effect_first(tmp_path, capsys):
    """A temperature-rate effect in all five runs, too weak to matter in one 1.5-h run, is
    the joint diagnosis's first candidate; every run's ledger records the joint step."""
    paths, _ = _csvs(tmp_path, 21, 5, hours=1.5, model="markov,temp,bias,temp_rate",
                     extra={"temp_rate.k": 2.0})
    assert main(["diagnose", *map(str, paths), "--model", "markov,temp,bias",
                 "--format", "json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["adequate"] is False
    first = doc["candidates"][0]
    assert first["term"] == "temp_rate", [c["term"] for c in doc["candidates"]]
    assert len(doc["runs"]) == 5 and doc["repeatability"]["runs"] == 5
    for p in paths:
        steps = read_ledger(p.with_name(p.stem + ".ledger.jsonl"))
        assert steps[-1]["joint"] and steps[-1]["best_candidate"] == "temp_rate"
    # the joint fit step: temp_rate added (its shared k and lag τ), the joint LR on the
    # df and test the joint diagnosis gave it (one coefficient, the sup over the shared lag)
    assert main(["fit", *map(str, paths), "--model", "markov,temp,bias", "--add",
                 "temp_rate", "--format", "json"]) == 0
    step = json.loads(capsys.readouterr().out)
    assert (step["df"], step["test"]) == (first["df"], first["test"]) == (1, "sup over shape")
    assert step["p_value"] < 1e-3
    assert step["lr_stat"] == pytest.approx(first["lr_stat"], rel=0.05, abs=0.5)
    assert "temp_rate.k" in step["parameters"] and "bias.b@5" in step["parameters"]
    assert read_ledger(paths[2].with_name("run3.ledger.jsonl"))[-1]["action"] == "fit"
    # the report of the five runs: the joint diagnosis as a document
    out = tmp_path / "rep"
    assert main(["report", *map(str, paths), "--model", "markov,temp,bias", "--format",
                 "text", "--out", str(out)]) == 0
    text = (out / "report.txt").read_text()
    assert "turn-on repeatability" in text and "temp_rate" in text
