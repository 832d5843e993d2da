"""``gyrostand design`` (#15 item 1, first slice): programs within the chamber's limits, the
chamber-to-case lag, a designed program that beats the standard cycle on the parameters in
doubt, and predictions that simulated runs confirm."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
import yaml

from gyrostand import exitcodes
from gyrostand.core.design.search import (
    ChamberLimits,
    case_temperature,
    design,
    program_of,
    standard_cycle,
)
from gyrostand.core.model import Model
from gyrostand.errors import ModelError

MODEL = "markov,temp,bias,temp_rate,hysteresis,white"
TRUTH = {"markov.beta": 0.0015, "markov.sigma": 0.05, "temp.gamma": -0.0002, "bias.b": 0.1,
         "temp_rate.k": 5.0, "white.sigma": 0.01, "hysteresis.h": 0.05}
DOUBT = ("temp_rate.k", "hysteresis.h")


def _check_program(prog, lim: ChamberLimits) -> None:
    sp = prog.setpoint(lim.duration)
    assert sp.times[0] == 0 and sp.times[-1] == pytest.approx(lim.duration)
    assert min(sp.temps) >= lim.t_min - 1e-9 and max(sp.temps) <= lim.t_max + 1e-9
    slopes = np.abs(np.diff(sp.temps)) / np.diff(sp.times)
    assert np.all(slopes <= lim.max_rate * (1 + 1e-9))
    for _, rate, soak in prog.legs:
        assert 0 < rate <= lim.max_rate * (1 + 1e-12) and soak >= lim.min_soak - 1e-9


def test_programs_stay_within_the_limits_and_fill_the_duration():
    lim = ChamberLimits(-10, 60, 1.0 / 60, 600, 6 * 3600, legs=5)
    rng = np.random.default_rng(4)
    feasible = 0
    for _ in range(200):
        prog = program_of(rng.normal(0, 2, 15), lim)
        if prog.excess > 0:
            continue
        feasible += 1
        _check_program(prog, lim)
        ramps = sum(abs(T - p) / r for (T, r, _), p in
                    zip(prog.legs, [lim.t0] + [g[0] for g in prog.legs[:-1]], strict=True))
        assert ramps + sum(s for *_, s in prog.legs) == pytest.approx(lim.duration)
    assert feasible > 50
    _check_program(standard_cycle(lim), lim)


def test_the_case_follows_the_set_point_through_the_lag():
    """A ramp at r from a soak: the case's exact response r(t − τ(1 − e^(−t/τ))) behind the
    set-point, to rounding (the first-order hold is exact for a piecewise-linear input)."""
    lim = ChamberLimits(0, 50, 1.0 / 60, 0, 3600, legs=1, lag=600.0, start=0.0)
    prog = program_of(np.array([50.0, 50.0, 0.0]), lim)
    T, r, _ = prog.legs[0]
    case = case_temperature(prog.setpoint(lim.duration), lim)
    t = lim.grid
    k = t <= T / r
    expect = r * (t[k] - 600.0 * (1 - np.exp(-t[k] / 600.0)))
    assert np.max(np.abs(case[k] - expect)) < 1e-9
    t1 = T / r  # then the soak: the lag behind it decays as e^(−(t − t1)/τ)
    lag_at_t1 = T - r * (t1 - 600.0 * (1 - np.exp(-t1 / 600.0)))
    assert case[-1] == pytest.approx(T - lag_at_t1 * np.exp(-(3600 - t1) / 600.0), abs=1e-9)


def test_bad_limits_and_goals_are_errors_naming_them():
    with pytest.raises(ModelError, match="t_max"):
        ChamberLimits(50, 0, 1, 0, 3600)
    with pytest.raises(ModelError, match="cannot hold 6 soaks"):
        ChamberLimits(0, 50, 1, 3600, 3600)
    lim = ChamberLimits(0, 50, 1 / 60, 600, 3600, legs=2)
    with pytest.raises(ModelError, match="'temp_rate.q' is not a free parameter"):
        design(Model.parse(MODEL), TRUTH, lim, goal="std:temp_rate.q")
    with pytest.raises(ModelError, match="use d-optimal, worst or std:PARAM"):
        design(Model.parse(MODEL), TRUTH, lim, goal="best")


def test_designed_program_beats_the_standard_cycle_on_the_parameters_in_doubt():
    """2 h, 0..50 °C, <= 1 °C/min, soaks >= 10 min: the worst relative std among temp_rate.k
    and hysteresis.h at least 1.3x smaller than the standard cycle's (a reduced search,
    measured 1.49x; the slow test below checks the 6-h acceptance)."""
    lim = ChamberLimits(0, 50, 1 / 60, 600, 2 * 3600, legs=6)
    res = design(Model.parse(MODEL), TRUTH, lim, goal="worst", doubt=DOUBT, starts=1,
                 maxfev=40, n_mc_report=8)
    _check_program(res.program, lim)
    _, rel = res.worst()
    _, ref = res.worst("reference")
    assert ref / rel >= 1.3, (rel, ref)


def test_the_command_writes_a_program_a_session_can_rehearse(tmp_path):
    out = tmp_path / "d"
    args = [sys.executable, "-m", "gyrostand", "design", "--model", MODEL,
            *[f"--param={k}={v}" for k, v in TRUTH.items()], "--hours", "1", "--legs", "3",
            "--goal", "std:temp_rate.k", "--evaluations", "15", "--lag", "5", "--out", str(out),
            "--json"]
    p = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)
    assert doc == json.loads((out / "design.json").read_text())
    assert set(doc["predicted_std"]) == set(TRUTH) and doc["reference"] == "standard cycle"
    assert doc["limits"]["lag_s"] == 300.0 and len(doc["program"]) == 3
    assert all(r["rate_degC_per_min"] <= 1.0 + 1e-9 for r in doc["program"])
    rows = np.loadtxt(out / "profile.csv", delimiter=",", skiprows=1)
    assert rows.shape == (3601, 3)
    assert np.max(np.abs(np.diff(rows[:, 2]))) <= 1.0 / 60 + 1e-6  # the case lags
    sim = yaml.safe_load((out / "simulate.yaml").read_text())["simulate"]
    assert sim["duration"] == 3600 and sim["temperature"][0][0] == 0
    t = [a for a, _ in sim["temperature"]]
    assert t == sorted(t) and math.isclose(t[-1], 3600, abs_tol=1)
    assert (out / "design.png").stat().st_size > 10_000


def test_bad_param_is_an_error_naming_it(tmp_path):
    p = subprocess.run([sys.executable, "-m", "gyrostand", "design", "--model", "markov,temp",
                        "--param", "temp.gamma", "--out", str(tmp_path)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == exitcodes.USAGE
    assert "--param 'temp.gamma': expected NAME=VALUE" in p.stderr


@pytest.mark.slow
def test_six_hour_design_halves_the_worst_std_and_simulations_confirm_it():
    """#15's acceptance: 6 h, 0..50 °C, <= 1 °C/min, soaks >= 10 min; the designed
    program's worst-determined parameter (of those in doubt) >= 2x better than the
    standard cycle's, and 100 simulated runs of each, fitted by ML as the prediction
    assumes (the shape parameters at their plain values, design.json's
    ``predicted_given``), realize the predicted std within 20 %.

    Since temp_rate and hysteresis gained their lag, a fit that also estimates the lags
    realizes a heavier tail on the standard cycle (30 runs: temp_rate.k std 1.56, robust
    1.05, against 0.82 with the lags held: 2 runs put the lag at 140-180 s and k at -1.5
    and 2.2); design's verify shows both spreads and names what the prediction holds."""
    from gyrostand.cli.design import held_in_prediction
    from gyrostand.core.ml.fit import ml
    from gyrostand.core.simulation import simulate

    model = Model.parse(MODEL)
    lim = ChamberLimits(0, 50, 1 / 60, 600, 6 * 3600, legs=6)
    res = design(model, TRUTH, lim, goal="worst", doubt=DOUBT, starts=2, maxfev=80,
                 n_mc_report=40)
    name, rel = res.worst()
    _, ref = res.worst("reference")
    assert ref / rel >= 2.0, (rel, ref)
    held = held_in_prediction(model, res)
    assert held == {"temp_rate.tau": 0.0, "hysteresis.tau": 0.0, "hysteresis.w": 1e-3}
    for label, prog, pred in (("designed", res.program, res.predicted),
                              ("reference", res.reference, res.reference_predicted)):
        case = case_temperature(prog.setpoint(lim.duration), lim)
        rng = np.random.default_rng([15, 0 if label == "designed" else 1])
        vals = [ml(simulate(model, TRUTH, t=lim.grid, temp=case, seed=rng), model,
                   fixed=held, std_errors=False).value(name) for _ in range(100)]
        assert np.std(vals, ddof=1) == pytest.approx(pred[name], rel=0.2), label
