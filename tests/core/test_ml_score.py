"""The analytic score of the concentrated likelihood (#25: diagnose's cost): one
tangent-linear filter pass gives ∂ ln L/∂z, and it is the derivative of the likelihood
the search maximises — checked against Richardson-extrapolated central differences of
``Problem.profile`` on data that arrived as frames (jitter, 2 % drops so that bins hold
different frame counts — the measurement noise's weights —, an outage of missing bins, a
quantised sensor), for models whose searched parameters move the noise (β, noise ratios,
a random walk, a second process) and the mean (a lag, a width, β through the thermal
response)."""

from __future__ import annotations

import numpy as np
import pytest

from gyrostand.core.data import Samples
from gyrostand.core.ml.fit import Problem, ml
from gyrostand.core.ml.score import score_pass
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate
from gyrostand.core.validate import prepare

from ..workbench.framelike import frame_run


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Samples:
    path = frame_run(tmp_path_factory.mktemp("score") / "run.csv", ("temp_rate",),
                     seed=41, hours=1.5, drop=0.02, outage=(1500.0, 1530.0),
                     params={"temp_rate.k": 5.0})
    s = prepare(Samples.read_csv(path), "ml")
    assert s.noise_weights.size and np.isnan(s.drift).sum() >= 25  # weights, gaps
    return s


@pytest.fixture(scope="module")
def steady_run() -> Samples:
    """A 2-h run whose bins all hold the same frame count (no weights, no gaps): the
    filter and its tangent-linear pass reach their steady state."""
    truth = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
             "white.sigma": 0.02, "bias.b": 0.3, "temp_rate.k": 5.0}
    s = simulate(Model.parse("markov,temp,white,bias,temp_rate"), truth, chamber_profile(2.0),
                 seed=7)
    return prepare(Samples.from_arrays(s.t, s.drift, np.round(s.temp / 0.05) * 0.05), "ml")


def _fd(prob: Problem, z: np.ndarray, h: float = 1e-3) -> np.ndarray:
    """Central differences at h and h/2, Richardson-extrapolated (error O(h⁴))."""
    def cd(step: float) -> np.ndarray:
        return np.array([(prob.profile(z + step * e)[0] - prob.profile(z - step * e)[0])
                         / (2 * step) for e in np.eye(z.size)])
    return (4 * cd(h / 2) - cd(h)) / 3


@pytest.mark.parametrize("spec", [
    "markov,temp,white,bias",
    "markov,temp,white,bias,temp_rate",
    "markov,temp,white,bias,hysteresis",
    "markov,temp,white,bias,random_walk",
    "markov,temp,white,bias,markov2",
    "markov,temp,white,bias,warmup,temp_lag",
])
@pytest.mark.parametrize("data", ["run", "steady_run"])
def test_the_score_is_the_derivative_of_the_concentrated_likelihood(data, spec, request):
    prob = Problem(Model.parse(spec), request.getfixturevalue(data), {})
    rng = np.random.default_rng(3)
    for _ in range(2):  # two points inside the search box, away from its bounds
        z = np.array([rng.uniform(lo + 0.3 * (hi - lo), hi - 0.4 * (hi - lo))
                      for lo, hi in prob.bounds])
        ll, extra = prob.profile(z)
        assert np.isfinite(ll) and extra is not None
        _, theta, s2, _ = extra
        g = prob.score(z, theta, s2)
        want = _fd(prob, z)
        scale = max(1.0, float(np.max(np.abs(want))))
        assert np.max(np.abs(g - want)) < 2e-5 * scale, (prob.znames, g, want)


@pytest.mark.parametrize("spec, share", [
    ("markov,temp,white,bias", 0.05), ("markov,temp,white,bias,temp_rate", 0.05),
    ("markov,temp,white,bias,hysteresis", 0.05),
    # two processes: P itself takes longer to repeat (4,051 of 7,201 samples here)
    ("markov,temp,white,bias,markov2", 0.7)])
def test_the_tangent_linear_pass_settles(steady_run, spec, share):
    """Guard (#25): once the filter's covariance repeats, its derivatives settle and the
    pass holds them (DP_SETTLED). Bit-for-bit equality of ∂P never held — its recursion
    ends in a cycle a unit in the last place wide — and every sample recomputed them:
    3.4 ms a pass on a 6-h run where the filter takes 1.0, 0.45 ms now."""
    prob = Problem(Model.parse(spec), steady_run, {})
    rng = np.random.default_rng(5)
    z = np.array([rng.uniform(lo + 0.3 * (hi - lo), hi - 0.4 * (hi - lo))
                  for lo, hi in prob.bounds])
    _, theta, s2, _ = prob.profile(z)[1]
    g, unsettled = score_pass(prob, z, theta, s2)
    assert np.all(np.isfinite(g))
    assert unsettled < share * steady_run.n_observed, (unsettled, steady_run.n_observed)


def test_the_score_vanishes_at_the_optimum_ml_reports(run):
    """Where ML stopped, the gradient in every searched parameter is ~0 (in ln L units,
    against the ~1e2-1e3 of the points above): the search used the right derivative."""
    m = Model.parse("markov,temp,white,bias,temp_rate")
    fit = ml(run, m)
    prob = Problem(m, run, {})
    z = np.array([np.log(fit.value(n) / (fit.value("markov.sigma") if n in prob.stds
                                         else 1.0)) for n in prob.znames])
    _, theta, s2, _ = prob.profile(z)[1]
    g = prob.score(z, theta, s2)
    inside = [i for i, n in enumerate(prob.znames) if n not in fit.info["at_bound"]]
    assert np.max(np.abs(g[inside])) < 0.05, dict(zip(prob.znames, g, strict=True))


def test_the_search_follows_the_score_not_central_differences(run):
    """Guard (#25): a candidate refit's search evaluates the concentrated likelihood about
    once per L-BFGS-B step (the score is one more pass, not 2·d of them): with central
    differences a step cost 1 + 2·3 evaluations here."""
    base = ml(run, Model.parse("markov,temp,white,bias"))
    r = ml(run, Model.parse("markov,temp,white,bias,temp_rate"), start=base.values,
           grid=False, n_local=1)
    steps, evals, starts = r.info["iterations"], r.info["evaluations"], r.info["start_points"]
    assert steps >= 3
    assert evals - starts <= 2 * steps + 4, (evals, starts, steps)


def test_a_term_s_own_slopes_are_its_regressors_derivatives(run):
    """``Hysteresis.regressor_slopes`` (one tanh a step of the search instead of four)
    against Richardson-extrapolated central differences of its regressors in ln w and
    ln τ, and the score it gives against the score from central differences alone."""
    from gyrostand.core.model import context
    from gyrostand.core.terms.builtin import Hysteresis

    model = Model.parse("markov,temp,white,bias,hysteresis")
    ctx = context(run, model).bound(model.modifiers)
    term = model.term_of("hysteresis.h")
    fastest = float(np.max(np.abs(ctx.temp_rate)))
    for tau, w in ((12.0, 0.05 * fastest), (300.0, 0.5 * fastest), (40.0, 0.02 * fastest)):
        p = {"hysteresis.tau": tau, "hysteresis.w": w, "hysteresis.h": 1.0,
             "markov.beta": 0.01}
        for name in ("hysteresis.w", "hysteresis.tau"):
            def col(h: float, name=name, p=p) -> np.ndarray:
                return term.regressors({**p, name: p[name] * float(np.exp(h))}, ctx)[
                    "hysteresis.h"]

            def cd(h: float) -> np.ndarray:
                return (col(h) - col(-h)) / (2 * h)

            want = (4 * cd(5e-5) - cd(1e-4)) / 3
            got = term.regressor_slopes(p, ctx, name)["hysteresis.h"]
            assert np.max(np.abs(got - want)) < 1e-7 * np.max(np.abs(want)), (name, tau, w)
    # the score with the slopes and with central differences of the regressors
    prob = Problem(model, run, {})
    rng = np.random.default_rng(5)
    for _ in range(3):
        z = np.array([rng.uniform(lo + 0.3 * (hi - lo), hi - 0.4 * (hi - lo))
                      for lo, hi in prob.bounds])
        _, (_, theta, s2, _) = prob.profile(z)
        g = prob.score(z, theta, s2)
        own = Hysteresis.regressor_slopes
        try:
            Hysteresis.regressor_slopes = lambda self, p, ctx, name: None  # type: ignore
            g_cd = prob.score(z, theta, s2)
        finally:
            Hysteresis.regressor_slopes = own  # type: ignore
        assert np.max(np.abs(g - g_cd)) < 1e-7 * max(1.0, float(np.max(np.abs(g_cd)))), (g, g_cd)
