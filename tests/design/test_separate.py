"""``gyrostand design --separate A B`` (#15 items 1 and 2): the expected likelihood ratio
between two look-alike models (its whitened distance against dense GLS, its noise part
against the exact Gaussian KL), a designed program that separates them better than the
standard cycle and simulated runs that confirm it, and ``diagnose`` printing the command
with the run's own limits."""

from __future__ import annotations

import dataclasses
import json
import shlex
import subprocess
import sys

import numpy as np
import pytest

from gyrostand.core.data import Samples
from gyrostand.core.design.divergence import (
    _distance,
    _spectrum,
    divergence,
    mean_response,
    whittle_loglik,
)
from gyrostand.core.design.search import ChamberLimits, case_temperature, standard_cycle
from gyrostand.core.design.separation import rivals, separate, verify
from gyrostand.core.model import Model, context
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate
from gyrostand.errors import ModelError

BASE = {"markov.beta": 0.0015, "markov.sigma": 0.05, "temp.gamma": -0.0002, "bias.b": 0.1,
        "white.sigma": 0.01}


def _dense_cov(model: Model, p, n: int, dt: float) -> np.ndarray:
    """Covariance of the model's noise over n samples, from its state space."""
    ss = model.state_space(p, dt)
    k = np.arange(n)
    C = np.eye(n) * ss.r
    for phi, q, p0 in zip(ss.phi, ss.q, ss.p0, strict=True):
        # x_0 ~ N(0, p0), x_k = phi x_{k-1} + w_k: cov(x_i, x_j) = phi^|i-j| var x_min(i,j)
        m = np.minimum.outer(k, k)
        var = p0 * phi ** (2 * m) + (q * (1 - phi ** (2 * m)) / (1 - phi * phi)
                                     if phi != 1 else q * m)
        C += phi ** np.abs(np.subtract.outer(k, k)) * var
    return C


def test_the_whitened_distance_is_the_gls_distance():
    """Kalman-whitened least squares of A's mean on B's columns = (μ − Xβ)ᵀ Σ⁻¹ (μ − Xβ)
    minimized with the dense covariance Σ of B's noise."""
    ma = Model.parse("markov,temp,bias,temp_rate")
    mb = Model.parse("markov,temp,bias,hysteresis")
    pa = {**BASE, "markov.beta": 0.02, "temp_rate.k": 5.0}
    pb = {**BASE, "markov.beta": 0.02, "hysteresis.h": 0.05}
    t = np.arange(400.0)
    temp = 25 + 10 * np.sin(t / 40.0)
    s = Samples(t, np.zeros_like(t), temp, 1.0)
    s = s.replace(drift=mean_response(ma, pa, s))
    X = mb.regressors(pb, context(s, mb))
    Ci = np.linalg.inv(_dense_cov(mb, pb, t.size, 1.0))
    beta = np.linalg.solve(X.T @ Ci @ X, X.T @ Ci @ s.drift)
    r = s.drift - X @ beta
    assert _distance(mb, pb, s) == pytest.approx(float(r @ Ci @ r), rel=1e-6)


def test_the_noise_divergence_is_the_gaussian_kl():
    """Whittle's N·mean(ρ − 1 − ln ρ) against the exact 2 KL of two stationary Gaussian
    noises over 600 samples, tr(Σ_B⁻¹Σ_A) − N + ln det Σ_B − ln det Σ_A, within 3 %."""
    ma = Model.parse("markov,markov2")
    mb = Model.parse("markov")
    pa = {"markov.beta": 0.05, "markov.sigma": 0.1, "markov2.beta": 0.3,
          "markov2.sigma": 0.05, "white.sigma": 0.02}
    pb = {"markov.beta": 0.08, "markov.sigma": 0.11, "white.sigma": 0.03}
    n = 600
    A, B = _dense_cov(ma, pa, n, 1.0), _dense_cov(mb, pb, n, 1.0)
    exact = (np.trace(np.linalg.solve(B, A)) - n + np.linalg.slogdet(B)[1]
             - np.linalg.slogdet(A)[1])
    w = 2 * np.pi * np.arange(1, n // 2 + 1) / n
    got = whittle_loglik(_spectrum(ma, pa, 1.0, w), mb, pb, w, 1.0, n)
    assert got == pytest.approx(exact, rel=0.03), (got, exact)


def test_a_model_is_no_distance_from_itself_nor_from_a_model_that_contains_it():
    lim = ChamberLimits(0, 50, 1 / 60, 600, 3600, legs=3)
    case = case_temperature(standard_cycle(lim).setpoint(lim.duration), lim)
    m0, ml = Model.parse("markov,temp,bias"), Model.parse("markov,temp,bias,temp_lag")
    assert divergence(m0, BASE, m0, BASE, lim.grid, case, 1.0) < 1e-9
    # data without a lag, fitted by the model with one: τ goes to its lower bound
    lam = divergence(m0, BASE, ml, {**BASE, "temp_lag.tau": 300.0}, lim.grid, case, 1.0)
    assert lam < 0.05, lam
    # and with a lag, fitted without: a clear distance
    assert divergence(ml, {**BASE, "temp_lag.tau": 300.0}, m0, BASE, lim.grid, case,
                      1.0) > 3


def test_the_designed_program_separates_temp_lag_from_markov2_and_the_fits_confirm():
    """2 h, 0..50 °C, <= 1 °C/min, soaks >= 10 min, a 120-s lag whose look-alike is a second
    Gauss–Markov process: the designed program's expected LR >= 2x the standard cycle's (a
    reduced search; the slow test checks the 6-h acceptance), and 10 simulated runs from the
    lag model on it, both models fitted by ML, pick the lag in >= 80 % with a mean LR of at
    least half the prediction."""
    lim = ChamberLimits(0, 50, 1 / 60, 600, 2 * 3600, legs=6)
    case = case_temperature(standard_cycle(lim).setpoint(lim.duration), lim)
    riv = rivals(Model.parse("markov,temp,bias"), "temp_lag", "markov2",
                 {**BASE, "temp_lag.tau": 120.0}, lim.grid, case, 1.0)
    assert set(riv.params_b) == set(riv.model_b.param_names)
    res = separate(riv, lim, starts=1, maxfev=30)
    assert res.gain >= 2.0, (res.expected, res.reference_expected)
    designed = case_temperature(res.program.setpoint(lim.duration), lim)
    v = verify(riv, {"designed": (lim.grid, designed)}, 10, seed=3)
    got = v["designed"]["temp_lag"]
    assert got["failed"] == 0 and got["right_wins_lr"] >= 0.8, got
    # measured: 25.3 realized vs 16.1 predicted; verify's ML of the two-process rival
    # (one local search from its best start) can stop short of its optimum, which only
    # raises the right model's LR: the prediction is checked as a floor
    assert got["mean_lr"] >= 0.5 * res.expected["temp_lag"], (got, res.expected)


def test_bad_rivals_are_errors_naming_them():
    m = Model.parse("markov,temp,bias")
    t = np.arange(100.0)
    with pytest.raises(ModelError, match="two different terms"):
        rivals(m, "trend", "trend", BASE, t, t * 0, 1.0)
    with pytest.raises(ModelError, match="unknown model term 'trnd'"):
        rivals(m, "trnd", "warmup", BASE, t, t * 0, 1.0)
    with pytest.raises(ModelError, match="missing trend.c"):
        rivals(m, "trend", "warmup", BASE, t, t * 0, 1.0)


def test_the_command_writes_the_separating_program(tmp_path):
    out = tmp_path / "d"
    args = [sys.executable, "-m", "gyrostand", "design", "--model", "markov,temp,bias",
            *[f"--param={k}={v}" for k, v in {**BASE, "temp_lag.tau": 120.0}.items()],
            "--separate", "temp_lag", "markov2", "--hours", "1", "--legs", "3",
            "--evaluations", "10", "--out", str(out), "--json"]
    p = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)
    assert doc == json.loads((out / "design.json").read_text())
    assert doc["goal"] == "separate" and doc["separate"] == ["temp_lag", "markov2"]
    assert "temp_lag" in doc["models"]["temp_lag"] and "markov2" in doc["models"]["markov2"]
    for which in ("designed", "reference"):
        lam = doc["expected_lr"][which]
        assert lam["total"] == pytest.approx(lam["temp_lag"] + lam["markov2"])
    assert doc["gain"] == pytest.approx(doc["expected_lr"]["designed"]["total"]
                                        / doc["expected_lr"]["reference"]["total"])
    # in 1 h the standard cycle is already all ramps at the chamber's rate: it may win
    assert len(doc["program"]) in (3, 4) and doc["reference"] == "standard cycle"
    assert doc["gain"] >= 1.0
    assert all(leg["rate_degC_per_min"] <= 1.0 + 1e-9 for leg in doc["program"])
    for name in ("program.csv", "profile.csv", "simulate.yaml", "design.png"):
        assert (out / name).stat().st_size > 0


def _trend_run_diagnosis(tmp_path):
    """A 4-h chamber run (10..45 °C, ramps up to 2 °C/min) with a hidden trend, diagnosed
    with the trend and warm-up candidates: (its path, temperatures, subject, report)."""
    from gyrostand.core.diagnose.verdict import diagnose
    from gyrostand.workbench import open_subject
    from gyrostand.workbench.steps import with_design_commands

    base = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
            "white.sigma": 0.02, "bias.b": 0.3}
    m = Model.parse("markov,temp,bias,trend")
    s = simulate(m, {**base, "trend.c": 1e-5}, chamber_profile(4.0), seed=102)
    rng = np.random.default_rng(1102)
    temp = np.round((s.temp + 0.01 * rng.standard_normal(len(s))) / 0.05) * 0.05
    path = tmp_path / "run.csv"
    Samples.from_arrays(s.t, s.drift, temp).to_csv(path)
    subject = open_subject(path)
    rep = with_design_commands(diagnose(subject.samples, subject.model,
                                        terms=["trend", "warmup"]), subject)
    return path, temp, subject, rep


def test_diagnose_prints_the_design_command_with_the_runs_limits(tmp_path):
    """The trend / warm-up look-alikes of a 4-h chamber run: the look-alike carries the
    `design --separate` command with this run's path, model and limits (JSON too, the
    term's advice kept), and the text prints it."""
    from gyrostand.cli import build_parser
    from gyrostand.report.text import diagnosis

    path, temp, subject, rep = _trend_run_diagnosis(tmp_path)
    (la,) = rep.look_alikes
    assert "warm-up settles" in la["advice"]
    cmd = shlex.split(la["command"])
    assert cmd[:2] == ["gyrostand", "design"]
    args = build_parser().parse_args(cmd[1:])
    assert args.run == str(path) and args.separate == la["terms"]
    assert args.model == str(subject.model)
    assert args.t_min <= temp.min() and args.t_min > temp.min() - 1
    assert args.t_max >= temp.max() and args.t_max < temp.max() + 1
    assert 2.0 <= args.max_rate <= 2.2 and args.hours == 4.0
    assert rep.to_dict()["look_alikes"][0]["command"] == la["command"]
    assert la["command"] in diagnosis(rep, str(path))


@pytest.mark.slow
def test_the_printed_command_runs(tmp_path):
    """The command diagnose prints designs a run (reduced search): the run's own record is
    the reference, its limits those of the run, the trend's fit near the truth."""
    from gyrostand.cli import build_parser

    _, _, _, rep = _trend_run_diagnosis(tmp_path)
    cmd = shlex.split(rep.look_alikes[0]["command"])
    args = build_parser().parse_args(cmd[1:])
    out = tmp_path / "d"
    p = subprocess.run([sys.executable, "-m", "gyrostand", *cmd[1:], "--evaluations", "4",
                        "--legs", "3", "--out", str(out), "--json"],
                       capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)
    assert doc["reference"] == "this run's record"
    assert doc["limits"]["t_min"] == args.t_min and doc["limits"]["duration_s"] == 4 * 3600
    assert set(doc["params"]) == {"trend", "warmup"}
    assert abs(doc["params"]["trend"]["trend.c"] / 1e-5 - 1) < 0.3


@pytest.mark.slow
def test_six_hour_design_separates_temp_lag_from_markov2_fourfold():
    """#15's acceptance: 6 h, 0..50 °C, <= 1 °C/min, soaks >= 10 min: the expected LR on the
    designed program >= 4x the standard cycle's, and of 50 simulated runs from the lag
    model on it, both models fitted by ML, the lag model wins >= 90 %."""
    lim = ChamberLimits(0, 50, 1 / 60, 600, 6 * 3600, legs=6)
    case = case_temperature(standard_cycle(lim).setpoint(lim.duration), lim)
    riv = rivals(Model.parse("markov,temp,bias"), "temp_lag", "markov2",
                 {**BASE, "temp_lag.tau": 60.0}, lim.grid, case, 1.0)
    res = separate(riv, lim, starts=2, maxfev=80)
    assert res.gain >= 4.0, (res.expected, res.reference_expected)
    designed = case_temperature(res.program.setpoint(lim.duration), lim)
    v = verify(riv, {"designed": (lim.grid, designed), "reference": (lim.grid, case)}, 50,
               seed=15)
    assert v["designed"]["temp_lag"]["right_wins_lr"] >= 0.9, v
    assert v["designed"]["temp_lag"]["mean_lr"] >= 4 * v["reference"]["temp_lag"]["mean_lr"]


# -- time-only rivals (trend / warmup): the budget split into switch-ons ---------------

def test_the_joint_distance_is_the_gls_distance_over_the_runs():
    """Two runs fitted by the warm-up model with a shared γ and each run's own bias and
    warm-up amplitude: the stacked Kalman-whitened least squares = the dense GLS with a
    block-diagonal covariance (the runs independent) and per-run columns."""
    from gyrostand.core.design.divergence import _joint_distance

    ma, mb = Model.parse("markov,temp,bias,trend"), Model.parse("markov,temp,bias,warmup")
    pa = {**BASE, "markov.beta": 0.02, "trend.c": 1e-4}
    pb = {**BASE, "markov.beta": 0.02, "warmup.A": 0.3, "warmup.tau": 200.0}
    recs, cols, ys, Cs = [], [], [], []
    for k, n in enumerate((300, 200)):
        t = np.arange(float(n))
        s = Samples(t, np.zeros_like(t), 25 + 10 * np.sin(t / (30.0 + 20 * k)), 1.0)
        s = s.replace(drift=mean_response(ma, pa, s))
        recs.append(s)
        ys.append(s.drift)
        cols.append(mb.regressors(pb, context(s, mb)))
        Cs.append(_dense_cov(mb, pb, n, 1.0))
    lin = mb.names_of_kind("linear")
    per = [lin.index("bias.b"), lin.index("warmup.A")]
    shared = [j for j in range(len(lin)) if j not in per]
    X = np.zeros((500, len(shared) + 2 * len(per)))
    X[:, :len(shared)] = np.vstack([c[:, shared] for c in cols])
    X[:300, len(shared):len(shared) + 2] = cols[0][:, per]
    X[300:, len(shared) + 2:] = cols[1][:, per]
    y = np.concatenate(ys)
    Ci = np.zeros((500, 500))
    Ci[:300, :300], Ci[300:, 300:] = np.linalg.inv(Cs[0]), np.linalg.inv(Cs[1])
    beta = np.linalg.solve(X.T @ Ci @ X, X.T @ Ci @ y)
    r = y - X @ beta
    assert _joint_distance(mb, [pb, pb], recs) == pytest.approx(float(r @ Ci @ r), rel=1e-6)


def test_k_alike_switch_ons_give_k_times_one_runs_expected_lr():
    """The same run repeated k times from its own switch-on, the truth alike in each: the
    joint refit's optimum is every run's own (the sum of k equal functions), so Λ is k ×
    one run's — with the warm-up's τ refitted per run, and the trend shared (measured:
    0.385 and 1.16 from the warm-up)."""
    from gyrostand.core.design.divergence import divergence_runs

    lim = ChamberLimits(0, 50, 1 / 60, 300, 1800, legs=3)
    case = case_temperature(standard_cycle(lim).setpoint(lim.duration), lim)
    ma, mb = Model.parse("markov,temp,bias,warmup"), Model.parse("markov,temp,bias,trend")
    pa = {**BASE, "warmup.A": 0.2, "warmup.tau": 400.0}
    pb = {**BASE, "trend.c": -5e-5}
    rec = (lim.grid, case)
    for truth, fit in (((ma, pa), (mb, pb)), ((mb, pb), (ma, pa))):
        one = divergence_runs(*truth, *fit, [rec], 1.0)
        three = divergence_runs(*truth, *fit, [rec] * 3, 1.0)
        # data from the warm-up: a clear Λ; from the trend: the warm-up's long τ mimics it
        assert one > 0.2 if truth[0] is ma else one < 1e-3, one
        assert three == pytest.approx(3 * one, rel=0.02, abs=1e-4), (truth[0], one, three)


def test_trend_and_warmup_are_time_only_and_a_split_budget_is_measured():
    """trend / warmup are named time-only (temp_lag / markov2 not); the budget split into
    switch-ons gives each split's Λ (measured at 2 h: both directions fall with the split,
    the per-run bias absorbing each restart's level), and the joint verify of a split design
    on data from a short warm-up picks the warm-up every time."""
    from gyrostand.core.design.divergence import divergence_runs
    from gyrostand.core.design.separation import Rivals, time_only
    from gyrostand.core.design.switch_ons import separate_switch_ons, switch_on_records

    lim = ChamberLimits(0, 50, 1 / 60, 600, 2 * 3600, legs=6)
    case = case_temperature(standard_cycle(lim).setpoint(lim.duration), lim)
    m = Model.parse("markov,temp,bias")
    riv = rivals(m, "trend", "warmup", {**BASE, "trend.c": 2e-5}, lim.grid, case, 1.0)
    assert time_only(riv)
    lag = rivals(m, "temp_lag", "markov2", {**BASE, "temp_lag.tau": 120.0, "markov2.beta":
                                            0.002, "markov2.sigma": 0.01}, lim.grid, case, 1.0)
    assert not time_only(lag)
    so = separate_switch_ons(riv, lim, max_runs=2, min_run=1800)
    assert set(so.expected) == {1, 2} and so.run_hours == {1: 2.0, 2: 1.0}
    one, two = so.expected[1], so.expected[2]
    assert one == pytest.approx({k: v for k, v in
                                 separate(riv, lim, starts=1, maxfev=1).reference_expected.items()},
                                rel=0.05, abs=1e-3)
    assert two["warmup"] < one["warmup"] and two["trend"] < one["trend"] + 1e-3, so.expected
    assert so.best == 1 and so.gain == 1.0
    # a split design's verify: several runs per set, both models fitted jointly
    short = Rivals("warmup", "trend", riv.model_b, riv.model_a,
                   {**BASE, "warmup.A": 0.3, "warmup.tau": 300.0}, {**BASE, "trend.c": -2e-5})
    recs = switch_on_records(dataclasses.replace(lim, duration=3600, legs=3), 2)
    assert len(recs) == 2 and recs[0][0][-1] == 1800
    v = verify(short, {"switch-ons": recs}, 3, seed=4)
    got = v["switch-ons"]["warmup"]
    lam = divergence_runs(short.model_a, short.params_a, short.model_b, short.params_b,
                          recs, 1.0)
    assert got["failed"] == 0 and got["right_wins_lr"] == 1.0, got
    assert 0.5 * lam <= got["mean_lr"] <= 2 * lam + 2, (got, lam)


def test_the_command_says_trend_and_warmup_are_time_only(tmp_path):
    """``design --separate trend warmup``: the command prints that the rivals are time-only,
    the table of the budget split into switch-ons and the reachable gain; design.json
    carries the splits."""
    out = tmp_path / "d"
    args = [sys.executable, "-m", "gyrostand", "design", "--model", "markov,temp,bias",
            *[f"--param={k}={v}" for k, v in {**BASE, "trend.c": 2e-5}.items()],
            "--separate", "trend", "warmup", "--hours", "2", "--legs", "3",
            "--evaluations", "3", "--out", str(out)]
    p = subprocess.run(args, capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr
    assert "trend and warmup are time-only effects" in p.stdout
    assert "the reachable gain over the standard cycle is" in p.stdout, p.stdout
    doc = json.loads((out / "design.json").read_text())
    so = doc["switch_ons"]
    assert so["time_only"] is True and [s["runs"] for s in so["splits"]] == [1, 2]
    assert so["splits"][0]["expected_lr"]["total"] == pytest.approx(
        doc["expected_lr"]["reference"]["total"], rel=0.05, abs=1e-3)
    rows = [ln.split() for ln in p.stdout.splitlines() if ln.strip()[:1] in ("1", "2")
            and len(ln.split()) == 6]
    assert [r[0] for r in rows] == ["1", "2"], p.stdout
    assert float(rows[1][4]) == pytest.approx(so["splits"][1]["expected_lr"]["total"],
                                              rel=1e-3)
