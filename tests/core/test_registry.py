"""The identifiers' one registry: names everywhere come from it, options are typed and
frozen with the functions' defaults, refusals name the term, and every online identifier
runs behind one update/estimate interface."""

from __future__ import annotations

import dataclasses
import inspect
import math
import re
from pathlib import Path

import pytest

from gyrostand import config
from gyrostand.cli import build_parser
from gyrostand.cli.identify import options_for
from gyrostand.core import registry
from gyrostand.core.lkf.filter import lkf
from gyrostand.core.lsq.fit import lsq
from gyrostand.core.ml.fit import ml_fit
from gyrostand.core.model import Model
from gyrostand.core.names import METHODS
from gyrostand.core.options import LkfOptions, LsqOptions, MlOptions
from gyrostand.core.profiles import paper_profile
from gyrostand.core.registry import REGISTRY, get, identify
from gyrostand.core.simulation import simulate
from gyrostand.errors import ModelError
from gyrostand.session.online import ONLINE

from ..conftest import truth

ROOT = Path(__file__).resolve().parents[2]


def test_every_list_of_identifiers_is_the_registry_s():
    assert set(METHODS) == set(REGISTRY)  # the parser's list too
    assert config.IDENTIFIERS == registry.names() == ("lkf", "lsq", "ml")
    assert ONLINE == ("lkf", "lsq")
    # the generated DBC's Identifier value tables: the registry's names, in its order
    text = (ROOT / "dbc" / "generate.py").read_text()
    tables = set(re.findall(r"VAL_ \{[rs]\} Identifier ((?:\d+ \"\w+\" )+);", text))
    assert tables == {" ".join(f'{i} "{n}"' for i, n in enumerate(REGISTRY)) + " "}


@pytest.mark.parametrize("name, fn", [("lsq", lsq), ("lkf", lkf), ("ml", ml_fit)])
def test_options_defaults_are_the_functions_defaults(name, fn):
    sig = inspect.signature(fn).parameters
    shared = [f for f in dataclasses.fields(get(name).Options) if f.name in sig]
    assert len(shared) >= 2
    for f in shared:
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        want = sig[f.name].default
        assert default == want or (not default and want is None), (name, f.name)


def test_options_are_typed_frozen_and_checked():
    o = get("lkf").options(beta0=0.03, held={"random_walk.q": 1e-4})
    assert isinstance(o, LkfOptions) and o.beta0 == 0.03
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.beta0 = 1.0  # type: ignore[misc]
    with pytest.raises(TypeError):
        o.held["x"] = 1.0  # type: ignore[index]
    with pytest.raises(ModelError, match=r"lkf has no options bogus, regressor; its options: "
                                         r"beta0, gamma0"):
        get("lkf").options(regressor="current", bogus=1)
    with pytest.raises(ModelError, match="unknown lkf variant 'x'; choose one of relin, paper"):
        LkfOptions(variant="x")
    with pytest.raises(ModelError, match="regressor must be 'previous' or 'current'"):
        LsqOptions(regressor="next")
    with pytest.raises(ModelError, match=r"unknown identifier 'kf'; choose one of lkf, lsq, ml"):
        get("kf")
    with pytest.raises(TypeError, match="lsq: options must be LsqOptions, got MlOptions"):
        get("lsq").fit(None, Model.parse("markov"), MlOptions())  # type: ignore[arg-type]


@pytest.mark.parametrize("name, model, term", [
    ("lkf", "markov,temp,temp_lag", "temp_lag"),
    ("lkf", "random_walk,white", "markov"),
    ("lsq", "markov,temp,hysteresis", "hysteresis"),
    ("lsq", "markov,markov2", "markov2"),
    ("lsq", "random_walk,white", "markov"),
])
def test_an_identifier_refuses_a_model_naming_the_term(name, model, term):
    why = get(name).refusal(Model.parse(model))
    assert why is not None and term in why and why.startswith(name)
    with pytest.raises(ModelError, match=term):
        get(name).check(Model.parse(model))


def test_ml_accepts_every_model_and_lkf_and_lsq_their_own():
    everything = Model.parse("markov,temp,bias,temp_rate,hysteresis,trend")
    assert get("ml").refusal(everything) is None
    assert get("lkf").refusal(everything) is None
    assert get("lsq").refusal(Model.parse("markov,temp,bias")) is None


@pytest.fixture(scope="module")
def c2():
    m = Model.parse("markov,temp,bias")
    return m, simulate(m, truth("C1", sigma_v=0.0, **{"bias.b": 0.3}), paper_profile(),
                       seed=8)


def test_the_keyword_wrapper_and_the_typed_fit_are_the_same_fit(c2):
    m, s = c2
    a = identify(s, m, "lsq", regressor="current")
    b = get("lsq").fit(s, m, LsqOptions(regressor="current"))
    assert a.info["regressor"] == "current"
    assert {k: e.value for k, e in a.parameters.items()} == \
        {k: e.value for k, e in b.parameters.items()}
    prev = identify(s, m, "lsq")  # the default regressor: the option reached the fit
    assert prev.info["regressor"] == "previous" and prev.value("markov.beta") != \
        a.value("markov.beta")
    e = prev.parameters["markov.beta"]
    assert abs(e.value - 0.0333) <= 3 * e.std


def test_cli_options_come_from_the_options_class():
    p = build_parser()
    args = p.parse_args(["identify", "x.csv", "--method", "lkf", "--variant", "paper",
                         "--beta0", "0.01", "--sigma", "0.1", "--regressor", "current"])
    assert options_for(args) == LkfOptions(variant="paper", beta0=0.01, sigma=0.1)
    args = p.parse_args(["identify", "x.csv", "--method", "lsq", "--regressor", "current"])
    assert options_for(args) == LsqOptions(regressor="current")
    args = p.parse_args(["identify", "x.csv", "--sigma", "0.2"])
    assert options_for(args) == MlOptions(sigma=0.2)


def test_every_online_identifier_runs_behind_one_interface_and_ends_at_the_batch_value(c2):
    """Fed bin by bin, each online identifier's estimate at the end is its batch value on
    the same bins: LSQ to rounding; the relin LKF after its last re-linearisation within
    a tenth of its std; both recover the truth (C1: β 0.0333, γ −0.01) within 3σ."""
    m, s = c2
    for name in ONLINE:
        ident = get(name)
        track = ident.track(m, s.dt, ident.Options(**({"warmup": 200} if name == "lkf"
                                                      else {})))
        for y, T in zip(s.drift, s.temp, strict=True):
            track.update(float(y), float(T))
        track.finish()
        est = track.estimate()
        assert est.identifier == name and est.samples >= len(s) - 1
        assert est.status in ("ok", "warning"), est.note
        batch = ident.fit(s, m)
        for k, want in (("markov.beta", 0.0333), ("temp.gamma", -0.01)):
            v, sd = est.values[k]
            assert math.isfinite(v) and abs(v - want) <= 3 * sd, (name, k, v, sd)
            b = batch.parameters[k]
            tol = 1e-9 * max(abs(b.value), 1e-12) if name == "lsq" else 0.1 * b.std
            assert abs(v - b.value) <= tol, (name, k, v, b.value)
    with pytest.raises(ModelError, match="ml does not run online"):
        get("ml").track(m, 1.0)


def test_an_identifier_states_its_facts_when_its_class_is_defined():
    """The identifier's contract is checked at class definition, naming what is missing."""
    from gyrostand.core.options import LsqOptions
    from gyrostand.core.registry import Identifier

    with pytest.raises(ModelError, match=r"lacks what an identifier must state: name .*; "
                                         r"Options .*; help .*; fit\(\)"):
        class Nothing(Identifier):
            pass

    with pytest.raises(ModelError, match=r"track\(\) \(it says it runs online\)"):
        class Online(Identifier):
            name, Options, help, online = "online_test", LsqOptions, "a test", True

            def fit(self, samples, model, options=None):
                raise NotImplementedError

    class Batch(Identifier):
        name, Options, help = "batch_test", LsqOptions, "a test"

        def fit(self, samples, model, options=None):
            raise NotImplementedError

    assert Batch().name == "batch_test"
