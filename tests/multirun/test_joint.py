"""The joint exact likelihood of several runs of one gyro (gyrostand.core.ml.joint)."""

from __future__ import annotations

import numpy as np
import pytest

from gyrostand.core.data import Samples
from gyrostand.core.ml.fit import ml
from gyrostand.core.ml.joint import joint_ml, repeatability
from gyrostand.core.ml.joint_problem import run_key
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate
from gyrostand.errors import DataError

from ..workbench.framelike import frame_run
from .sets import PHYSICS, SPREAD, run_set


def test_one_run_is_the_single_run_fit():
    """R = 1 is the single-run ML: the same numbers, bit for bit."""
    m, runs, _ = run_set(3, n_runs=1)
    one, joint = ml(runs[0], m), joint_ml(runs, m)
    r = joint.runs[0]
    assert r.loglik == one.loglik == joint.loglik
    for n, e in one.parameters.items():
        assert (r.parameters[n].value, r.parameters[n].std) == (e.value, e.std), n
    assert joint.parameters[run_key("bias.b", 0)].value == one.value("bias.b")
    assert joint.repeatability is None


def test_one_run_with_a_warmup_is_the_single_run_fit():
    """A per-run nonlinear parameter (the warm-up's τ) too."""
    m = Model.parse("markov,temp,bias,warmup")
    p = {**PHYSICS, "bias.b": 0.3, "warmup.A": 0.4, "warmup.tau": 600.0}
    s = simulate(m, p, chamber_profile(2.0), seed=11)
    one, joint = ml(s, m), joint_ml([s], m)
    for n, e in one.parameters.items():
        assert joint.runs[0].parameters[n].value == e.value, n
        assert joint.runs[0].parameters[n].std == e.std, n


def test_five_runs_share_gamma_and_keep_their_biases():
    """Five runs: the shared γ's std is one run's /√5 (within 20 %), every run's bias is
    its own, and the true values lie within 3 std."""
    m, runs, biases = run_set(7)
    singles = [ml(s, m) for s in runs]
    joint = joint_ml(runs, m)
    one_std = float(np.mean([r.std("temp.gamma") for r in singles]))
    assert joint.std("temp.gamma") == pytest.approx(one_std / np.sqrt(5), rel=0.2)
    assert abs(joint.value("temp.gamma") - PHYSICS["temp.gamma"]) < 3 * joint.std("temp.gamma")
    for r, b in enumerate(biases):
        e = joint.parameters[run_key("bias.b", r)]
        assert abs(e.value - b) < 3 * e.std + 3 * 0.0085, (r, e, b)
        # each run's block: its own bias under the model's name, its residuals
        assert joint.runs[r].value("bias.b") == e.value
        assert joint.runs[r].residuals.shape == (len(runs[r]),)
    assert joint.loglik == pytest.approx(sum(r.loglik for r in joint.runs))
    rep = joint.repeatability
    assert rep is not None and rep.interval[0] < SPREAD < rep.interval[1]
    assert rep.p < 1e-6  # the biases differ far beyond their errors
    d = joint.to_dict()
    single_keys = set(singles[0].to_dict())
    assert single_keys <= set(d) and set(d) - single_keys == {"runs", "repeatability"}
    assert set(d["parameters"]) == {"markov.beta", "markov.sigma", "temp.gamma", "white.sigma"}
    assert len(d["runs"]) == 5 and d["repeatability"]["runs"] == 5


def test_equal_biases_give_a_spread_near_zero():
    """Runs with one bias: τ̂ small, the interval starts at 0 or near it, Q not significant."""
    m = Model.parse("markov,temp,bias")
    runs = [simulate(m, {**PHYSICS, "bias.b": 0.3}, chamber_profile(2.0), seed=40 + r)
            for r in range(5)]
    rep = joint_ml(runs, m).repeatability
    assert rep is not None
    assert rep.interval[0] < 0.01 and rep.spread < 0.03
    assert rep.p > 0.001


def test_q_profile_interval_covers_at_its_level():
    """The Q-profile interval alone: 400 sets of 5 values with unequal, correlated errors;
    its coverage of the true spread is 95 % (binomial 99.9 % band 91..98 %)."""
    rng = np.random.default_rng(1)
    stds = np.array([0.02, 0.05, 0.03, 0.08, 0.04])
    C = np.outer(stds, stds) * (0.7 * np.eye(5) + 0.3)
    Lc = np.linalg.cholesky(C)
    hit = 0
    for _ in range(400):
        b = 1.0 + SPREAD * rng.standard_normal(5) + Lc @ rng.standard_normal(5)
        rep = repeatability(b, C)
        hit += rep.interval[0] <= SPREAD <= rep.interval[1]
    assert 0.91 <= hit / 400 <= 0.98


def test_repeatability_needs_two_runs():
    with pytest.raises(DataError, match="at least 2 runs"):
        repeatability([0.1], np.eye(1))


def test_runs_built_from_frames(tmp_path):
    """Runs that arrived as frames (jitter, drops, partial first/last bins, quantized
    temperature) through the project's binner: γ shared and recovered, biases separate."""
    biases = [0.2, 0.35, 0.3, 0.45]
    runs = []
    for r, b in enumerate(biases):
        path = frame_run(tmp_path / f"run{r}.csv", seed=60 + r, hours=1.5, drift_hz=4.0,
                         temp_hz=2.0, drop=0.01, params={"bias.b": b})
        runs.append(Samples.read_csv(path))
    m = Model.parse("markov,temp,bias")
    joint = joint_ml(runs, m)
    g = joint.parameters["temp.gamma"]
    assert abs(g.value - (-0.0005)) < 3 * g.std
    for r, b in enumerate(biases):
        e = joint.parameters[run_key("bias.b", r)]
        assert abs(e.value - b) < 4 * e.std, (r, e)
    rep = joint.repeatability
    assert rep is not None and rep.interval[0] < float(np.std(biases, ddof=1)) < rep.interval[1]


@pytest.mark.slow
def test_repeatability_interval_covers_the_truth_in_100_sets():
    """The acceptance: 100 simulated sets of five runs, spread 0.1: the interval contains
    the truth in ≥ 90 % (benchmarks/multirun.py prints the table)."""
    hit = 0
    for k in range(100):
        m, runs, _ = run_set(1000 + k)
        rep = joint_ml(runs, m, hessian_passes=1).repeatability
        assert rep is not None
        hit += rep.interval[0] <= SPREAD <= rep.interval[1]
    assert hit >= 90
