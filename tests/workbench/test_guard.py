"""The score test guards a candidate's LR where the model fits (issue 23: a verdict is only
as good as its reference; the LR of a term whose refit readjusts the random part
overshoots its own law — :func:`~gyrostand.core.diagnose.candidates.guarded`)."""

from __future__ import annotations

import pytest
from scipy.stats import chi2

from gyrostand.core.chisq import sup_chi2_sf
from gyrostand.core.diagnose.candidates import rank_candidates
from gyrostand.core.diagnose.reference import REPORT_ALPHA, reference_fit
from gyrostand.core.diagnose.results import TEST_GUARD
from gyrostand.core.ml.fit import ml
from gyrostand.core.profiles import chamber_profile
from gyrostand.workbench import open_subject, run_fit

from .framelike import frame_run


@pytest.fixture(scope="module")
def clean6h(tmp_path_factory):
    """benchmarks/false_alarm.py's clean 6-h run 52 (seed 1052): its temp_rate refit
    trades the rate against markov.beta (×1.26) for an LR of 9.3."""
    path = frame_run(tmp_path_factory.mktemp("guard") / "clean.csv", seed=1052, drop=0.01,
                     start_offset=0.37, end_cut=0.4, profile=chamber_profile(6.0))
    sub = open_subject(path)
    fit = ml(sub.samples, sub.model)
    ref = reference_fit(sub.samples, sub.model, fit)
    assert not ref.p_value < REPORT_ALPHA  # the model fits: the score is taken
    return sub, fit


def test_an_lr_beyond_its_law_is_held_to_the_score_tests_p(clean6h):
    sub, fit = clean6h
    by = {c.term: c for c in rank_candidates(sub.samples, sub.model, fit,
                                              ["temp_rate", "temp_lag"])}
    tr = by["temp_rate"]
    lr_p = sup_chi2_sf(tr.lr_stat, tr.df, tr.shape_lkc)
    assert tr.lr_stat > 8.0 and lr_p < 0.01  # by the LR alone: significant at 0.05/8 ...
    assert tr.score_stat is not None and tr.score_stat < 0.6 * tr.lr_stat
    assert tr.score_p is not None and tr.score_p > 0.05  # ... by the score: nothing
    assert tr.test == TEST_GUARD and tr.p_value == tr.score_p
    assert tr.to_dict()["test"] == TEST_GUARD and tr.to_dict()["p_value"] == tr.score_p
    # temp_lag's chord score guards its χ²(1 + 1) too; p is never below the LR's own
    lag = by["temp_lag"]
    assert lag.score_p is not None
    assert lag.p_value == pytest.approx(max(chi2.sf(lag.lr_stat, 2), lag.score_p),
                                        rel=1e-12)


def test_fit_add_gives_the_number_diagnose_gives(clean6h):
    """One number, one meaning: the fit step's p is the candidate's, guarded alike."""
    sub, fit = clean6h
    (tr,) = rank_candidates(sub.samples, sub.model, fit, ["temp_rate"])
    step = run_fit(sub, add=["temp_rate"], record=False)
    assert step.test == TEST_GUARD == tr.test
    assert step.p_value == pytest.approx(tr.p_value, rel=1e-9)


def test_a_real_effect_the_model_lacks_stays_significant(tmp_path):
    """A 4-h run with a trend of 1e-5 deg/h/s, where the saturated reference shows no lack
    of fit at the report's level: the score sees the trend from the null and the guarded
    p stays far below the Bonferroni level."""
    path = frame_run(tmp_path / "trend.csv", ["trend"], {"trend.c": 1e-5}, seed=6, drop=0.01)
    sub = open_subject(path)
    fit = ml(sub.samples, sub.model)
    ref = reference_fit(sub.samples, sub.model, fit)
    assert not ref.p_value < REPORT_ALPHA
    (c,) = rank_candidates(sub.samples, sub.model, fit, ["trend"])
    assert c.score_p is not None and c.score_p < 1e-4
    assert c.p_value < 1e-4 and c.p_value >= chi2.sf(c.lr_stat, 1)


def test_beside_a_random_walk_the_lr_stands(clean6h):
    """A random walk in the model takes the reference's time group away: the reference
    cannot show a slow misfit the walk absorbed, so no score guards the LR there."""
    from gyrostand.core.diagnose.candidates import step_score
    from gyrostand.core.model import Model

    sub, _ = clean6h
    m = Model.parse("markov,temp,bias,random_walk")
    fit = ml(sub.samples, m)
    ref = reference_fit(sub.samples, m, fit)
    assert not ref.p_value < REPORT_ALPHA
    assert not any(c.group == "time" for c in ref.basis.columns)
    assert step_score(sub.samples, m, fit, "temp_rate", ref) is None
    (tr,) = rank_candidates(sub.samples, m, fit, ["temp_rate"])
    assert tr.score_p is not None  # taken for the screen, not for the p
    assert tr.test != TEST_GUARD
    assert tr.p_value == pytest.approx(sup_chi2_sf(tr.lr_stat, tr.df, tr.shape_lkc), rel=1e-12)
