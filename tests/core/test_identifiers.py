"""Seeded recovery of known parameters by each identifier, within stated tolerances."""

import math

import numpy as np
import pytest

from gyrostand.core.data import Samples
from gyrostand.core.lkf.filter import OnlineLKF, lkf
from gyrostand.core.lsq.fit import lsq
from gyrostand.core.ml.fit import ml
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile, paper_profile
from gyrostand.core.simulation import simulate
from gyrostand.errors import ModelError

from ..conftest import truth

SUM = "markov,temp,bias,random_walk"


def within(result, p, name, n_std=4.0, rel=None):
    """|estimate − truth| ≤ n_std · reported std (and ≤ rel · |truth| when given)."""
    v, s = result.value(name), result.std(name)
    err = abs(v - p[name])
    assert err <= n_std * s, f"{name}: {v:.6g} vs truth {p[name]:.6g}, std {s:.3g}"
    if rel is not None:
        assert err <= rel * abs(p[name]), f"{name}: {v:.6g} vs truth {p[name]:.6g}"


# ---- least squares ---------------------------------------------------------------------

@pytest.mark.parametrize("case", ["C1", "C3"])
def test_lsq_recovers_the_paper_cases(case, base_model):
    p = truth(case)
    s = simulate(base_model, p, paper_profile(), seed=21)
    r = lsq(s, base_model)
    within(r, p, "markov.beta", rel=0.25)
    within(r, p, "temp.gamma", rel=0.25)
    assert r.value("white.sigma") < 0.02  # no measurement noise in the data
    assert r.loglik is None and r.method == "lsq"


def test_lsq_with_bias_and_both_regressors():
    m = Model.parse("markov,temp,bias")
    p = truth("C1", **{"bias.b": 0.5})
    s = simulate(m, p, chamber_profile(2), seed=22)
    r = lsq(s, m)
    within(r, p, "markov.beta", rel=0.1)
    within(r, p, "temp.gamma", rel=0.1)
    within(r, p, "bias.b")
    r_lit = lsq(s, m, regressor="current")
    assert r_lit.info["regressor"] == "current"
    assert r_lit.value("markov.beta") != r.value("markov.beta")


def test_lsq_is_biased_by_measurement_noise_and_says_so(base_model):
    """The errors-in-variables effect (MODEL.md): σ_v = σ/2 biases LSQ's β upward."""
    p = truth("C2", sigma_v=0.05)
    s = simulate(base_model, p, paper_profile(), duration=2000, seed=23)
    r = lsq(s, base_model)
    assert any("measurement noise" in w for w in r.warnings)
    assert r.value("white.sigma") == pytest.approx(0.05, rel=0.3)


def test_lsq_refuses_a_sum_of_processes():
    s = simulate(Model.parse("markov,temp"), truth("C1"), paper_profile(), seed=1)
    with pytest.raises(ModelError, match=r"lsq cannot represent a sum of random processes "
                                         r"\(markov \+ random_walk\).*lkf or --method ml"):
        lsq(s, Model.parse(SUM))
    with pytest.raises(ModelError, match=r"markov \+ markov2"):
        lsq(s, Model.parse("markov,temp,markov2"))


# ---- maximum likelihood ----------------------------------------------------------------

@pytest.mark.parametrize("case", ["C1", "C2", "C3"])
@pytest.mark.parametrize("sigma_known", [True, False])
def test_ml_recovers_the_paper_cases(case, sigma_known, base_model):
    p = truth(case)
    s = simulate(base_model, p, paper_profile(), seed=31)
    r = ml(s, base_model, sigma=0.1 if sigma_known else None)
    within(r, p, "markov.beta", rel=0.3)
    within(r, p, "temp.gamma", rel=0.3)
    if not sigma_known:
        within(r, p, "markov.sigma", rel=0.3)
    else:
        assert r.parameters["markov.sigma"].fixed
    assert np.isfinite(r.loglik)
    assert r.loglik == pytest.approx(base_model.loglik(r.values, s), rel=1e-12)


def test_ml_recovers_every_parameter_of_a_six_hour_run():
    m = Model.parse("markov,temp,bias")
    p = truth("C1", sigma_v=0.05, **{"bias.b": 0.5})
    s = simulate(m, p, chamber_profile(6), seed=32)
    r = ml(s, m)
    for name in m.param_names:
        within(r, p, name, rel=0.1)
    assert r.info["converged"]


def test_ml_is_a_maximum():
    """No parameter nudge raises the likelihood (to the optimiser's tolerance)."""
    m = Model.parse("markov,temp,bias")
    p = truth("C1", sigma_v=0.03, **{"bias.b": 0.2})
    s = simulate(m, p, paper_profile(), seed=33)
    r = ml(s, m)
    best = r.loglik
    for name in m.param_names:
        for f in (0.98, 1.02):
            q = dict(r.values)
            q[name] *= f
            assert m.loglik(q, s) <= best + 1e-6


def test_ml_handles_a_sum_of_processes():
    m = Model.parse(SUM)
    p = truth("C1", sigma_v=0.02, **{"bias.b": 0.3, "random_walk.q": 0.002})
    s = simulate(m, p, chamber_profile(6), seed=34)
    r = ml(s, m)
    within(r, p, "markov.beta", rel=0.15)
    within(r, p, "temp.gamma", rel=0.15)
    within(r, p, "random_walk.q", rel=0.5)
    within(r, p, "white.sigma", rel=0.2)
    base = ml(s, Model.parse("markov,temp,bias"))
    assert r.loglik - base.loglik > 10  # the random walk is there and the LR sees it


def test_ml_handles_markov2():
    m = Model.parse("markov,temp,markov2")
    p = truth("C1", sigma_v=0.01, **{"markov2.beta": 0.3, "markov2.sigma": 0.08})
    s = simulate(m, p, chamber_profile(6), seed=35)
    r = ml(s, m)
    within(r, p, "markov.beta", rel=0.2)
    within(r, p, "temp.gamma", rel=0.2)
    within(r, p, "markov2.beta", rel=0.3)
    within(r, p, "markov2.sigma", rel=0.2)


def test_ml_fixed_parameters_are_reported_fixed(base_model, c1_samples):
    r = ml(c1_samples, base_model, fixed={"white.sigma": 1e-4, "markov.sigma": 0.1})
    assert r.parameters["white.sigma"].fixed and r.parameters["white.sigma"].std == 0
    with pytest.raises(ModelError, match="cannot fix bias.b"):
        ml(c1_samples, base_model, fixed={"bias.b": 0.0})


# ---- linearised Kalman filter ----------------------------------------------------------

def test_online_lkf_equals_batch_lkf():
    m = Model.parse("markov,temp,bias")
    p = truth("C1", sigma_v=0.01, **{"bias.b": 0.2})
    s = simulate(m, p, paper_profile(), seed=41)
    y = s.drift.copy()
    y[[0, 1, 500, 501, 502, 1300]] = np.nan  # gaps, including the start
    s = Samples.from_arrays(s.t, y, s.temp)
    held = {"markov.sigma": 0.1, "white.sigma": 0.01}
    ps = {"markov.beta": 1.0, "temp.gamma": 0.5, "bias.b": 10.0}
    batch = lkf(s, m, variant="paper", beta0=0.02, gamma0=-0.005, held=held, prior_std=ps)
    online = OnlineLKF(m, 1.0, beta0=0.02, gamma0=-0.005, held=held, prior_std=ps)
    for k in range(len(s)):
        e, f = online.update(float(s.drift[k]), float(s.temp[k]))
        assert (math.isnan(e) and math.isnan(batch.residuals[k])) or e == batch.residuals[k]
        for name, (v, sd) in online.estimates.items():
            assert v == batch.history[name][k]
            assert sd == batch.history[name + ":std"][k]
    for name, (v, sd) in online.estimates.items():
        assert v == batch.value(name) and sd == batch.std(name)
    np.testing.assert_array_equal(online.covariance[1:4, 1:4], batch.covariance)


@pytest.mark.parametrize("case", ["C1", "C3"])
def test_iterated_lkf_recovers_the_paper_cases(case, base_model):
    p = truth(case)
    s = simulate(base_model, p, paper_profile(), seed=42)
    r = lkf(s, base_model, variant="paper", sigma=0.1, held={"white.sigma": 0.0}, iterate=True)
    assert r.info["settled"]
    assert not any("ended at the linearisation point" in w for w in r.warnings)
    within(r, p, "markov.beta", rel=0.3)
    within(r, p, "temp.gamma", rel=0.3)


def test_single_pass_lkf_depends_on_its_linearisation_point(base_model):
    """MODEL.md: at the paper's 1e-4 the single pass is badly biased; near the truth it is not."""
    p = truth("C1")
    s = simulate(base_model, p, paper_profile(), seed=43)
    held = {"white.sigma": 0.0}
    far = lkf(s, base_model, variant="paper", sigma=0.1, held=held)
    near = lkf(s, base_model, variant="paper", sigma=0.1, held=held, beta0=0.8 * 0.0333,
               gamma0=0.8 * -0.01)
    assert any(w.startswith("lkf (paper variant): beta =") for w in far.warnings)
    assert not any("paper variant" in w for w in near.warnings)
    assert abs(far.value("markov.beta") / 0.0333 - 1) > 0.8
    assert abs(near.value("markov.beta") / 0.0333 - 1) < 0.3


@pytest.mark.parametrize("variant", ["paper", "relin"])
def test_lkf_handles_a_sum_of_processes(variant):
    m = Model.parse(SUM)
    p = truth("C1", sigma_v=0.02, **{"bias.b": 0.3, "random_walk.q": 0.002})
    s = simulate(m, p, chamber_profile(3), seed=44)
    r = lkf(s, m, variant=variant, iterate=True)
    assert r.info["held_from"] == "ml"
    assert r.parameters["random_walk.q"].fixed
    within(r, p, "markov.beta", rel=0.3)
    within(r, p, "temp.gamma", rel=0.3)


def test_lkf_history_tracks_convergence(base_model, c1_samples):
    r = lkf(c1_samples, base_model, variant="paper", sigma=0.1, held={"white.sigma": 0.0}, beta0=0.03,
            gamma0=-0.009)
    sd = r.history["markov.beta:std"]
    assert sd[10] > sd[-1] and r.history["markov.beta"].shape == (len(c1_samples),)


def test_online_lsq_equals_batch_lsq():
    from gyrostand.core.lsq.fit import OnlineLSQ

    m = Model.parse("markov,temp,bias")
    p = truth("C1", sigma_v=0.02, **{"bias.b": 0.2})
    s = simulate(m, p, paper_profile(), seed=45)
    y = s.drift.copy()
    y[[0, 300, 301, 900]] = np.nan
    s = Samples.from_arrays(s.t, y, s.temp)
    online = OnlineLSQ(m, 1.0)
    for k in range(len(s)):
        online.update(float(s.drift[k]), float(s.temp[k]))
    est, _ = online.estimates()
    batch = lsq(s, m)
    for name in m.param_names:
        assert est[name].value == pytest.approx(batch.value(name), rel=1e-9)
        assert est[name].std == pytest.approx(batch.std(name), rel=1e-9)


def test_ml_finds_the_global_maximum_under_measurement_noise():
    """Regression (paper_tables c-known C4 run 152): least squares seeds β ≈ 0.4 (errors in
    variables), and β has a spurious likelihood maximum near 0.33 1/s, 460 ln-L units below
    the truth's; the start grid's wide β axis and basin-diverse local starts find the true one."""
    m = Model.parse("markov,temp")
    p = truth("C4", sigma_v=0.05)
    state = np.random.SeedSequence([2024, 1, 3, 152]).generate_state(2)
    s = simulate(m, p, paper_profile(), seed=np.random.default_rng(state))
    r = ml(s, m, sigma=0.1)
    assert r.loglik >= m.loglik(p, s)
    within(r, p, "markov.beta", rel=0.5)


def test_iterated_lkf_flags_an_implausible_fixed_point(base_model):
    """C2 with the paper's start: the iteration may settle far along the γ/β ridge; the
    result must say so rather than report a 'settled' β of several 1/s silently. A fit it
    does not flag recovers the truth: β within 4 of its stds (the linearization's stds,
    optimistic at C2's low signal: seed 510 is 3.4 std off) and the static thermal gain
    γ/β, which the ridge leaves identifiable, within 10 % (all 11 unflagged seeds: ≤ 7 %)."""
    p = truth("C2")
    gain = p["temp.gamma"] / p["markov.beta"]
    for seed in range(12):
        s = simulate(base_model, p, paper_profile(), seed=500 + seed)
        r = lkf(s, base_model, variant="paper", sigma=0.1, held={"white.sigma": 0.0},
                iterate=True)
        b = r.value("markov.beta")
        assert r.info["linearization"]["markov.beta"] <= 1.0  # the point stays below 1/Δt
        flagged = any("spurious fixed point" in w or "did not settle" in w
                      for w in r.warnings)
        if b > 10 * p["markov.beta"]:
            assert flagged, (seed, b, r.warnings)
        if not flagged:
            assert abs(b - p["markov.beta"]) <= 4 * r.std("markov.beta"), (seed, b)
            assert r.value("temp.gamma") / b == pytest.approx(gain, rel=0.10), seed


LINEAR_EFFECTS = {"temp_rate": {"temp_rate.k": 5.0}, "hysteresis": {"hysteresis.h": 0.05},
                  "trend": {"trend.c": 1e-5}, "warmup": {"warmup.A": 0.5, "warmup.tau": 900.0},
                  "temp2": {"temp2.gamma2": 5e-6}}


@pytest.mark.parametrize("variant", ["paper", "relin"])
@pytest.mark.parametrize("term", list(LINEAR_EFFECTS))
def test_lkf_estimates_the_linear_effect_terms(term, variant):
    """Where the paper's linearisation applies (coefficients of inputs and outputs), the
    LKF carries them as correction states; the warm-up's τ is held (at the ML value)."""
    m = Model.parse(["markov", "temp", "bias", term])
    p = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
         "white.sigma": 0.02, "bias.b": 0.3, **LINEAR_EFFECTS[term]}
    s = simulate(m, p, chamber_profile(4), seed=11)
    r = lkf(s, m, variant=variant, iterate=True, beta0=0.02, gamma0=-0.001)
    assert r.info["settled"]
    name = next(iter(LINEAR_EFFECTS[term]))
    if variant == "paper":
        within(r, p, name, rel=0.3)
        within(r, p, "temp.gamma", rel=0.3)
        return
    # relin: ML's estimate on this record (γ is 1.3-2.8 std from the truth here), within
    # 0.1 of its std, and the truth within 3.5 of the LKF's std; the LKF holds a shape
    # parameter (temp_rate.tau, hysteresis.w) at its default, so ML of that same shape
    best = ml(s, m, fixed=m.defaults)
    for k in ("markov.beta", "temp.gamma", "bias.b", name):
        assert abs(r.value(k) - best.value(k)) <= 0.1 * best.std(k), k
        assert abs(r.value(k) - p[k]) <= 3.5 * r.std(k), k
        if not (term == "warmup" and k == name):  # τ held: its std is conditional on τ
            assert 0.8 <= r.std(k) / best.std(k) <= 1.1, k
