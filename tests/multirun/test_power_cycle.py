"""The power-cycle protocol's joint likelihood (#15): the turn-on bias a random effect of
known spread σ_b (exact: against the dense GLS with V = Σ + σ_b² 11', and σ_b → ∞ giving
the free per-run bias), the trend on the clock of the first switch-on, and a simulated set
whose shared trend it recovers; the default joint fit untouched."""

from __future__ import annotations

import numpy as np
import pytest

from gyrostand.core.ml.joint import joint_ml
from gyrostand.core.ml.joint_problem import JointProblem
from gyrostand.core.model import Model, context
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate
from gyrostand.errors import DataError

P = {"markov.beta": 0.0015, "markov.sigma": 0.05, "temp.gamma": -0.0002, "bias.b": 0.1,
     "white.sigma": 0.01, "trend.c": 1e-5}
M = Model.parse("markov,temp,bias,trend")


def _set(seed: int, hours: float, starts: list[float], spread: float):
    """Runs of one gyro switched on at ``starts`` (s, one clock): each its own stationary
    start, its turn-on bias P's + u ~ N(0, spread²), the trend's level at its switch-on."""
    rng = np.random.default_rng(seed)
    out = []
    for d in starts:
        s = simulate(M, P, chamber_profile(hours), seed=rng)
        u = float(rng.normal(0.0, spread))
        out.append(s.replace(t=np.asarray(s.t) + d, drift=s.drift + u + P["trend.c"] * d))
    return out


def _dense_cov(p, n: int) -> np.ndarray:
    phi = np.exp(-p["markov.beta"])
    k = np.arange(n)
    return (p["markov.sigma"] ** 2 * phi ** np.abs(k[:, None] - k[None, :])
            + p["white.sigma"] ** 2 * np.eye(n))


def test_random_bias_loglik_is_the_dense_gls():
    """Each run's ln L with its bias integrated out equals the Gaussian density of the run
    with mean X θ + c δ_r and covariance Σ + σ_b² 11' (dense, 300 samples)."""
    runs = [s.replace(t=s.t[:300], drift=s.drift[:300], temp=s.temp[:300])
            for s in _set(3, 1.0, [0.0, 40000.0], 0.1)]
    runs = [s.replace(t=np.asarray(s.t), drift=np.asarray(s.drift)) for s in runs]
    sb = 0.1
    prob = JointProblem(M, runs, {}, bias_spread=sb, absolute_time=True)
    lls = prob.random_loglik(P)
    for r, s in enumerate(runs):
        n = len(s)
        X = M.regressors(P, context(s, M))
        theta = np.array([P[k] for k in M.names_of_kind("linear")])
        mean = X @ theta + P["trend.c"] * (s.t[0] - runs[0].t[0])
        V = _dense_cov(P, n) + sb * sb * np.ones((n, n))
        e = np.asarray(s.drift) - mean
        _, logdet = np.linalg.slogdet(V)
        dense = -0.5 * (n * np.log(2 * np.pi) + logdet + e @ np.linalg.solve(V, e))
        assert lls[r] == pytest.approx(dense, abs=1e-7)


def test_infinite_spread_is_the_free_bias_and_absolute_time_is_absorbed_by_it():
    """σ_b → ∞: the random-effect ln L + ½ Σ_r ln(σ_b² 1'Σ_r⁻¹1) is the free-bias joint
    ln L (to 1e-6, at the free fit's optimum); with free per-run biases, absolute time
    changes nothing (each bias absorbs the trend's level at its switch-on)."""
    runs = _set(5, 1.0, [0.0, 30000.0, 60000.0], 0.1)
    free = joint_ml(runs, M, std_errors=False)
    plain, shifted = JointProblem(M, runs, {}), JointProblem(M, runs, {}, absolute_time=True)
    for z in (np.array([np.mean(b) for b in plain.bounds]), np.log([0.0015, 0.2])):
        a, (_, theta_a, _, _) = plain.profile(z)
        b, (_, theta_b, _, _) = shifted.profile(z)
        assert b == pytest.approx(a, abs=1e-6)
        c = plain.lin_free.index("trend.c")
        assert theta_b[c] == pytest.approx(theta_a[c], rel=1e-6, abs=1e-12)
    sb = 1e4
    prob = JointProblem(M, runs, {}, bias_spread=sb, absolute_time=True)
    p = {k: v for k, v in free.values.items() if "@" not in k}
    p["bias.b"] = 0.0
    corr = 0.0
    for r, part in enumerate(prob.parts):
        G = prob.shifted(part.gram(prob.run_params(p, r))[0], r)
        corr += 0.5 * np.log(sb * sb * G[prob.bias_col, prob.bias_col])
    assert sum(prob.random_loglik(p)) + corr == pytest.approx(free.loglik, abs=1e-6)


def test_default_joint_fit_has_no_protocol():
    """The protocol is an explicit option: the default problem has none of it, and asking
    for it on a model without a free bias is an error naming it."""
    runs = _set(6, 1.0, [0.0, 30000.0], 0.1)
    prob = JointProblem(M, runs, {})
    assert prob.spread is None and prob.bias_col is None and prob.trend_col is None
    assert prob.per_run == {"bias.b"}
    with pytest.raises(DataError, match="free bias"):
        JointProblem(Model.parse("markov,temp,trend"), runs, {}, bias_spread=0.1)


def test_a_power_cycled_set_recovers_the_shared_trend():
    """Three 2-h switch-ons 12 h apart, turn-on biases spread 0.1: the protocol's joint fit
    (σ_b 0.1, absolute time) finds the trend within 3 std of the truth, several times
    better determined than with a free bias per run; each run's reported bias is its
    level at its switch-on."""
    starts = [0.0, 14 * 3600.0, 28 * 3600.0]
    runs = _set(11, 2.0, starts, 0.1)
    fit = joint_ml(runs, M, bias_spread=0.1, absolute_time=True)
    free = joint_ml(runs, M)
    c, sd = fit.value("trend.c"), fit.std("trend.c")
    assert abs(c - P["trend.c"]) < 3 * sd, (c, sd)
    assert sd < free.std("trend.c") / 3, (sd, free.std("trend.c"))
    assert fit.info["bias_spread"] == 0.1 and fit.repeatability is None
    levels = [r.value("bias.b") for r in fit.runs]
    assert levels[2] - levels[0] == pytest.approx(P["trend.c"] * starts[2], abs=0.35)
