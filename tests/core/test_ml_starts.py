"""Where ML starts, and what one ML problem reuses (#25 item 2: diagnose's candidate refits).

A refit from a neighbouring model's optimum (``ml(..., start=fit.values, grid=False)``)
starts only from that optimum and from scans of the parameters it lacks, not from the whole
start grid, and reaches the optimum the grid-started fit reaches. An ML problem keeps its
filter input ``[y, X]`` by the parameters its regressors depend on: every point — moving a
rate, a time constant, a width, a noise level or a coefficient — gives the same Gram matrix
as a problem that computes everything afresh.
"""

from __future__ import annotations

import numpy as np

from gyrostand.core.data import Samples
from gyrostand.core.ml.fit import SCAN_POINTS, Problem, ml
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate

TRUTH = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
         "white.sigma": 0.02, "bias.b": 0.3, "temp_rate.k": 5.0}


def _run(hours: float = 2.0, seed: int = 7) -> Samples:
    s = simulate(Model.parse("markov,temp,bias,temp_rate"), TRUTH, chamber_profile(hours),
                 seed=seed)
    # the sensor quantised to 0.05 degC, as a stand's
    return Samples.from_arrays(s.t, s.drift, np.round(s.temp / 0.05) * 0.05)


def test_a_refit_without_the_grid_starts_from_the_fit_and_reaches_the_same_optimum():
    s = _run()
    base = ml(s, Model.parse("markov,temp,bias,white"))
    bigger = Model.parse("markov,temp,bias,white,temp_rate")
    full = ml(s, bigger, start=base.values)
    fast = ml(s, bigger, start=base.values, grid=False)
    # the base's optimum, and temp_rate.tau (new) scanned over its range with it
    assert fast.info["start_points"] == 1 + SCAN_POINTS
    assert full.info["start_points"] > fast.info["start_points"] + 10
    assert fast.info["evaluations"] < full.info["evaluations"]
    assert full.loglik is not None and fast.loglik is not None
    assert abs(fast.loglik - full.loglik) < 1e-3, (fast.loglik, full.loglik)
    assert abs(fast.value("temp_rate.k") - full.value("temp_rate.k")) < 1e-3 * full.std(
        "temp_rate.k")
    # the effect is found (truth 5): the refit is a fit, not its start
    assert abs(fast.value("temp_rate.k") - 5.0) < 3 * fast.std("temp_rate.k")


def test_without_a_start_the_grid_is_used_whatever_grid_says():
    s = _run(1.0)
    model = Model.parse("markov,temp,bias,white")
    a, b = ml(s, model), ml(s, model, grid=False)
    assert a.info["start_points"] == b.info["start_points"] > 1
    assert a.loglik == b.loglik


def test_the_kept_filter_input_gives_the_same_gram_as_a_fresh_problem(monkeypatch):
    s = _run(1.0)
    model = Model.parse("markov,temp,bias,white,temp_rate,hysteresis")
    kept = Problem(model, s, {})
    rng = np.random.default_rng(3)
    p0 = {"markov.beta": 0.01, "markov.sigma": 0.05, "white.sigma": 0.02,
          "temp.gamma": -5e-4, "bias.b": 0.3, "temp_rate.k": 5.0, "temp_rate.tau": 300.0,
          "hysteresis.h": 0.1, "hysteresis.tau": 60.0, "hysteresis.w": 0.003}
    builds = []
    real = Model.filter_input  # the kept input's builder (a fresh problem's too)
    monkeypatch.setattr(Model, "filter_input", lambda self, p, ctx, y: builds.append(
        self is model) or real(self, p, ctx, y))
    moved, shaped = 0, 0
    for i in range(20):  # 6 distinct rate/shape points: fewer than the 8 kept
        p = dict(p0)
        # one parameter moved at a time, as a gradient's and a Hessian's points do, and
        # now and then back to p0 (a point whose [y, X] is kept)
        name = sorted(p0)[i % len(p0)]
        if i % 3:
            p[name] *= float(np.exp(0.2 * rng.standard_normal()))
            moved += 1
            shaped += model.kind(name) not in ("std", "linear")
        before = sum(builds)
        G, slogf, n = kept.gram(p)
        own = sum(builds) - before
        G1, slogf1, n1 = Problem(model, s, {}).gram(p)
        assert n == n1 and slogf == slogf1, name
        np.testing.assert_array_equal(G, G1, err_msg=name)
        if not (i % 3 and model.kind(name) not in ("std", "linear")) and i > 0:
            assert own == 0, name  # a noise level, a coefficient or p0: the kept input
    assert moved > 10
    # the regressors were built for p0 and for each point that moved a rate or a shape
    assert sum(builds) - 20 == 1 + shaped, (sum(builds), shaped)


def test_a_new_noise_level_alone_is_scanned_down_to_its_bound():
    """A refit adding a random walk (one new noise level, no new rate) scans it over its
    range, its lower bound — the smaller model itself — included: with no walk in the data
    the search starts at the bound and stops there, where from mid-range it crawled 13-26
    iterations to it; with a walk it reaches the grid-started fit's optimum."""
    base_model = Model.parse("markov,temp,bias,white")
    bigger = base_model.add("random_walk")
    # none: the data of the module's run (a temp_rate effect, no walk)
    s = _run()
    base = ml(s, base_model)
    fast = ml(s, bigger, start=base.values, grid=False, hessian_passes=1)
    assert fast.info["start_points"] == 1 + SCAN_POINTS
    assert fast.info["iterations"] <= 2
    assert abs(fast.loglik - base.loglik) < 1e-6  # the smaller model's own likelihood
    assert "random_walk.q" in fast.info["at_bound"]
    # a walk: the same optimum as from the whole start grid
    w = simulate(bigger, {**TRUTH, "random_walk.q": 2e-3}, chamber_profile(2.0), seed=8)
    w = Samples.from_arrays(w.t, w.drift, np.round(w.temp / 0.05) * 0.05)
    base = ml(w, base_model)
    fast = ml(w, bigger, start=base.values, grid=False, hessian_passes=1)
    full = ml(w, bigger)
    assert 2 * (fast.loglik - base.loglik) > 10.0  # the walk is there to find
    assert fast.loglik >= full.loglik - 1e-3
    assert abs(np.log(fast.values["random_walk.q"] / 2e-3)) < np.log(3)


def test_the_covariance_is_computed_for_the_kept_fit_only(monkeypatch):
    """A shape stopped at its search bound gets a refit at its plain shape (τ = 0); the
    observed information (the costliest part of a refit after its search) is computed
    once, for whichever of the two fits is kept, and its stds are the kept fit's."""
    from gyrostand.core.ml import fit

    s = _run(seed=2)  # a run whose temp_rate.tau stops at its lower bound
    base = ml(s, Model.parse("markov,temp,bias,white"))
    bigger = Model.parse("markov,temp,bias,white,temp_rate")
    calls = []
    real = fit.observed_covariance
    monkeypatch.setattr(fit, "observed_covariance", lambda *a, **k: calls.append(a[2]) or
                        real(*a, **k))
    r = ml(s, bigger, start=base.values, grid=False, hessian_passes=1)
    assert "temp_rate.tau" in r.info["plain"]  # the data's lag is none: the plain shape won
    assert len(calls) == 1
    assert calls[0]["temp_rate.tau"] == r.value("temp_rate.tau") == 0.0  # the kept fit's point
    assert r.parameters["temp_rate.tau"].fixed and r.std("temp_rate.k") > 0
    assert r.covariance is not None and "temp_rate.tau" not in r.cov_names


def test_a_plain_shape_reads_as_one_warning_and_keeps_both_in_the_fit():
    """Where the plain shape won, the text shows its warning alone (it names the bound and
    why the plain shape was kept); the fit keeps the bound's too, which identification
    reads (a shape at a bound where its shape is still physical)."""
    from gyrostand.core.summary import fit_table, shown_warnings

    s = _run(seed=2)  # a run whose temp_rate.tau stops at its lower bound
    base = ml(s, Model.parse("markov,temp,bias,white"))
    r = ml(s, Model.parse("markov,temp,bias,white,temp_rate"), start=base.values, grid=False,
           hessian_passes=1)
    bound = [w for w in r.warnings if "temp_rate.tau is at its lower search bound" in w]
    plain = [w for w in r.warnings if "temp_rate.tau is at its plain shape" in w]
    assert len(bound) == 1 and len(plain) == 1
    shown = shown_warnings(r.warnings)
    assert plain[0] in shown and bound[0] not in shown
    assert [w for w in r.warnings if w not in bound] == shown  # nothing else dropped
    text = fit_table(r)
    assert "at its plain shape" in text and "at its lower search bound" not in text
    # another parameter's bound stays
    other = "ml: markov.beta is at its lower search bound (x)"
    assert shown_warnings([*r.warnings, other])[-1] == other


def test_a_noise_level_at_zero_takes_the_others_covariance_from_the_smaller_fit():
    """A candidate that adds a noise level the data do not want (a random walk on a run
    without one: its level at 0, the fit the smaller one): with ``known`` the Hessian is
    the added level's own curvature only — its std the number the whole Hessian gives,
    bit for bit — and the others' covariance is the smaller fit's. A level the data want
    (a walk there) gets the whole Hessian either way."""
    small = Model.parse("markov,temp,bias,white")
    bigger = small.add("random_walk")
    s = simulate(small, TRUTH, chamber_profile(2.0), seed=11)
    base = ml(s, small)
    full = ml(s, bigger, start=base.values, hessian_passes=1, grid=False)
    fast = ml(s, bigger, start=base.values, hessian_passes=1, grid=False, known=base)
    assert full.loglik == fast.loglik and full.values == fast.values
    assert 2 * (full.loglik - base.loglik) < 1e-3  # the level at its bound
    q = "random_walk.q"
    assert fast.std(q) == full.std(q) > 0
    for n in base.cov_names:
        assert fast.std(n) == base.std(n)
    # a deterministic term is a model of its own, whatever its fit: the whole Hessian
    trend = small.add("trend")
    full = ml(s, trend, start=base.values, hessian_passes=1, grid=False)
    fast = ml(s, trend, start=base.values, hessian_passes=1, grid=False, known=base)
    assert np.array_equal(full.covariance, fast.covariance)
    walk = simulate(bigger, {**TRUTH, "random_walk.q": 3e-3}, chamber_profile(2.0), seed=12)
    base = ml(walk, small)
    full = ml(walk, bigger, start=base.values, hessian_passes=1, grid=False)
    fast = ml(walk, bigger, start=base.values, hessian_passes=1, grid=False, known=base)
    assert full.values[q] > 1e-4  # the walk found: an interior optimum
    assert np.array_equal(full.covariance, fast.covariance)
