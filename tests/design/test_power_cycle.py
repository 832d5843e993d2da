"""``design --separate trend warmup`` with a turn-on bias spread (#15): the power-cycle
protocol. Its whitened distance against the dense GLS with V = Σ + σ_b² 11' per run, the
expected LR falling as σ_b grows, the command's files and verify (a few sets), and the
acceptance (slow): 6 h powered on, σ_b 0.1, gain >= 4x over the standard cycle and the
right model winning >= 90 % of 50 sets in each direction."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

from gyrostand.core.data import Samples
from gyrostand.core.design.search import ChamberLimits, case_temperature, standard_cycle
from gyrostand.core.design.separation import expected_lr, rivals
from gyrostand.core.design.switch_ons import (
    _protocol_distance,
    expected_lr_protocol,
    power_cycle,
    verify_protocol,
)
from gyrostand.core.model import Model, context

BASE = {"markov.beta": 0.0015, "markov.sigma": 0.05, "temp.gamma": -0.0002, "bias.b": 0.1,
        "white.sigma": 0.01}


def _dense(p, n: int) -> np.ndarray:
    k = np.arange(n)
    return (p["markov.sigma"] ** 2 * np.exp(-p["markov.beta"]) ** np.abs(k[:, None] - k[None, :])
            + p["white.sigma"] ** 2 * np.eye(n))


def test_protocol_distance_is_the_dense_gls():
    """Kalman whitening with the random bias's shrinkage = min_β Σ_r (y_r − X_r β)'
    V_r⁻¹ (y_r − X_r β), V_r = Σ + σ_b² 11', β shared, the trend's column + δ_r."""
    fit = Model.parse("markov,temp,bias,trend")
    p = {**BASE, "trend.c": 0.0}
    n, sb, offsets = 300, 0.1, [0.0, 5000.0]
    rng = np.random.default_rng(2)
    recs = []
    for _ in offsets:
        t = np.arange(float(n))
        temp = 20 + 10 * np.sin(t / 40.0)
        recs.append(Samples(t, 0.3 * np.exp(-t / 150.0) + 0.01 * rng.standard_normal(n),
                            temp, 1.0, source="test"))
    got = _protocol_distance(fit, [p, p], recs, offsets, sb)
    lin = fit.names_of_kind("linear")
    XtVX, XtVy, yVy = 0.0, 0.0, 0.0
    for s, d in zip(recs, offsets, strict=True):
        X = fit.regressors(p, context(s, fit)).copy()
        X[:, lin.index("trend.c")] += d
        Vi = np.linalg.inv(_dense(p, n) + sb * sb * np.ones((n, n)))
        y = np.asarray(s.drift)
        XtVX = XtVX + X.T @ Vi @ X
        XtVy = XtVy + X.T @ Vi @ y
        yVy += float(y @ Vi @ y)
    beta = np.linalg.solve(XtVX, XtVy)
    dense = yVy - float(XtVy @ beta)
    assert got == pytest.approx(dense, rel=1e-6)


def _rivals(hours: float):
    lim = ChamberLimits(0, 50, 1 / 60, 600, hours * 3600, legs=6 if hours >= 6 else 3)
    case = case_temperature(standard_cycle(lim).setpoint(lim.duration), lim)
    riv = rivals(Model.parse("markov,temp,bias"), "trend", "warmup",
                 {**BASE, "trend.c": 1e-5}, lim.grid, case, lim.dt)
    return lim, case, riv


def test_the_power_cycle_pays_less_as_the_bias_spread_grows():
    """2 switch-ons of 1 h, 12 h apart: the expected LR in the trend's direction falls as
    σ_b grows (measured: 68, 10, 1.3 at σ_b 0.03, 0.1, 0.3); at σ_b 0.03 the protocol's sum
    is >= 4x one 2-h standard cycle's."""
    lim, case, riv = _rivals(2.0)
    ref = sum(expected_lr(riv, lim.grid, case, lim.dt).values())
    lam = {sb: expected_lr_protocol(riv, power_cycle(lim, 2, 12 * 3600.0, sb), lim.dt)
           for sb in (0.03, 0.1, 0.3)}
    trend = [lam[sb]["trend"] for sb in (0.03, 0.1, 0.3)]
    assert trend[0] > trend[1] > trend[2], lam
    assert sum(lam[0.03].values()) >= 4 * ref, (lam, ref)


def test_the_command_designs_and_verifies_a_power_cycle(tmp_path):
    """``design --separate trend warmup --param bias.spread=0.05`` (2 h, reduced search,
    --verify 2): the assumptions in words, the protocol's files (power_cycle.csv with the
    gyro on and off, simulate_power_cycle.yaml), design.json's power_cycle block with a
    gain >= 4 and verify counts."""
    out = tmp_path / "d"
    args = [sys.executable, "-m", "gyrostand", "design", "--model", "markov,temp,bias,trend",
            "--separate", "trend", "warmup", "--hours", "2", "--legs", "3",
            "--evaluations", "4", "--verify", "2", "--out", str(out),
            "--param", "bias.spread=0.05"]
    args += [f"--param={k}={v}" for k, v in {**BASE, "trend.c": 1e-5}.items()]
    p = subprocess.run(args, capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr
    assert "keeps its rate in absolute time" in p.stdout
    assert "restarts at every switch-on" in p.stdout and "sigma_b = 0.05" in p.stdout
    doc = json.loads((out / "design.json").read_text())
    pc = doc["power_cycle"]
    assert pc["assumptions"]["bias_spread"] == 0.05
    assert pc["gain"] >= 4.0, pc
    assert pc["protocol"]["run_hours"] == [1.0, 1.0] and pc["protocol"]["off_hours"] == 24.0
    gains = [x["gain"] for x in pc["by_spread"]]
    assert [x["bias_spread"] for x in pc["by_spread"]] == [0.03, 0.05, 0.1, 0.3]
    assert gains == sorted(gains, reverse=True)
    for truth in ("trend", "warmup"):
        assert pc["verify"][truth]["failed"] == 0
        assert pc["verify"][truth]["right_wins_lr"] is not None
    with open(out / "power_cycle.csv", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["power"] for r in rows} == {"0", "1"}
    on = [float(r["time_s"]) for r in rows if r["power"] == "1"]
    assert on[0] == 0.0 and max(on) == pytest.approx((1 + 24 + 1) * 3600.0)
    assert (out / "simulate_power_cycle.yaml").read_text().count("\nsimulate:") == 2


def test_the_splits_tried_keep_the_powered_on_budget():
    """Equal splits of at least an hour and a long first run with one or two 1-h runs
    after it, every split summing to the budget."""
    from gyrostand.core.design.switch_ons import protocol_splits

    lim = ChamberLimits(0, 50, 1 / 60, 600, 6 * 3600, legs=6)
    splits = protocol_splits(lim)
    assert splits == [(3.0, 3.0), (2.0, 2.0, 2.0), (1.5, 1.5, 1.5, 1.5), (5.0, 1.0),
                      (4.0, 1.0, 1.0)]
    assert all(sum(s) == pytest.approx(6.0) for s in splits)
    pc = power_cycle(lim, [5.0, 1.0], 24 * 3600.0, 0.1)
    assert pc.starts == (0.0, 29 * 3600.0) and pc.chamber_hours == pytest.approx(30.0)


@pytest.mark.slow
def test_six_hour_power_cycle_separates_trend_from_warmup():
    """#15's acceptance: 6 h powered on, σ_b 0.1, the protocol the design chooses (5 h and
    1 h, 24 h apart): the expected LR >= 4x the standard cycle's (measured 200x), and of 50
    simulated sets from each model, both fitted by the protocol's joint ML, the right one
    wins >= 90 % by LR."""
    lim, case, riv = _rivals(6.0)
    ref = sum(expected_lr(riv, lim.grid, case, lim.dt).values())
    pc = power_cycle(lim, [5.0, 1.0], 24 * 3600.0, 0.1)
    lam = expected_lr_protocol(riv, pc, lim.dt)
    assert sum(lam.values()) >= 4 * ref, (lam, ref)
    v = verify_protocol(riv, pc, 50, seed=15)
    for truth in ("trend", "warmup"):
        assert v[truth]["failed"] == 0
        assert v[truth]["right_wins_lr"] >= 0.9, v
