"""Every fact about a term lives in its class, and a term that lacks one fails loudly.

The LKF, the diagnostics, the candidate tests and the CAN summary read the facts from the
term classes; these tests check the built-ins state them consistently, and that a term
missing a fact (no causal regressor, no signature) is a ModelError naming it instead of the
old silent fall-throughs (the hysteresis regressor for any unknown LKF output; a candidate
silently dropped from the cross-correlation).
"""

import numpy as np
import pytest

from gyrostand.core.diagnose.diagnostics import candidate_regressor
from gyrostand.core.lkf.filter import OnlineLKF, lkf_layout, lkf_terms
from gyrostand.core.model import Model, StateSpace, context
from gyrostand.core.profiles import paper_profile
from gyrostand.core.simulation import simulate
from gyrostand.core.terms import builtin as terms
from gyrostand.core.terms.base import REQUIRED_HOOKS
from gyrostand.core.terms.builtin import NULLS, ROLES, TERMS, Param, Term, register, separation
from gyrostand.errors import ModelError

from ..conftest import truth


class Bare(Term):
    """An output term that states nothing beyond its regressor."""

    name = "bare_test_term"
    params = (Param("a", "linear", "y", "amplitude"), Param("w", "linear", "y", "second"))

    def regressors(self, p, ctx):
        return {self.key("a"): np.sin(ctx.t / 100.0), self.key("w"): np.cos(ctx.t / 100.0)}


@pytest.fixture
def bare(monkeypatch):
    monkeypatch.setitem(TERMS, Bare.name, Bare)  # registered for this test only
    return Bare


def test_built_in_facts_are_consistent():
    assert [c.bit for c in TERMS.values()] == list(range(len(TERMS)))
    for name, cls in TERMS.items():
        assert cls.role in ROLES and cls.null in NULLS, name
        for other in cls.look_alikes:
            assert other in TERMS, (name, other)
            assert separation(name, other) == separation(other, name) is not None
    # what the README says the LKF handles, from the roles
    m = Model.parse("markov,temp,temp2,bias,temp_rate,hysteresis,trend,warmup,random_walk,"
                    "markov2")
    assert lkf_layout(m) == [
        "delta_eps", "markov.beta", "temp.gamma", "temp2.gamma2", "bias.b", "temp_rate.k",
        "hysteresis.h", "trend.c", "warmup.A", "random_walk", "markov2"]
    with pytest.raises(ModelError, match=r"does not support the term\(s\) temp_lag \(temp_lag:"):
        lkf_terms(Model.parse("markov,temp,temp_lag"))


def test_every_candidate_has_a_signature_or_says_why_not(c1_samples):
    ctx = context(c1_samples, Model.parse("markov,temp"))
    p = {"markov.beta": 0.03, "temp.gamma": -0.01, "warmup.tau": 100.0}
    sig = {}
    for name, cls in TERMS.items():
        r = candidate_regressor(name, ctx, p)
        assert (r is None) == bool(cls.no_signature), name
        if r is not None:
            assert r.shape == c1_samples.t.shape and np.all(np.isfinite(r)), name
            sig[name] = r
    assert set(sig) == {"temp2", "temp_lag", "temp_rate", "hysteresis", "trend", "warmup"}
    # a fitted model without markov has no β to filter an input through: skipped, by the
    # term's own signature_needs
    assert candidate_regressor("temp2", ctx, {}) is None
    with pytest.raises(ModelError, match="unknown model term 'nope'"):
        candidate_regressor("nope", ctx, p)


def test_a_term_without_a_signature_or_a_causal_regressor_is_named(bare, c1_samples):
    ctx = context(c1_samples, Model.parse("markov,temp"))
    with pytest.raises(ModelError, match="'bare_test_term' has no diagnostic signature"):
        candidate_regressor("bare_test_term", ctx, {})
    m = Model.parse("markov,temp,bare_test_term")
    assert m.names[-1] == "bare_test_term"  # after the built-ins
    with pytest.raises(ModelError, match=r"bare_test_term: it defines no causal regressor"):
        lkf_terms(m)
    with pytest.raises(ModelError, match="bare_test_term"):
        OnlineLKF(m, 1.0, held={"markov.sigma": 0.1, "white.sigma": 0.01})
    # its default LKF prior scale: 10 |y| for a coefficient in the drift's unit
    assert Bare().prior_std(terms.Scales(y=2.0, T=20.0, rate=1.0)) == {
        "bare_test_term.a": 20.0, "bare_test_term.w": 20.0}


def test_register_refuses_a_clash_and_assigns_the_next_bit(monkeypatch):
    monkeypatch.setattr(terms, "TERMS", dict(TERMS))
    monkeypatch.setattr(terms, "ORIGIN", {})

    class MyBias(Term):
        name = "bias"
        params = (Param("b", "linear", "y", "offset"),)

    with pytest.raises(ModelError, match=r"clashes with the built-in term 'bias' "
                                         r"\(gyrostand\.core\.terms\.builtin\.Bias\)"):
        register(MyBias, "mine.MyBias")

    class Ok(Term):
        name = "ok_test_term"
        params = (Param("c", "linear", "y", "offset"),)
        math = "+ c"

        def regressors(self, p, ctx):
            return {self.key("c"): np.ones_like(ctx.t)}

    register(Ok, "mine.Ok")
    assert Ok.bit == len(terms.BUILTIN) and terms.summary_bits()["ok_test_term"] == 12

    class Again(Term):
        name = "ok_test_term"

    with pytest.raises(ModelError, match=r"clashes with the plugin term 'ok_test_term' "
                                         r"\(mine\.Ok\)"):
        register(Again, "other.Again")


def test_every_built_in_term_keeps_the_contract_of_its_role():
    for name, cls in TERMS.items():
        assert cls.contract_gaps() == [], name
        for hook in REQUIRED_HOOKS[cls.role]:
            assert cls.overrides(hook), (name, hook)


def test_register_names_the_fact_a_term_lacks(monkeypatch):
    """The contract is checked when a term registers, not when the LKF first runs it."""
    monkeypatch.setattr(terms, "TERMS", dict(TERMS))
    monkeypatch.setattr(terms, "ORIGIN", {})

    class NoRegressor(Term):
        name = "no_regressor_term"
        params = (Param("c", "linear", "y", "offset"),)
        math = "+ c"

    with pytest.raises(ModelError, match=r"plugin mine.NoRegressor: term 'no_regressor_term' "
                                         r"\(role 'output'\) lacks .*regressors\(\)"):
        register(NoRegressor, "mine.NoRegressor")

    class Cubed(Term):
        """A cubic in T, LKF-capable (a causal regressor), coefficient in y/degC³."""
        name = "temp_cubed"
        params = (Param("c", "linear", "y/degC^3", "cubic coefficient"),)
        math = "+ c·(T − 25)³"

        def regressors(self, p, ctx):
            return {self.key("c"): (ctx.temp - 25.0) ** 3}

        def causal_regressors(self, p, now):
            return {self.key("c"): (now.T - 25.0) ** 3}

    with pytest.raises(ModelError, match=r"lacks .*prior_std\(\) \(the online LKF's prior "
                                         r"scale of c \(unit y/degC\^3\)"):
        register(Cubed, "mine.Cubed")

    class CubedMlOnly(Cubed):
        """The same without a causal regressor: the LKF refuses it anyway (no prior needed)."""
        name = "temp_cubed_ml"
        causal_regressors = Term.causal_regressors

    assert register(CubedMlOnly, "mine.CubedMlOnly") is CubedMlOnly

    class CubedWithPrior(Cubed):
        name = "temp_cubed_prior"

        def prior_std(self, s):
            return {self.key("c"): 10 * s.y / s.T ** 3}

    assert register(CubedWithPrior, "mine.CubedWithPrior") is CubedWithPrior

    class Odd(Term):
        name = "odd_role_term"
        role = "sideways"
        math = "?"

    with pytest.raises(ModelError, match=r"role \(one of process, noise, input, output, "
                                         r"modifier; got 'sideways'\)"):
        register(Odd, "mine.Odd")

    class Process(Term):
        name = "stateless_process"
        role = "process"
        math = "x"

    with pytest.raises(ModelError, match=r"states\(\) \(every process term defines it\); "
                                         r"n_states"):
        register(Process, "mine.Process")


def test_the_state_space_is_named_and_shared_by_simulation_and_likelihood():
    m = Model.parse("markov,temp,random_walk")
    p = truth("C1", sigma_v=0.01, **{"random_walk.q": 1e-3})
    ss = m.state_space(p, 1.0)
    assert isinstance(ss, StateSpace) and ss.states == ("markov", "random_walk")
    assert ss.phi[0] == pytest.approx(np.exp(-0.0333)) and ss.phi[1] == 1.0
    assert ss.q[1] == pytest.approx(1e-6) and ss.p0[1] == 0.0
    assert ss.r == pytest.approx(1e-4)
    with pytest.raises(AttributeError):
        ss.r = 1.0  # frozen
    s = simulate(m, p, paper_profile(), seed=3)
    assert np.isfinite(m.loglik(p, s))
