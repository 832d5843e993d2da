"""Joint (several-run) diagnoses test a candidate with a shape as single runs do: its LR
against the supremum of a χ²(df) process over the shape (gyrostand.core.diagnose.candidates), the
process's geometry taken on the joint model (the runs' whitened regressors stacked, the
joint fit's metric)."""

from __future__ import annotations

import pytest

from gyrostand.core.chisq import sup_chi2_sf
from gyrostand.core.diagnose.candidates import rank_candidates
from gyrostand.core.diagnose.joint import JointDiagnosis
from gyrostand.core.diagnose.results import TEST_GUARD, TEST_SUP
from gyrostand.core.ml.fit import ml
from gyrostand.core.ml.joint import joint_ml
from gyrostand.report.text import RENDERER

from .sets import run_set

SHAPED = ["temp_rate", "warmup", "hysteresis"]


def test_a_joint_diagnosis_of_one_run_tests_shapes_as_the_single_run():
    """N = 1: the same test, df, curvatures and p as the single-run diagnosis."""
    m, runs, _ = run_set(3, n_runs=1)
    # refitted, not score-screened: a joint diagnosis refits every candidate (a screened
    # single-run candidate shows its LM statistic, 1.2557 here for hysteresis's LR 1.9604)
    single = {c.term: c for c in rank_candidates(runs[0], m, ml(runs[0], m), SHAPED,
                                                 screen=False)}
    joint = {c.term: c for c in rank_candidates(tuple(runs), m, joint_ml(runs, m), SHAPED)}
    for term in SHAPED:
        s, j = single[term], joint[term]
        print(f"{term}: single LR {s.lr_stat:.4f} p {s.p_value:.4g} lkc {s.shape_lkc}; "
              f"joint LR {j.lr_stat:.4f} p {j.p_value:.4g} lkc {j.shape_lkc}")
        # the single run's p is guarded by its score test where the model fits
        # (candidates.guarded); the joint diagnosis takes no score: its p is the LR's
        assert j.test == TEST_SUP and s.test in (TEST_SUP, TEST_GUARD), term
        assert s.df == j.df == 1 and len(j.shape_lkc) == len(s.shape_lkc), term
        assert j.shape_lkc == pytest.approx(s.shape_lkc, rel=1e-6), term
        assert j.lr_stat == pytest.approx(s.lr_stat, rel=1e-6, abs=1e-6), term
        lr_p = sup_chi2_sf(s.lr_stat, s.df, s.shape_lkc)
        assert j.p_value == pytest.approx(lr_p, rel=1e-6), term
        assert s.p_value == pytest.approx(max(lr_p, s.score_p or 0.0), rel=1e-6), term


def test_a_joint_diagnosis_of_two_runs_tests_a_shared_shape_over_its_range():
    """Two runs: the gyro's lag and width (shared by the runs) are tested as the supremum
    over the shape, df = the coefficient, p from the LR and the curvatures shown; a per-run
    shape (each switch-on's warm-up τ: one process per run) keeps χ² with the shapes
    counted."""
    m, runs, _ = run_set(5, n_runs=2)
    fit = joint_ml(runs, m)
    by = {c.term: c for c in rank_candidates(tuple(runs), m, fit, SHAPED)}
    for term, dims in (("temp_rate", 1), ("hysteresis", 2)):
        c = by[term]
        assert c.test == TEST_SUP and c.df == 1 and len(c.shape_lkc) == dims, term
        assert all(v > 0 for v in c.shape_lkc), term
        assert c.p_value == pytest.approx(sup_chi2_sf(c.lr_stat, c.df, c.shape_lkc)), term
        assert c.to_dict()["df"] == c.df and c.to_dict()["shape_lkc"] == list(c.shape_lkc)
    w = by["warmup"]
    assert w.test != TEST_SUP and w.shape_lkc == () and w.df == 4  # 2 amplitudes, 2 τ
    d = JointDiagnosis(fit=fit, candidates=tuple(by.values()), alpha=0.05, adequate=True,
                       reasons=())
    table = RENDERER.render(d)
    assert "p from: " in table and "sup over the shape" in table
    sup_line = table.split("df = coefficients): ")[1].split(";")[0]
    assert "temp_rate" in sup_line and "hysteresis" in sup_line and "warmup" not in sup_line


def test_a_joint_diagnosis_names_a_term_the_runs_do_not_need():
    """Two runs without a trend, diagnosed jointly with a trend in the model: ADEQUATE, and
    the trend named redundant by its own test on the runs together (as one run's
    ``diagnose`` names one), in the JSON and the text; the true model names nothing."""
    from gyrostand.core.diagnose.joint import joint_diagnose

    m, runs, _ = run_set(7, n_runs=2, hours=1.5)
    d = joint_diagnose(runs, m.add("trend"), terms=["temp2"])
    assert d.adequate, d.reasons
    (x,) = d.redundant
    assert x["term"] == "trend" and x["p_value"] >= 0.05 and x["df"] == 1, x
    assert d.to_dict()["redundant"] == [x]
    assert "redundant: trend no longer earns its place on the runs together" in \
        RENDERER.render(d)
    assert joint_diagnose(runs, m, terms=["temp2"]).redundant == ()
