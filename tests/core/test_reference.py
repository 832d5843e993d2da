"""The saturated reference (issue 23, :mod:`gyrostand.core.diagnose.reference`): no lack of
fit on a clean run, a lack of fit with the right group named on a shape outside the
vocabulary, and the random part the misfit moved."""

from __future__ import annotations

import numpy as np

from gyrostand.core.data import Samples
from gyrostand.core.diagnose.reference import LACK_OF_FIT_ALPHA, reference_fit
from gyrostand.core.ml.fit import ml
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate

BASE = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
        "white.sigma": 0.02, "bias.b": 0.3}
M = Model.parse("markov,temp,bias")


def _run(seed: int, hours: float, extra=None) -> Samples:
    s = simulate(M, BASE, chamber_profile(hours), seed=seed)
    drift = s.drift + (extra(s) if extra is not None else 0.0)
    rng = np.random.default_rng(seed + 1)
    temp = np.round((s.temp + 0.01 * rng.standard_normal(len(s))) / 0.05) * 0.05
    return Samples.from_arrays(s.t, drift, temp)


def test_a_clean_run_shows_no_lack_of_fit():
    s = _run(21, 2.0)
    r = reference_fit(s, M, ml(s, M))
    assert r.df >= 10 and r.p_value > LACK_OF_FIT_ALPHA, (r.lr, r.df, r.p_value)
    assert not r.traded and not r.significant


def test_a_cubic_in_t_is_a_lack_of_fit_in_the_temperature_group():
    s = _run(11, 3.0, lambda s: 4e-5 * (s.temp - 35.0) ** 3)
    fit = ml(s, M)
    r = reference_fit(s, M, fit)
    assert r.significant and r.p_value < 1e-6
    # the misfit moved the fit's random part; the floor's noise is the reference's
    assert r.traded and r.noise["markov.sigma"] < fit.values["markov.sigma"]
    top = r.missing()[0]
    assert top.group == "temperature" and top.p_value < 1e-6
    # the partial effect has the cubic's shape beyond a line: its curvature changes sign
    resid = top.effect - np.polyval(np.polyfit(top.x, top.effect, 1), top.x)
    truth = 4e-5 * (top.x - 35.0) ** 3
    truth = truth - np.polyval(np.polyfit(top.x, truth, 1), top.x)
    assert np.corrcoef(resid, truth)[0, 1] > 0.8
