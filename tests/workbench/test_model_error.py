"""The model error a user watches: open-loop and h-step prediction errors, their floor,
and bins weighted by the frames they hold.

Runs are 4-hour chamber cycles (as in test_hidden_effects) with effects of a size an
engineer would care about (RMS at least the model's own 60-s floor, ~0.045 deg/h).
"""

import json

import numpy as np
import pytest

from gyrostand.cli import main
from gyrostand.core.data import Samples
from gyrostand.core.diagnose.reference import reference_fit
from gyrostand.core.diagnose.verdict import diagnose, fit_error
from gyrostand.core.kalman import kf_run
from gyrostand.core.ml.fit import ml
from gyrostand.core.model import LOG_2PI, Model
from gyrostand.workbench import open_subject, read_ledger, run_diagnose, run_fit

from .framelike import frame_run
from .test_hidden_effects import chamber_run

#: hidden term -> its true parameters (effects clearly above the noise)
VISIBLE = {
    "temp_rate": {"temp_rate.k": 10.0},
    "hysteresis": {"hysteresis.h": 0.15},
    "trend": {"trend.c": 3e-5},
    "warmup": {"warmup.A": 0.5, "warmup.tau": 900.0},
    "temp_lag": {"temp_lag.tau": 600.0},
    "temp2": {"temp2.gamma2": 5e-6},
}


@pytest.mark.parametrize("term", list(VISIBLE))
def test_unexplained_open_loop_error_falls_when_the_effect_is_added(term, tmp_path):
    """The acceptance figure: unexplained part of the open-loop error (60-s means, whole
    run) over the true model's floor falls by at least 70 %."""
    path = chamber_run(tmp_path, [term], VISIBLE[term], seed=100 + list(VISIBLE).index(term))
    step = run_fit(open_subject(path), add=[term])
    eb, ea = step.before_error, step.after_error
    floor = ea.floor
    before = np.sqrt(max(eb.rms**2 - floor**2, 0.0))
    after = np.sqrt(max(ea.rms**2 - floor**2, 0.0))
    print(f"{term}: open-loop error {eb.rms:.4f} -> {ea.rms:.4f}, floor {floor:.4f}, "
          f"unexplained {before:.4f} -> {after:.4f} ({100 * (1 - after / before):.0f} % fall)")
    assert before > 0.5 * floor  # the effect is visible in the base model's error
    assert after <= 0.3 * before
    assert ea.at_floor()
    d = step.to_dict()
    for side in ("before", "after"):
        assert d[side]["model_error"] == pytest.approx(
            (eb if side == "before" else ea).rms)
        assert d[side]["model_error_floor"] > 0
    entry = read_ledger(open_subject(path).ledger_path)[-1]
    assert entry["after"]["model_error"] < entry["before"]["model_error"]


def test_model_error_sits_at_its_floor_for_data_that_follow_the_model(tmp_path):
    s = Samples.read_csv(chamber_run(tmp_path, [], {}, seed=11))
    fit = ml(s, Model.parse("markov,temp,bias"))
    err = fit_error(fit, s)
    for h in (0.0, 1.0, 60.0, 600.0):
        for w in (60.0, 600.0):
            run = err.entries[(h, w)][0]
            assert 0.6 < run["rms"] / run["floor"] < 1.3, (h, w, run)
    # one-step errors average out over a window; open-loop ones keep the Markov part
    assert err.entries[(1.0, 60.0)][0]["rms"] < 0.2 * err.entries[(0.0, 60.0)][0]["rms"]
    assert err.at_floor()
    assert err.headline()["fit_percent"] > 50
    # within the floor's spread nothing is unexplained; beyond it, the part above the floor
    for rows in err.entries.values():
        for row in rows:
            if row["rms"] is None or row["floor_limit"] is None:
                continue
            if row["rms"] <= row["floor_limit"]:
                assert row["unexplained"] == 0.0, row
            else:
                assert row["unexplained"] == pytest.approx(
                    np.sqrt(row["rms"] ** 2 - row["floor"] ** 2)), row
    assert err.headline()["unexplained"] == 0.0
    hidden = Samples.read_csv(chamber_run(tmp_path, ["temp_rate"], VISIBLE["temp_rate"],
                                          seed=100))
    base = ml(hidden, Model.parse("markov,temp,bias"))
    # the floor from the saturated reference's random part, as diagnose takes it
    h = fit_error(base, hidden, reference=reference_fit(hidden, base.model, base)).headline()
    assert not h["at_floor"]
    assert h["unexplained"] == pytest.approx(np.sqrt(h["rms"] ** 2 - h["floor"] ** 2))
    assert h["unexplained"] > 0.5 * h["rms"]


def test_diagnose_json_has_the_model_error_contract(tmp_path, capsys):
    path = chamber_run(tmp_path, ["temp_rate"], VISIBLE["temp_rate"], seed=100)
    assert main(["diagnose", str(path), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    me = d["model_error"]
    assert me["windows_s"] == [60.0, 600.0] and me["horizons_s"] == [1.0, 60.0, 600.0]
    for block in [me["open_loop"], *me["k_step"].values()]:
        for w in ("60", "600"):
            run = block[w]["run"]
            assert {"rms", "max", "fit_percent", "floor", "unexplained"} <= set(run)
            assert run["max"] >= run["rms"] > 0
            assert block[w]["segments"] and {"kind", "t_start", "t_stop", "rms"} <= set(
                block[w]["segments"][0])
    assert me["headline"]["rms"] == me["open_loop"]["60"]["run"]["rms"]
    assert main(["diagnose", str(path)]) == 0
    out = capsys.readouterr().out
    assert "model error (open loop" in out and "600-s ahead" in out
    steps = read_ledger(open_subject(path).ledger_path)
    assert steps[-1]["model_error"] > 0 and steps[-1]["model_error_floor"] > 0


def test_weighted_likelihood_equals_the_dense_gaussian_one():
    """R_k = σ_v² n̄/n_k in the Kalman kernel == the exact Gaussian density of the bins."""
    rng = np.random.default_rng(3)
    N = 120
    counts = rng.integers(1, 11, N).astype(float)
    y = rng.standard_normal(N)
    phi, q, p0, r = np.array([0.95]), np.array([0.1]), np.array([1.0]), 0.3
    w = counts.mean() / counts
    _, _, G, slogf, n = kf_run(phi, q, p0, r, w, y[:, None].copy(), False)
    ll = -0.5 * (n * LOG_2PI + slogf + G[0, 0])
    k = np.arange(N)
    var_x = p0[0] * phi[0] ** (2 * k) + q[0] * (1 - phi[0] ** (2 * k)) / (1 - phi[0] ** 2)
    C = phi[0] ** np.abs(k[:, None] - k[None, :]) * var_x[np.minimum.outer(k, k)]
    C += np.diag(r * w)
    sign, logdet = np.linalg.slogdet(C)
    dense = -0.5 * (N * LOG_2PI + logdet + y @ np.linalg.solve(C, y))
    assert ll == pytest.approx(dense, rel=1e-10)


def test_a_one_frame_first_bin_is_weighted_not_an_outlier(tmp_path):
    """The issue's case 1: a log that starts just before a bin ends leaves one frame in the
    first bin (50 in the others) and one in the last; unweighted, a warm-up with τ ≈ 0.5 s
    'explains' the first sample; weighted by its frame count, nothing is significant."""
    path = frame_run(tmp_path / "partial.csv", seed=9, start_offset=0.99, end_cut=0.98,
                     drift_hz=50, temp_hz=1, params={"markov.sigma": 0.01, "white.sigma": 0.1})
    s = Samples.read_csv(path)
    assert s.counts[0] == 1 and s.counts[1] == 50
    base = Model.parse("markov,temp,bias")
    unweighted = diagnose(s.replace(counts=None), base)
    lr_unweighted = {c.term: c for c in unweighted.candidates}["warmup"]
    # the one sample's 'explanation' (τ at its 3-Δt bound, so no longer ranked either)
    level = 0.05 / len(unweighted.candidates)
    assert lr_unweighted.p_value < level and lr_unweighted.effect["warmup.tau"].value < 5
    rep = run_diagnose(open_subject(path), record=False)
    assert rep.adequate, (rep.reasons, [(c.term, c.p_value) for c in rep.candidates[:3]])
    assert {c.term: c for c in rep.candidates}["warmup"].p_value > 10 * level


def test_units_come_from_unit_and_reach_tables_json_and_plots(tmp_path, capsys):
    path = chamber_run(tmp_path, ["temp_rate"], VISIBLE["temp_rate"], seed=100)
    assert main(["diagnose", str(path), "--unit", "deg/h", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["unit"] == "deg/h" and d["model_error"]["unit"] == "deg/h"
    assert d["parameters"]["temp.gamma"]["unit"] == "(deg/h)/(s·°C)"
    assert d["parameters"]["bias.b"]["unit"] == "deg/h"
    eff = {c["term"]: c["effect"] for c in d["candidates"]}
    assert eff["temp_rate"]["temp_rate.k"]["unit"] == "(deg/h)·s/°C"
    assert main(["fit", str(path), "--unit", "deg/h", "--add", "temp_rate"]) == 0
    out = capsys.readouterr().out
    assert "(deg/h)·s/°C" in out and " y " not in out and "deg/h" in out
    assert main(["fit", str(path), "--unit", "deg/h", "--remove", "temp_rate",
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["unit"] == "deg/h"
