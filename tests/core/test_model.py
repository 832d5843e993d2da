"""Model spec, exact discretisation and the exact likelihood against a dense Gaussian."""

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.stats import multivariate_normal

from gyrostand.core.data import Samples
from gyrostand.core.kalman import foh_weights
from gyrostand.core.model import Model, context
from gyrostand.core.profiles import paper_profile
from gyrostand.core.simulation import simulate
from gyrostand.errors import GyrostandError, ModelError


def test_parse_orders_terms_and_always_adds_white():
    m = Model.parse(["bias", "temp", "markov"])
    assert m.names == ("markov", "temp", "white", "bias")
    assert m.param_names == ("markov.beta", "markov.sigma", "temp.gamma", "white.sigma",
                             "bias.b")


def test_add_and_remove_return_new_models():
    m = Model.parse("markov,temp")
    m2 = m.add("random_walk")
    assert m.names == ("markov", "temp", "white")
    assert m2.names == ("markov", "temp", "white", "random_walk")
    assert m2.remove("random_walk") == m


@pytest.mark.parametrize("spec, msg", [
    ("markov,tmp", r"unknown model term 'tmp'.*vocabulary is: markov, temp"),
    ("markov,markov", "listed twice"),
    ("temp,bias,random_walk", "'temp' needs 'markov'"),
    ("bias", "at least one stochastic drift term"),
])
def test_bad_model_specs_are_named(spec, msg):
    with pytest.raises(ModelError, match=msg):
        Model.parse(spec)


def test_model_error_is_also_value_error():
    with pytest.raises(ValueError):
        Model.parse("nope")
    assert issubclass(ModelError, GyrostandError)


def test_cannot_remove_white():
    with pytest.raises(ModelError, match="always part of the model"):
        Model.parse("markov").remove("white")


@pytest.mark.parametrize("beta", [1e-7, 5.5e-4, 0.0333, 0.9])
def test_foh_weights_match_the_integrals(beta):
    dt = 1.0
    phi, a0, a1 = foh_weights(beta, dt)
    assert phi == pytest.approx(np.exp(-beta * dt), rel=1e-15)
    i0 = quad(lambda s: np.exp(-beta * s) * s / dt, 0, dt, epsabs=1e-15)[0]
    i1 = quad(lambda s: np.exp(-beta * s) * (1 - s / dt), 0, dt, epsabs=1e-15)[0]
    assert a0 == pytest.approx(i0, rel=1e-10)
    assert a1 == pytest.approx(i1, rel=1e-10)


def test_temperature_input_is_exact_for_a_ramp():
    """For T = c t, dε/dt = −βε + T has the closed form ε(t) = c(t/β − 1/β²) + C e^{−βt}."""
    beta, c = 0.01, 0.05
    t = np.arange(0.0, 300.0)
    s = Samples.from_arrays(t, np.zeros_like(t), c * t)
    x = context(s, None).through_markov(c * t, beta)
    C = 0.0 + c / beta**2  # x(0) = u(0)/beta = 0
    exact = c * (t / beta - 1 / beta**2) + C * np.exp(-beta * t)
    np.testing.assert_allclose(x, exact, rtol=1e-10, atol=1e-9)


def dense_loglik(model, p, s):
    """Log-density of y under the model by brute force: y ~ N(Xθ, Σ)."""
    N = len(s)
    X = model.regressors(p, context(s, model))
    theta = np.array([p[n] for n in model.names_of_kind("linear")])
    mean = X @ theta if theta.size else np.zeros(N)
    k = np.arange(N)
    cov = np.eye(N) * p["white.sigma"] ** 2
    for name in ("markov", "markov2"):
        if name in model:
            phi = np.exp(-p[f"{name}.beta"] * s.dt)
            cov += p[f"{name}.sigma"] ** 2 * phi ** np.abs(k[:, None] - k[None, :])
    if "random_walk" in model:
        cov += p["random_walk.q"] ** 2 * s.dt * np.minimum(k[:, None], k[None, :])
    return multivariate_normal(mean, cov).logpdf(s.drift)


@pytest.mark.parametrize("spec, extra", [
    ("markov,temp", {}),
    ("markov,temp,bias", {"bias.b": 0.3}),
    ("markov,temp,bias,random_walk", {"bias.b": -0.2, "random_walk.q": 0.02}),
    ("markov,temp,markov2", {"markov2.beta": 0.2, "markov2.sigma": 0.05}),
])
def test_kalman_likelihood_equals_dense_gaussian(spec, extra):
    m = Model.parse(spec)
    p = {"markov.beta": 0.05, "markov.sigma": 0.1, "temp.gamma": -0.01,
         "white.sigma": 0.03, **extra}
    s = simulate(m, p, paper_profile(), duration=120, seed=3)
    assert m.loglik(p, s) == pytest.approx(dense_loglik(m, p, s), rel=1e-10)


def test_likelihood_with_gaps_is_the_marginal_density():
    m = Model.parse("markov,temp,bias")
    p = {"markov.beta": 0.05, "markov.sigma": 0.1, "temp.gamma": -0.01,
         "white.sigma": 0.03, "bias.b": 0.1}
    s = simulate(m, p, paper_profile(), duration=80, seed=4)
    y = s.drift.copy()
    gap = np.r_[10:15, 40]
    y[gap] = np.nan
    sg = Samples.from_arrays(s.t, y, s.temp)
    keep = np.isfinite(y)
    X = m.regressors(p, context(s, m))
    mean = X @ np.array([p["temp.gamma"], p["bias.b"]])
    k = np.arange(len(s))
    cov = np.eye(len(s)) * 0.03**2 + 0.01 * np.exp(-0.05) ** np.abs(k[:, None] - k[None, :])
    ref = multivariate_normal(mean[keep], cov[np.ix_(keep, keep)]).logpdf(y[keep])
    assert m.loglik(p, sg) == pytest.approx(ref, rel=1e-10)


def test_simulation_is_seeded_and_reproducible():
    m = Model.parse("markov,temp,bias,random_walk")
    p = {"markov.beta": 0.03, "markov.sigma": 0.1, "temp.gamma": -0.01, "white.sigma": 0.01,
         "bias.b": 0.5, "random_walk.q": 0.001}
    a = simulate(m, p, paper_profile(), seed=11)
    b = simulate(m, p, paper_profile(), seed=11)
    c = simulate(m, p, paper_profile(), seed=12)
    np.testing.assert_array_equal(a.drift, b.drift)
    assert not np.allclose(a.drift, c.drift)


def test_simulated_markov_has_the_stationary_variance():
    m = Model.parse("markov")
    p = {"markov.beta": 0.5, "markov.sigma": 2.0, "white.sigma": 0.0}
    s = simulate(m, p, t=np.arange(200000.0), temp=np.zeros(200000), seed=5)
    assert np.std(s.drift) == pytest.approx(2.0, rel=0.02)
    lag1 = np.corrcoef(s.drift[1:], s.drift[:-1])[0, 1]
    assert lag1 == pytest.approx(np.exp(-0.5), abs=0.01)
