"""The calibrated test of a candidate with a shape (a lag τ, a switching width w, a
warm-up's τ): not identified when its coefficient is 0, so its LR — the supremum over the
shape — is referred to the supremum of a χ² process (Euler characteristic / Davies 1987,
:func:`gyrostand.core.chisq.sup_chi2_sf`) with the curvatures of the shape's range
(:func:`gyrostand.core.diagnose.candidates.shape_curvatures`), not to χ²(1 + shapes).

The tail is checked against a Monte Carlo of the very process: Z(θ) = u(θ)'ε with ε iid
N(0, 1), u(θ) the whitened, projected regressor on the refit's grid, on a clean 2-h run
built from frames (jitter, drops, partial first/last bins, quantized temperature).
"""

import itertools
import math

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from gyrostand.core.chisq import chi2_sf, sup_chi2_sf
from gyrostand.core.diagnose.candidates import rank_candidates
from gyrostand.core.diagnose.results import TEST_CHI2, TEST_GUARD, TEST_MIXTURE, TEST_SUP
from gyrostand.core.diagnose.shapes import shape_curvatures, shape_grid, shape_params
from gyrostand.core.ml.fit import ml
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.workbench import open_subject

from .framelike import frame_run


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    path = frame_run(tmp_path_factory.mktemp("cal") / "clean.csv", seed=1000, drop=0.01,
                     start_offset=0.37, end_cut=0.4, profile=chamber_profile(2.0))
    sub = open_subject(path)
    return sub, ml(sub.samples, sub.model)


def test_sup_tail_formula_matches_davies_and_chi2():
    # no shape: χ²(df) itself
    assert sup_chi2_sf(7.0, 1, ()) == pytest.approx(chi2_sf(7.0, 1))
    # one dimension, df = 1: P(χ²₁ > u) + L₁ e^(−u/2) / π (Davies' bound, V = √(2/π) L₁)
    for u, length in ((5.0, 2.0), (15.0, 0.8), (24.2, 1.46)):
        assert sup_chi2_sf(u, 1, (length,)) == pytest.approx(
            chi2_sf(u, 1) + length * math.exp(-u / 2) / math.pi, rel=1e-12)
    # df = 2: ρ₁ = e^(−u/2) √u / √(2π)
    assert sup_chi2_sf(10.0, 2, (1.5,)) == pytest.approx(
        chi2_sf(10.0, 2) + 1.5 * math.exp(-5.0) * math.sqrt(10.0 / (2 * math.pi)))
    # two dimensions, df = 1: ρ₂ = √u e^(−u/2) / (√2 π^(3/2)) (twice the Gaussian field's)
    assert sup_chi2_sf(12.0, 1, (0.0, 3.0)) == pytest.approx(
        chi2_sf(12.0, 1) + 3.0 * math.sqrt(12.0) * math.exp(-6.0) / (math.sqrt(2) * math.pi ** 1.5))
    assert sup_chi2_sf(0.0, 1, (3.0,)) == 1.0 and sup_chi2_sf(0.5, 1, (50.0, 50.0)) == 1.0
    with pytest.raises(ValueError, match="3 dimensions"):
        sup_chi2_sf(5.0, 1, (1.0, 1.0, 1.0))


def test_which_candidates_have_a_shape():
    m = Model.parse("markov,temp,white,bias")
    assert shape_params(m.add("temp_rate"), "temp_rate") == ("temp_rate.tau",)
    assert shape_params(m.add("hysteresis"), "hysteresis") == ("hysteresis.tau",
                                                               "hysteresis.w")
    assert shape_params(m.add("warmup"), "warmup") == ("warmup.tau",)
    for term in ("trend", "temp2", "temp_lag", "random_walk", "markov2"):
        assert shape_params(m.add(term), term) == ()


@pytest.mark.parametrize("term", ["temp_rate", "warmup", "hysteresis", "temp_lag"])
def test_sup_tail_matches_a_monte_carlo_of_the_score_process(term, clean):
    """The curvature formula against the grid's own score process (temp_lag: its chord,
    the score that guards its LR)."""
    sub, fit = clean
    lkc = shape_curvatures(sub.samples, sub.model, fit, term)
    axes, unit = shape_grid(sub.samples, sub.model, fit, term)
    U = unit(list(itertools.product(*axes)))
    assert U.shape[1] == int(np.prod([a.size for a in axes]))
    assert np.allclose(np.linalg.norm(U, axis=0), 1.0)
    rng = np.random.default_rng(11)
    draws = 3000 if len(axes) == 1 else 800
    sup = np.empty(draws)
    with threadpool_limits(limits=1, user_api="blas"):
        for i in range(0, draws, 200):
            eps = rng.standard_normal((200, U.shape[0]))
            sup[i:i + 200] = np.max((eps @ U) ** 2, axis=1)
    for u in (6.0, 9.0):
        p = sup_chi2_sf(u, 1, lkc)
        seen = float(np.mean(sup > u))
        sd = math.sqrt(p * (1 - p) / draws)
        print(f"{term}: L = {lkc}, P(sup > {u:g}): formula {p:.4f}, Monte Carlo {seen:.4f}, "
              f"χ²({1 + len(axes)}) {chi2_sf(u, 1 + len(axes)):.4f}")
        if len(axes) == 1:
            assert abs(seen - p) < 4 * sd, (u, seen, p)
        else:
            # the grid's maximum is below the continuum's, and the narrowest width's rough
            # edge makes the Euler characteristic an overestimate: conservative, not by 2x
            assert seen - 4 * sd < p < 2.0 * seen + 4 * sd, (u, seen, p)
    # the supremum exceeds χ²(1): the shape's search costs something
    assert sup.mean() > 1.2


def test_the_table_says_which_test_and_df_shown_is_df_used(clean):
    sub, fit = clean
    cands = {c.term: c for c in rank_candidates(sub.samples, sub.model, fit,
                                                 ["temp_rate", "trend", "random_walk"])}
    # each p is its LR's by the law named, or (no lack of fit here) the score test's where
    # that is larger (:func:`~gyrostand.core.diagnose.candidates.guarded`), named so
    tr = cands["temp_rate"]
    assert tr.df == 1 and len(tr.shape_lkc) == 1 and tr.score_p is not None
    lr_p = sup_chi2_sf(tr.lr_stat, tr.df, tr.shape_lkc)
    assert tr.p_value == pytest.approx(max(lr_p, tr.score_p))
    assert tr.test == (TEST_GUARD if tr.score_p > lr_p else TEST_SUP)
    trend = cands["trend"]
    assert trend.df == 1 and trend.score_p is not None
    lr_p = chi2_sf(trend.lr_stat, 1)
    assert trend.p_value == pytest.approx(max(lr_p, trend.score_p))
    assert trend.test == (TEST_GUARD if trend.score_p > lr_p else TEST_CHI2)
    rw = cands["random_walk"]
    assert rw.test == TEST_MIXTURE and rw.score_p is None
    assert rw.p_value == pytest.approx(0.5 * chi2_sf(rw.lr_stat, rw.df))
    d = tr.to_dict()
    assert d["test"] == tr.test and d["df"] == 1 and d["shape_lkc"] == list(tr.shape_lkc)


def test_the_efficient_score_is_the_refit_lr_at_a_fixed_shape(clean):
    """The metric behind the curvatures: the current parameters (β, γ) readjust with the
    candidate, so the LR at a fixed lag is the efficient score x'ε / √(x'Mx), not the
    score taken orthogonal to the regressors alone (about half the LR on these runs)."""
    from gyrostand.core.diagnose.shapes import _efficient_metric, mean_tangents
    from gyrostand.core.model import context
    from gyrostand.core.validate import prepare

    sub, fit = clean
    model = sub.model
    used = prepare(sub.samples, "test")
    ctx = context(used, model)
    e, f = model.innovations(fit.values, used)
    ok = np.isfinite(e) & (f > 0)
    eps = e[ok] / np.sqrt(f[ok])
    names, tangents = mean_tangents(model, fit, ctx)
    assert "markov.beta" in names and "temp.gamma" in names
    tau = 3.0
    x = model.add("temp_rate").term_of("temp_rate.k").regressors(
        {**fit.values, "temp_rate.k": 0.0, "temp_rate.tau": tau}, ctx)["temp_rate.k"]
    E, f2 = model.filter_columns(fit.values, used, np.column_stack([tangents, x]))
    W = E[ok, 1:] / np.sqrt(f2[ok])[:, None]
    T, c = W[:, :-1], W[:, -1]
    K, d = _efficient_metric(T, names, fit)
    assert K is not None
    cm = c - K @ (d * (K.T @ c))
    efficient = float((c @ eps) ** 2 / (cm @ cm))
    Q = np.linalg.qr(T[:, :2])[0]  # the regressors alone (temp, bias)
    cp = c - Q @ (Q.T @ c)
    plain = float((cp @ eps) ** 2 / (cp @ cp))
    r = ml(sub.samples, model.add("temp_rate"), fixed={"temp_rate.tau": tau}, start=fit.values)
    lr = 2 * (r.loglik - fit.loglik)
    print(f"temp_rate at τ = {tau:g} s: refit LR {lr:.3f}, efficient score² {efficient:.3f}, "
          f"regressors-only score² {plain:.3f}")
    assert abs(efficient - lr) < 0.1 + 0.1 * lr
    assert plain < 0.8 * lr  # what the regressors-only metric missed


def test_the_curvatures_are_extrapolated_to_a_fine_grid(clean, monkeypatch):
    """Polygon lengths and flat-triangle areas on the grid fall short by O(h²); extrapolated
    from the grid and its every other point (sizes odd, so the grids nest) they come within
    3 % of a 4x finer grid's, closer than the plain 81 x 9 polygon used before."""
    import gyrostand.core.diagnose.shapes as shapes

    sub, fit = clean
    assert shapes.SHAPE_POINTS % 2 == 1 and all(k % 2 == 1 for k in shapes.SHAPE_POINTS_2D)
    got = {t: shape_curvatures(sub.samples, sub.model, fit, t)
           for t in ("temp_rate", "hysteresis")}
    monkeypatch.setattr(shapes, "SHAPE_POINTS", 4 * shapes.SHAPE_POINTS - 3)
    monkeypatch.setattr(shapes, "SHAPE_POINTS_2D", (241, 25))
    fine = {t: shape_curvatures(sub.samples, sub.model, fit, t) for t in got}
    for term, lkc in got.items():
        assert len(lkc) == len(fine[term])
        for a, b in zip(lkc, fine[term], strict=True):
            assert a == pytest.approx(b, rel=0.03), (term, lkc, fine[term])
    # the plain polygon on the grid of before: further from the fine grid's curvatures
    monkeypatch.setattr(shapes, "_extrapolated", lambda fine, coarse: fine)
    monkeypatch.setattr(shapes, "SHAPE_POINTS_2D", (81, 9))
    plain = shape_curvatures(sub.samples, sub.model, fit, "hysteresis")
    for p, g, f in zip(plain, got["hysteresis"], fine["hysteresis"], strict=True):
        assert p < g and abs(g - f) < abs(p - f), (plain, got["hysteresis"], fine["hysteresis"])
