"""The daemon's online LKF (issue 9): one meaning per label on the bus and in the files, an
honest status, and the Monte Carlo claims of benchmarks/lkf_accuracy.py on reduced sets."""

from __future__ import annotations

import csv
import json
import re

import numpy as np
import pytest
from sessionhelpers import TRUTH, decode, last_results, make_cfg, run_virtual

from gyrostand.can.bus import STATUS_CODES
from gyrostand.config import LkfConfig
from gyrostand.core.ml.fit import ml
from gyrostand.core.model import Model
from gyrostand.core.profiles import paper_profile
from gyrostand.core.simulation import simulate
from gyrostand.session.offline import simulated_frames
from gyrostand.session.online import LkfTrack

PARAMS = ("markov.beta", "markov.sigma", "temp.gamma", "white.sigma")  # model order
LKF, ML = 0, 2
M = Model.parse("markov,temp")
CASES = {"C1": (0.0333, -0.01), "C2": (0.0333, -0.001), "C3": (0.00055, -0.001)}


@pytest.fixture(scope="module")
def default_run(tmp_path_factory):
    """The demo's session (default lkf section: warm-up, then re-linearised every 100 s,
    noise levels re-estimated), the paper's C2 scenario on the virtual bus."""
    cfg = make_cfg(tmp_path_factory.mktemp("lkf"))
    outcome, seen, _ = run_virtual(cfg, simulated_frames(cfg))
    return cfg, outcome, seen


def test_lkf_means_the_online_value_at_stop_on_the_bus_and_in_every_file(default_run):
    cfg, outcome, seen = default_run
    assert outcome.ok
    doc = json.loads(outcome.result_json.read_text())
    g = doc["gyros"]["az"]
    fit = g["fits"]["lkf"]
    assert fit["info"]["online"] and fit["info"]["variant"] == "relin"
    online = g["online"]["lkf"]
    res = last_results(cfg, seen, "GS_RESULT_1")
    report = outcome.report.read_text()
    rows = {line.split()[0]: line for line in report.splitlines() if line.split()}
    for i, name in enumerate(PARAMS):
        v, s = fit["parameters"][name]["value"], fit["parameters"][name]["std"]
        # the last CAN round (float32) = result.json fits.lkf = result.json online.lkf
        assert res[LKF][i][0] == pytest.approx(v, rel=1e-6, abs=1e-12), name
        assert res[LKF][i][1] == pytest.approx(s, rel=1e-6, abs=1e-12), name
        assert online["parameters"][name] == {"value": v, "std": s}, name
        # ... = report.txt's lkf column (the first after the truth), 5 digits
        cells = re.findall(r"(-?[\d.e+-]+) (?:± [\d.e+-]+|\(held\))", rows[name])
        assert float(cells[0]) == pytest.approx(v, rel=1e-4), (name, rows[name])
    # the batch refit is a different label, and agrees with the online value here
    batch = g["fits"]["lkf_batch"]
    assert batch["info"].get("online") is None
    for name in ("markov.beta", "temp.gamma"):
        b, v = batch["parameters"][name], fit["parameters"][name]
        assert abs(b["value"] - v["value"]) <= 0.05 * v["std"], name
    assert "lkf = the online LKF at stop" in report
    # the status: GS_SUMMARY = estimates.csv's last row = result.json
    summ = [d for d in decode(cfg, seen, "GS_SUMMARY_1") if d["Identifier"] == LKF]
    with (outcome.run_dir / "az" / "estimates.csv").open() as fh:
        last = list(csv.DictReader(fh))[-1]
    assert summ[-1]["Status"] == STATUS_CODES[online["status"]] == STATUS_CODES[
        fit["info"]["status"]]
    assert last["lkf:status"] in STATUS_CODES
    # and the online value is where it should be: ML's ±2σ, the truth's ±3σ
    best = g["fits"]["ml"]["parameters"]
    for name in ("markov.beta", "temp.gamma"):
        v, s = fit["parameters"][name]["value"], fit["parameters"][name]["std"]
        assert abs(v - best[name]["value"]) <= 2 * best[name]["std"], name
        assert abs(v - TRUTH[name]) <= 3 * s, name


def _track(y, T, **cfg):
    tr = LkfTrack(M, LkfConfig(**cfg), 1.0)
    for a, b in zip(y, T, strict=True):
        tr.update(float(a), float(b))
    return tr


def test_status_is_never_ok_with_beta_at_or_below_zero_or_a_band_holding_zero():
    s = simulate(M, {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.001,
                     "white.sigma": 0.05}, paper_profile(), seed=2)
    given = {"beta0": 0.0333, "gamma0": -0.001, "b0": 0.0, "sigma": 0.1,
             "white_sigma": 0.05}
    early = _track(s.drift[:40], s.temp[:40], **given).estimate()
    assert early.status == "warning" and "contains 0" in early.note
    full = _track(s.drift, s.temp, **given)
    full.finish()
    e = full.estimate()
    b, sb = e.values["markov.beta"]
    assert b - 3 * sb > 0
    # with the noise levels held at the truth the filter ends at β̂ 0.064 (its own band
    # ± 0.010, 3.0 of them from the truth 0.0333) while the record's likelihood given
    # those levels is highest near 0.034, D(β̂) 24.7: the point is off its maximum and the
    # status says so (session 24); the reported band, widened to the profile interval
    # (± 0.014), still holds the truth
    assert abs(b - 0.0333) < 3 * sb
    assert e.status == "warning" and "not its likelihood's maximum" in e.note, e.note
    # a model that is wrong for the data (a 10x too small σ held): the innovations say so
    wrong = _track(s.drift, s.temp, **{**given, "sigma": 0.01, "white_sigma": 0.005})
    w = wrong.estimate()
    assert w.status == "failed" and "innovations inconsistent" in w.note, w.note
    # the paper's single pass: never ok, and says why
    paper = _track(s.drift, s.temp, **given, variant="paper").estimate()
    assert paper.status == "warning" and "paper variant" in paper.note
    # whatever the estimate, ok implies a positive β whose ±3σ band excludes 0
    for n in (60, 120, 400, 900, 2001):
        t = _track(s.drift[:n], s.temp[:n])
        est = t.estimate()
        if est.status == "ok":
            b, sb = est.values["markov.beta"]
            assert b > 0 and b - 3 * sb > 0, n


def _online_mc(case, sigma_v, runs, seed0):
    beta, gamma = CASES[case]
    p = {"markov.beta": beta, "markov.sigma": 0.1, "temp.gamma": gamma,
         "white.sigma": sigma_v}
    rows = []
    for i in range(runs):
        s = simulate(M, p, paper_profile(), seed=seed0 + i)
        tr = LkfTrack(M, LkfConfig(), 1.0)
        cover = []
        for k, (y, T) in enumerate(zip(s.drift, s.temp, strict=True), start=1):
            tr.update(float(y), float(T))
            if k % 100 == 0 and k >= 400:
                v = tr.estimate().values
                cover.append(all(abs(v[n][0] - p[n]) <= 3 * v[n][1]
                                 for n in ("markov.beta", "temp.gamma")))
        tr.finish()
        v = tr.estimate().values
        r = ml(s, M)
        rows.append((v["markov.beta"][0], v["markov.beta"][1], r.value("markov.beta"),
                     v["temp.gamma"][0], r.value("temp.gamma"), cover))
    a = np.array([r[:5] for r in rows])
    rel = lambda x, t: np.sqrt(np.mean(((x - t) / t) ** 2))  # noqa: E731
    cov = np.mean([r[5] for r in rows], axis=0)
    return (rel(a[:, 0], beta) / rel(a[:, 2], beta), rel(a[:, 3], gamma) / rel(a[:, 4], gamma),
            float(np.std(a[:, 0]) / np.mean(a[:, 1])), cov)


def test_reduced_monte_carlo_of_the_daemons_online_lkf():
    """CI-sized (C2, σ_v = σ/2, 12 runs): RMSE of β and γ within 15 % of ML's."""
    rb, rg, _, cov = _online_mc("C2", 0.05, 12, 7000)
    assert rb <= 1.15 and rg <= 1.15, (rb, rg)
    assert cov.min() >= 10 / 12


@pytest.mark.slow
@pytest.mark.parametrize("case,sigma_v", [(c, v) for c in CASES for v in (0.0, 0.05)])
def test_monte_carlo_of_the_daemons_online_lkf(case, sigma_v):
    """100 runs per cell (benchmarks/lkf_accuracy.py: 200): RMSE ≤ 1.1 × ML (C3: 1.2),
    spread / reported std within 0.85-1.2, ±3σ coverage ≥ 0.95 at every 100-s checkpoint
    after the warm-up (≥ 0.98 on the benchmark's runs; C3 σ_v = σ/2 at 400 s, where ML's
    own band covers 0.84: 0.99)."""
    rb, rg, spread, cov = _online_mc(case, sigma_v, 100, 20_000)
    lim = 1.2 if case == "C3" else 1.1
    assert rb <= lim and rg <= lim, (rb, rg)
    assert 0.85 <= spread <= 1.2, spread
    # C3 σ_v = σ/2 at 400-500 s: 0.99 on the benchmark's 200 runs (ML's own band: 0.84),
    # from 0.955-0.96 with the noise share from the profile's ends, 0.875 before that
    assert cov.min() >= 0.95, cov


def test_a_short_record_with_a_poorly_determined_noise_level_keeps_an_honest_band():
    """C3, σ_v = σ/2, the first 400 s (100 bins after the warm-up): the drift's σ is
    barely determined (often searched to its bound, σ_v/σ = 100). The band whose noise
    share came from the profile's curvature, or a fixed step at a bound, held the truth
    (β and γ both) in 35 of these 40 runs; with one-std shifts to the ends of the
    profile likelihood's ±3σ interval, 38. It is now the union of the filter's ±3σ bands
    over that interval: 40, and at least 39 asserted."""
    beta, gamma = CASES["C3"]
    p = {"markov.beta": beta, "markov.sigma": 0.1, "temp.gamma": gamma, "white.sigma": 0.05}
    held = 0
    for seed in range(40):
        s = simulate(M, p, paper_profile(), seed=seed)
        tr = LkfTrack(M, LkfConfig(), 1.0)
        for y, T in zip(s.drift[:400], s.temp[:400], strict=True):
            tr.update(float(y), float(T))
        v = tr.estimate().values
        held += all(abs(v[n][0] - p[n]) <= 3 * v[n][1] for n in ("markov.beta", "temp.gamma"))
    assert held >= 39, held
