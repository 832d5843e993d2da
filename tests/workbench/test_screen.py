"""Candidates screened by score (LM) tests (:mod:`gyrostand.core.diagnose.screen`): the LM
statistic at the current fit agrees with the refit's LR, a candidate the screen rules out
is shown as screened and not refitted, and ``screen=False`` (``diagnose --no-screen``)
refits every candidate as before."""

import numpy as np
import pytest

from gyrostand.cli import build_parser
from gyrostand.core.data import Samples
from gyrostand.core.diagnose.candidates import rank_candidates
from gyrostand.core.diagnose.reference import reference_fit
from gyrostand.core.diagnose.screen import SCREEN_P, score_tests, to_refit
from gyrostand.core.ml.fit import ml
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate

BASE = "markov,temp,white,bias"
TRUTH = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
         "white.sigma": 0.02, "bias.b": 0.3}


def _run(hidden: dict[str, float], seed: int, hours: float = 2.0) -> Samples:
    terms = ",".join([BASE, *sorted({k.split(".")[0] for k in hidden})])
    s = simulate(Model.parse(terms), {**TRUTH, **hidden}, chamber_profile(hours), seed=seed)
    rng = np.random.default_rng(seed + 1)
    temp = np.round((s.temp + 0.01 * rng.standard_normal(len(s))) / 0.05) * 0.05
    return Samples.from_arrays(s.t, s.drift, temp)


def _case(hidden: dict[str, float], seed: int = 3):
    s = _run(hidden, seed=seed)
    m = Model.parse(BASE)
    fit = ml(s, m)
    ref = reference_fit(s, m, fit)
    also = {n: float(ref.fit.values[n]) for n in ref.noise_names}
    full = {c.term: c for c in rank_candidates(s, m, fit, ["temp2", "trend", "warmup"],
                                                also=also, screen=False)}
    return s, m, fit, full, also


@pytest.fixture(scope="module")
def hidden_trend():
    return _case({"trend.c": 2e-5})


def test_lm_agrees_with_the_lr(hidden_trend):
    s, m, fit, full, also = hidden_trend
    scores = score_tests(s, m, fit, ["temp2", "trend"])
    # a significant linear candidate: the LM at the fit within 20 % of its refit's LR
    # (measured 13.99 vs 14.26)
    assert full["trend"].lr_stat > 10
    assert scores["trend"].stat == pytest.approx(full["trend"].lr_stat, rel=0.2)
    assert scores["trend"].p_value < 1e-3 and scores["trend"].df == 1
    # with the reference's random part as a second point, never below it
    both = score_tests(s, m, fit, ["temp2", "trend"], also)
    assert both["trend"].stat >= scores["trend"].stat


def test_an_absent_candidate_has_lm_and_lr_near_zero():
    s = _run({}, seed=5)
    m = Model.parse(BASE)
    fit = ml(s, m)
    full = {c.term: c for c in rank_candidates(s, m, fit, ["temp2", "trend"],
                                                screen=False)}
    scores = score_tests(s, m, fit, ["temp2", "trend"])
    for t in ("temp2", "trend"):
        assert full[t].lr_stat < 4 and scores[t].stat < 4, (t, full[t].lr_stat)
        # measured: trend LM 1.81 vs LR 3.50 (the refit also moves the random part)
        assert abs(scores[t].stat - full[t].lr_stat) < 2.0


def test_a_misfit_the_random_part_absorbed_is_not_screened_away():
    # a hidden T²: at the fit the inflated random part whitens temp2's score to a
    # fraction of its refit's LR; at the reference's random part it is not
    s, m, fit, full, also = _case({"temp2.gamma2": 2e-5})
    at_fit = score_tests(s, m, fit, ["temp2"])["temp2"].stat
    assert at_fit < 0.5 * full["temp2"].lr_stat
    assert score_tests(s, m, fit, ["temp2"], also)["temp2"].stat > full["temp2"].lr_stat


def test_the_screen_keeps_the_significant_and_the_top_two():
    from gyrostand.core.diagnose.screen import Score

    sc = {t: Score(t, stat, 1, p, (), 0.0) for t, stat, p in
          (("a", 0.1, 0.75), ("b", 0.5, 0.48), ("c", 2.0, 0.16), ("d", 0.01, 0.92))}
    assert to_refit(sc) == {"c", "b"}  # c: p < 0.5 and first; b: p < 0.5 and second
    assert to_refit(sc, p_screen=0.8, top=0) == {"a", "b", "c"}
    assert to_refit(sc, top=0) == {"b", "c"} and to_refit(sc, p_screen=0.2, top=0) == {"c"}
    assert SCREEN_P == 0.5


def test_a_screened_candidate_is_shown_as_such():
    s = _run({}, seed=6)  # clean: score p temp2 0.52, trend 0.85, warmup 0.92
    m = Model.parse(BASE)
    fit = ml(s, m)
    terms = ["temp2", "trend", "warmup"]
    full = {c.term: c for c in rank_candidates(s, m, fit, terms, screen=False)}
    cands = rank_candidates(s, m, fit, terms)
    by = {c.term: c for c in cands}
    # the top two by score are refitted: their LR and p are the full refit's
    for t in ("temp2", "trend"):
        assert not by[t].screened and by[t].lr_stat == full[t].lr_stat
        assert by[t].p_value == full[t].p_value and by[t].score_p is not None
    c = by["warmup"]
    assert c.screened and c.score_p is not None and c.score_p >= SCREEN_P and not c.ranked
    assert c.result is None and c.effect == {} and c.lr_stat == c.score_stat
    assert c.shape_lkc == full["warmup"].shape_lkc  # the LR's calibration, one pass
    assert "screened (score test)" in c.note and cands[-1] is c
    d = c.to_dict()
    assert d["screened"] is True and d["score_stat"] == c.score_stat
    assert {"lr_stat", "df", "p_value", "delta_aic", "note"} <= set(d)


def test_no_screen_refits_every_candidate_as_before(hidden_trend):
    s, m, fit, full, also = hidden_trend
    assert not any(c.screened or c.score_stat is not None for c in full.values())
    assert all(c.result is not None for c in full.values())
    args = build_parser().parse_args(["diagnose", "run.csv", "--no-screen"])
    assert args.no_screen is True
    assert build_parser().parse_args(["diagnose", "run.csv"]).no_screen is False
