"""Hidden-effect runs: the workbench finds the effect the model lacks, and adding it helps.

Each run is a seeded 4-hour thermal-chamber cycle (soaks; ramps at 1, 0.5 and 2 degC/min),
with the built-in sensor's temperature quantized to 0.05 degC and read with 0.01 degC
noise, and a drift of realistic size (deg/h). The analysed model is the configured
``markov,temp,bias``; the data contain one more effect (or none, or two).
"""

import numpy as np
import pytest

from gyrostand.core.data import Samples
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate
from gyrostand.workbench import open_subject, read_ledger, run_diagnose, run_fit

BASE = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
        "white.sigma": 0.02, "bias.b": 0.3}

#: hidden term -> its true parameters, and the relative tolerance on its main effect
HIDDEN = {
    "temp_rate": ({"temp_rate.k": 5.0}, 0.3),
    "hysteresis": ({"hysteresis.h": 0.05}, 0.3),
    "trend": ({"trend.c": 1e-5}, 0.3),
    "warmup": ({"warmup.A": 0.5, "warmup.tau": 900.0}, 0.4),
    "temp_lag": ({"temp_lag.tau": 600.0}, 0.3),
    "temp2": ({"temp2.gamma2": 5e-6}, 0.3),
}


def chamber_run(tmp_path, terms, extra, seed, hours=4.0):
    """Simulate, quantize the sensor, write a CSV; return its path."""
    m = Model.parse(["markov", "temp", "bias", *terms])
    s = simulate(m, {**BASE, **extra}, chamber_profile(hours), seed=seed)
    rng = np.random.default_rng(seed + 1000)
    temp = np.round((s.temp + 0.01 * rng.standard_normal(len(s))) / 0.05) * 0.05
    path = tmp_path / f"run-{'-'.join(terms) or 'none'}-{seed}.csv"
    Samples.from_arrays(s.t, s.drift, temp).to_csv(path)
    return path


@pytest.mark.parametrize("term", list(HIDDEN))
def test_hidden_effect_is_found_added_and_estimated(term, tmp_path):
    extra, tol = HIDDEN[term]
    path = chamber_run(tmp_path, [term], extra, seed=100 + list(HIDDEN).index(term))
    subject = open_subject(path)
    assert subject.model.names == ("markov", "temp", "white", "bias")
    rep = run_diagnose(subject)
    assert not rep.adequate
    assert rep.candidates[0].term == term, [(c.term, c.p_value) for c in rep.candidates]

    step = run_fit(open_subject(path), add=[term])
    assert step.after.residual_rms < step.before.residual_rms
    assert step.after.loglik > step.before.loglik
    main, truth = next(iter(extra.items()))
    est = step.after.parameters[main]
    assert abs(est.value - truth) <= max(4 * est.std, 0) and abs(est.value / truth - 1) < tol, \
        (main, est, truth)

    after = run_diagnose(open_subject(path))  # the ledger now holds the bigger model
    assert term in after.model.names
    assert after.adequate, after.reasons
    steps = read_ledger(subject.ledger_path)
    assert [s["action"] for s in steps] == ["diagnose", "fit", "diagnose"]
    assert steps[-1]["adequate"] is True and steps[0]["adequate"] is False


@pytest.mark.parametrize("seed", [7, 8])
def test_control_runs_raise_no_false_alarm(seed, tmp_path):
    rep = run_diagnose(open_subject(chamber_run(tmp_path, [], {}, seed=seed)))
    assert rep.adequate, (rep.reasons, [(c.term, c.p_value) for c in rep.candidates[:3]])


def test_two_hidden_effects_are_found_one_after_the_other(tmp_path):
    extra = {"temp_rate.k": 5.0, "trend.c": 1e-5}
    path = chamber_run(tmp_path, ["temp_rate", "trend"], extra, seed=300)
    first = run_diagnose(open_subject(path))
    assert not first.adequate
    t1 = first.candidates[0].term
    assert t1 in ("temp_rate", "trend")
    run_fit(open_subject(path), add=[t1])
    second = run_diagnose(open_subject(path))
    assert not second.adequate
    t2 = second.candidates[0].term
    assert {t1, t2} == {"temp_rate", "trend"}
    step = run_fit(open_subject(path), add=[t2])
    assert step.after.residual_rms < step.before.residual_rms
    final = run_diagnose(open_subject(path))
    assert final.adequate, final.reasons
    for name, truth in extra.items():
        e = final.fit.parameters[name]
        assert abs(e.value - truth) <= 4 * e.std


def test_look_alikes_are_named_with_the_profile_that_separates_them(tmp_path):
    """A trend over 4 hours is also fitted by a warm-up with a long time constant: the
    diagnosis must say that both explain the data about equally well, and how to tell them
    apart (a longer record after switch-on)."""
    path = chamber_run(tmp_path, ["trend"], HIDDEN["trend"][0], seed=102)
    rep = run_diagnose(open_subject(path), record=False)
    pairs = [set(la["terms"]) for la in rep.look_alikes]
    assert {"trend", "warmup"} in pairs, rep.look_alikes
    advice = next(la["advice"] for la in rep.look_alikes if set(la["terms"]) == {"trend", "warmup"})
    assert "warm-up settles" in advice
    assert rep.to_dict()["look_alikes"]  # in the JSON too
