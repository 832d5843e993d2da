"""A shared effect must repeat from run to run (gyrostand.core.diagnose.repeats): Cochran's
Q of the per-run coefficients, in the joint diagnosis of several runs built from frames."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gyrostand.cli import main
from gyrostand.core.chisq import chi2_sf
from gyrostand.core.data import Samples
from gyrostand.core.diagnose.joint import joint_diagnose
from gyrostand.core.diagnose.repeats import (
    REPEAT_ALPHA,
    compared_coefficients,
    q_statistic,
    slow_process,
)
from gyrostand.core.model import Model
from gyrostand.report.text import joint_diagnosis

from ..workbench.framelike import frame_run

BASE_MODEL = "markov,temp,bias"


def test_q_is_the_weighted_spread_around_the_common_estimate():
    # one coefficient: estimates 1 and 3, variances 1 and 1: mean 2, Q = 1 + 1
    assert q_statistic([np.array([1.0]), np.array([3.0])], [np.eye(1), np.eye(1)]) == 2.0
    # unequal variances 1 and 4: mean (1 + 3/4) / (1 + 1/4) = 1.4, Q = 0.16 + 2.56/4
    assert q_statistic([np.array([1.0]), np.array([3.0])],
                       [np.eye(1), 4 * np.eye(1)]) == pytest.approx(0.8, abs=1e-12)
    # two coefficients, correlated: Q is the GLS residual sum of squares of the stacked
    # estimates on a common mean (an independent route through lstsq)
    b = [np.array([1.0, -2.0]), np.array([0.5, 1.0]), np.array([2.0, 0.0])]
    v = [np.array([[1.0, 0.3], [0.3, 2.0]]), np.array([[0.5, -0.1], [-0.1, 1.0]]),
         np.array([[2.0, 0.0], [0.0, 0.5]])]
    chol = [np.linalg.cholesky(np.linalg.inv(c)).T for c in v]  # W = L'L
    a = np.vstack([c for c in chol])
    y = np.concatenate([c @ x for c, x in zip(chol, b, strict=True)])
    coef = np.linalg.lstsq(a, y, rcond=None)[0]
    rss = float(np.sum((y - a @ coef) ** 2))
    assert q_statistic(b, v) == pytest.approx(rss, rel=1e-12)


def test_what_is_tested():
    m = Model.parse(BASE_MODEL)
    assert compared_coefficients(m, "trend") == ("trend.c",)
    assert compared_coefficients(m, "temp2") != ()
    # random processes, per-run terms (a warm-up: each switch-on its own) and a lag
    # without a linear coefficient are not
    assert compared_coefficients(m, "random_walk") == compared_coefficients(m, "warmup") == compared_coefficients(m, "temp_lag") == ()
    assert not slow_process(m) and slow_process(m.add("random_walk"))


def _runs(tmp_path, c1, c2, seed):
    return [Samples.read_csv(frame_run(tmp_path / f"r{seed + i}.csv", ["trend"],
                                       {"trend.c": c}, seed=seed + i, drop=0.01))
            for i, c in enumerate((c1, c2))]


def test_a_trend_that_repeats_is_proposed(tmp_path):
    # the same trend in both switch-ons: Q small, the trend ranked and proposed first
    rep = joint_diagnose(_runs(tmp_path, 1e-5, 1e-5, 31), Model.parse(BASE_MODEL))
    first = rep.significant[0]
    assert first.term == "trend"
    assert first.repeats is not None and first.repeats.repeats
    assert first.repeats.p_value >= 0.01
    per_run = [v[0] for v in first.repeats.values]
    assert all(abs(v - 1e-5) < 4 * s[0] for v, s in zip(per_run, first.repeats.stds,
                                                         strict=True))
    d = rep.to_dict()["candidates"][0]
    assert d["term"] == "trend" and d["repeats"]["repeats"] is True


def test_a_trend_that_does_not_repeat_is_not_proposed(tmp_path):
    # one switch-on drifts 1e-5 deg/h a second, the next 3e-5: significant on the runs
    # together, but not one effect of the gyro
    runs = _runs(tmp_path, 1e-5, 3e-5, 41)
    rep = joint_diagnose(runs, Model.parse(BASE_MODEL))
    trend = next(c for c in rep.candidates if c.term == "trend")
    assert trend.p_value < rep.alpha / len(rep.candidates)  # significant by its LR
    assert trend.repeats is not None and not trend.repeats.repeats
    assert trend.repeats.p_value < REPEAT_ALPHA
    assert trend.repeats.p_value == pytest.approx(chi2_sf(trend.repeats.stat, 1), rel=1e-12)
    # the per-run estimates are each run's own trend
    (v1,), (v2,) = trend.repeats.values
    (s1,), (s2,) = trend.repeats.stds
    assert abs(v1 - 1e-5) < 4 * s1 and abs(v2 - 3e-5) < 4 * s2
    assert not trend.ranked and "does not repeat across the 2 runs" in trend.note
    assert all(c.term != "trend" for c in rep.significant)
    assert not rep.adequate
    if not rep.significant:  # nothing else to propose: the verdict says why
        assert any("does not repeat" in r for r in rep.reasons), rep.reasons
    text = joint_diagnosis(rep)
    assert "does not repeat across the 2 runs (Cochran's Q" in text
    assert rep.to_dict()["candidates"][[c.term for c in rep.candidates].index("trend")][
        "repeats"]["repeats"] is False


def test_the_model_s_own_thermal_coefficient_is_checked_run_by_run(tmp_path, capsys):
    # the same gyro twice: temp.gamma repeats; then a second switch-on whose thermal
    # coefficient is twice the first's (a mounting changed): it does not, and the verdict
    # says so
    m = Model.parse(BASE_MODEL)
    same = [Samples.read_csv(frame_run(tmp_path / f"s{k}.csv", seed=51 + k, drop=0.01))
            for k in range(2)]
    rep = joint_diagnose(same, m)
    (temp,) = rep.repeats
    assert temp.term == "temp" and temp.names == ("temp.gamma",) and temp.repeats
    for (v,), (s,) in zip(temp.values, temp.stds, strict=True):
        assert abs(v - (-0.0005)) < 4 * s
    assert not any("does not repeat" in r for r in rep.reasons)
    assert "does each shared effect repeat?" in joint_diagnosis(rep)
    assert rep.to_dict()["repeats"][0]["repeats"] is True

    # through the command, as a user runs it on the two CSVs
    other = frame_run(tmp_path / "o.csv", seed=53, drop=0.01, params={"temp.gamma": -0.001})
    first = str(tmp_path / "s0.csv")
    assert main(["diagnose", first, str(other), "--model", BASE_MODEL, "--format",
                 "json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    (temp,) = doc["repeats"]
    assert temp["term"] == "temp" and not temp["repeats"] and temp["p_value"] < REPEAT_ALPHA
    assert temp["values"][1][0] == pytest.approx(-0.001, abs=4 * temp["stds"][1][0])
    assert not doc["adequate"]
    assert any(r.startswith("the model's temp does not repeat across the 2 runs")
               for r in doc["reasons"]), doc["reasons"]
    assert main(["diagnose", first, str(other), "--model", BASE_MODEL]) == 0
    assert "DOES NOT REPEAT" in capsys.readouterr().out


def test_a_lone_unrepeated_effect_is_a_reason_unless_a_second_process_is_its_wander(tmp_path):
    # the trend the only candidate: nothing else to propose, so the verdict names it; with
    # a random walk in the model (the wander it can be) it is a note only
    runs = _runs(tmp_path, 1e-5, 3e-5, 41)
    rep = joint_diagnose(runs, Model.parse(BASE_MODEL), terms=["trend"])
    (trend,) = rep.candidates
    assert not trend.ranked and not rep.significant and not rep.adequate
    (reason,) = [r for r in rep.reasons if r.startswith("trend is significant on the 2 runs")]
    assert "does not repeat" in reason
    assert "the model has no random process but its first" in reason
    walk = joint_diagnose(runs, Model.parse(BASE_MODEL + ",random_walk"), terms=["trend"])
    (trend,) = walk.candidates
    assert trend.p_value < walk.alpha and trend.repeats is not None
    assert not trend.repeats.repeats and not trend.ranked
    assert not any(r.startswith("trend is significant") for r in walk.reasons), walk.reasons
