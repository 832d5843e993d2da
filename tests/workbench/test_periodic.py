"""A periodic disturbance (issue 23: an effect outside the vocabulary the workbench gave no
next step for): Fisher's test on the innovations at the saturated reference
(:mod:`gyrostand.core.diagnose.periodic`) finds its period and amplitude in a run built from
frames, the verdict names it and ``term new`` writes a sine and a cosine that make the model
adequate; a clean run and a hidden in-vocabulary effect are not reported."""

from __future__ import annotations

import numpy as np
import pytest

from gyrostand.cli import main
from gyrostand.core.data import Samples
from gyrostand.core.diagnose import periodic as pe
from gyrostand.core.diagnose.reference import reference_fit
from gyrostand.core.diagnose.verdict import diagnose
from gyrostand.core.ml.fit import ml
from gyrostand.core.model import Model

from .framelike import frame_run
from .plugin_run import fit_and_diagnose

#: the disturbance: deg/h, s
AMP, PERIOD = 0.05, 900.0


def cycling_run(tmp_path, seed, amp=AMP, period=PERIOD, **kw):
    return frame_run(tmp_path / f"cyc{seed}.csv", seed=seed, drop=0.01,
                     event=lambda t: amp * np.sin(2 * np.pi * t / period + 0.7), **kw)


def periodic_of(path, model="markov,temp,bias"):
    s = Samples.read_csv(path)
    m = Model.parse(model)
    fit = ml(s, m)
    return s, m, fit, reference_fit(s, m, fit)


def test_fisher_p_is_the_exact_law_of_the_largest_ordinate():
    # Fisher's g of white noise: P(g > x) against 4000 simulated periodograms of 301
    # ordinates, at the law's 50, 10 and 1 % points; and its first term where it is small
    rng = np.random.default_rng(5)
    q = 301
    power = np.abs(np.fft.rfft(rng.standard_normal((4000, 2 * q + 2)), axis=1)[:, 1:q + 1]) ** 2
    g = power.max(axis=1) / power.sum(axis=1)
    for x in np.quantile(g, [0.5, 0.9, 0.99]):
        assert pe.fisher_p(float(x), q) == pytest.approx(float(np.mean(g > x)), abs=0.012)
    assert pe.fisher_p(0.1, q) == pytest.approx(q * 0.9 ** (q - 1), rel=1e-9)
    assert pe.fisher_p(0.0, q) == 1.0 and pe.fisher_p(1.0, q) == 0.0


@pytest.mark.parametrize("seed", [41, 42])
def test_a_cycling_chamber_is_found_with_its_period_and_amplitude(tmp_path, seed):
    s, m, fit, ref = periodic_of(cycling_run(tmp_path, seed))
    r = pe.periodic(s, ref)
    assert r is not None and r.significant, r
    assert abs(r.period - PERIOD) < 0.01 * PERIOD, r
    assert abs(r.amplitude - AMP) < 3 * r.std and r.std < 0.015, r
    rep = diagnose(s, m, base=fit)
    assert not rep.adequate and rep.cycling and rep.outside
    assert rep.reasons[0].startswith("a periodic disturbance of the drift at a period of")
    assert rep.to_dict()["periodic"]["significant"] is True


def test_clean_runs_and_a_hidden_vocabulary_effect_show_no_line(tmp_path):
    for path in (frame_run(tmp_path / "c43.csv", seed=43, drop=0.01),
                 frame_run(tmp_path / "c44.csv", seed=44, drop=0.01, hours=2.0),
                 frame_run(tmp_path / "rate.csv", ["temp_rate"], {"temp_rate.k": 5.0},
                           seed=45, drop=0.01)):
        s, _, _, ref = periodic_of(path)
        r = pe.periodic(s, ref)
        assert r is not None and not r.significant, (path.name, r)


def test_term_new_writes_the_sinusoid_and_the_model_with_it_is_adequate(tmp_path, capsys):
    csv = cycling_run(tmp_path, 46)
    assert main(["term", "new", "--from", str(csv), "--name", "cycle_a"]) == 0
    assert "missing shape: a periodic disturbance at a period of" in capsys.readouterr().out
    pkg = tmp_path / "gyrostand-cycle-a"
    assert "PERIOD = " in (pkg / "gyrostand_cycle_a.py").read_text()
    step, d = fit_and_diagnose(pkg, csv, "cycle_a", cwd=tmp_path)
    assert step["added"] == ["cycle_a"] and step["p_value"] < 1e-6
    a, b = step["parameters"]["cycle_a.a"], step["parameters"]["cycle_a.b"]
    # a·sin + b·cos = 0.05·sin(ωt + 0.7) (t from the first bin, 0.07 s after the
    # simulation's start: a phase of 5e-4 rad)
    assert abs(a["value"] - AMP * np.cos(0.7)) < 3 * a["std"], a
    assert abs(b["value"] - AMP * np.sin(0.7)) < 3 * b["std"], b
    assert "cycle_a" in d["model"]
    assert d["periodic"]["significant"] is False, d["periodic"]
    assert d["adequate"] is True, d["reasons"]
