"""The converging LKF (feedback, re-linearisation, noise re-estimated) against exact ML.

The claims (benchmarks/lkf_accuracy.py measures them on 200 runs per cell): on the same
record the filter's fixed point is ML's estimate within a small fraction of its std, its
std is ML's within ~15 %, and so its Monte Carlo RMSE is ML's.
"""

import numpy as np
import pytest

from gyrostand.core.data import Samples
from gyrostand.core.lkf.filter import lkf
from gyrostand.core.lkf.relin import RelinLKF
from gyrostand.core.ml.fit import ml
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile, paper_profile
from gyrostand.core.simulation import simulate
from gyrostand.errors import ModelError

from ..conftest import truth

M = Model.parse("markov,temp")
NAMES = ("markov.beta", "temp.gamma")


@pytest.mark.parametrize("case,sigma_v", [("C1", 0.05), ("C2", 0.0), ("C2", 0.05),
                                          ("C3", 0.05)])
def test_batch_fixed_point_is_ml_run_by_run(case, sigma_v):
    for seed in range(3):
        s = simulate(M, truth(case, sigma_v=sigma_v), paper_profile(), seed=100 + seed)
        r = lkf(s, M)
        best = ml(s, M)
        assert r.info["settled"] and r.info["variant"] == "relin"
        for n in NAMES:
            assert abs(r.value(n) - best.value(n)) <= 0.3 * best.std(n), (seed, n)
            assert 0.85 <= r.std(n) / best.std(n) <= 1.15, (seed, n)
        # the noise levels it re-estimated are ML's too
        assert r.value("markov.sigma") == pytest.approx(best.value("markov.sigma"), rel=0.05)


def test_chamber_record_with_bias_and_temp_rate_matches_ml():
    """The bias enters as an input (c = βb) and the δβ column runs along the filtered
    level with the output terms at the point: without that the fixed point moved β by
    −30 % with a 4× too small std on such a record."""
    m = Model.parse("markov,temp,bias,temp_rate")
    p = {"markov.beta": 1 / 600, "markov.sigma": 0.05, "temp.gamma": 2e-5,
         "white.sigma": 0.02, "bias.b": 0.3, "temp_rate.k": 20.0}
    s = simulate(m, p, chamber_profile(3), seed=3)
    r = lkf(s, m)
    best = ml(s, m)
    for n in ("markov.beta", "temp.gamma", "bias.b", "temp_rate.k"):
        assert abs(r.value(n) - best.value(n)) <= 0.3 * best.std(n), n
        assert 0.8 <= r.std(n) / best.std(n) <= 1.15, n
        assert abs(r.value(n) - p[n]) <= 3 * r.std(n), n


def test_online_relinearisation_reaches_the_batch_fixed_point():
    s = simulate(M, truth("C2", sigma_v=0.05), paper_profile(), seed=8)
    y = s.drift.copy()
    y[[0, 700, 701, 1500]] = np.nan  # a gap at the start and two inside
    s = Samples.from_arrays(s.t, y, s.temp)
    f = RelinLKF(M, 1.0, point={"markov.beta": 0.08, "temp.gamma": -0.003},
                 held={"markov.sigma": 0.05, "white.sigma": 0.01}, relinearize_every=100)
    for k in range(len(s)):
        f.update(float(s.drift[k]), float(s.temp[k]))
        if k == 999:
            mid = f.estimates
    # every 100 bins to 1000, then every tenth of the record: 1100, 1210, ... 1948
    assert f.relinearizations == 17 and f.n == len(s) - 1  # starts at the first observed
    assert np.isfinite(mid["markov.beta"][1])
    f.relinearize()
    best = ml(s, M)
    for n in NAMES:
        assert abs(f.estimates[n][0] - best.value(n)) <= 0.3 * best.std(n), n
    e, v = f.innovations
    assert np.isnan(e[699]) and np.isnan(e[700])  # gaps (shifted by the skipped first bin)
    nis = np.nanmean(e * e / v)
    assert 0.85 < nis < 1.15  # innovations consistent with their variances


def test_reduced_monte_carlo_of_the_online_filter():
    """CI-sized Monte Carlo (C1, σ_v = σ/2, 16 runs): the online filter (re-linearised every
    100 bins, final re-linearisation at stop) has ML's RMSE, and its ±3σ band holds the
    truth. The full claim is the slow test in tests/session/test_online_lkf.py."""
    p = truth("C1", sigma_v=0.05)
    err_l, err_m, cover = [], [], 0
    for seed in range(16):
        s = simulate(M, p, paper_profile(), seed=900 + seed)
        f = RelinLKF(M, 1.0, point={"markov.beta": 0.05, "temp.gamma": -0.015},
                     held={"markov.sigma": 0.07, "white.sigma": 0.02}, relinearize_every=100)
        for y, T in zip(s.drift, s.temp, strict=True):
            f.update(float(y), float(T))
        f.relinearize()
        b, sb = f.estimates["markov.beta"]
        err_l.append(b / p["markov.beta"] - 1)
        err_m.append(ml(s, M).value("markov.beta") / p["markov.beta"] - 1)
        cover += abs(b - p["markov.beta"]) <= 3 * sb
    rl, rm = np.sqrt(np.mean(np.square(err_l))), np.sqrt(np.mean(np.square(err_m)))
    assert rl <= 1.1 * rm, (rl, rm)
    assert cover >= 15


def test_fixed_noise_levels_stay_and_bad_input_is_refused():
    s = simulate(M, truth("C1", sigma_v=0.05), paper_profile(), seed=4)
    r = lkf(s, M, sigma=0.1, held={"white.sigma": 0.05})
    assert r.value("markov.sigma") == 0.1 and r.parameters["markov.sigma"].fixed
    assert r.value("white.sigma") == 0.05
    with pytest.raises(ModelError, match="markov.beta must be > 0"):
        RelinLKF(M, 1.0, point={"markov.beta": 0.0}, held={"markov.sigma": 0.1,
                                                            "white.sigma": 0.0})
    with pytest.raises(ModelError, match="held parameter"):
        RelinLKF(M, 1.0, point={"markov.beta": 0.03}, held={"markov.sigma": 0.1})
    with pytest.raises(ModelError, match="unknown lkf variant 'x'"):
        lkf(s, M, variant="x")


def _chamber_6h(seed: int) -> tuple[Model, dict[str, float], Samples]:
    """benchmarks/lkf_accuracy.py's 6-h chamber run (ramps of 30 °C/h, soaks)."""
    from gyrostand.core.profiles import TemperatureProfile

    m = Model.parse("markov,temp,bias,white,temp_rate")
    p = {"markov.beta": 1 / 600, "markov.sigma": 0.05, "temp.gamma": 2e-5,
         "white.sigma": 0.02, "bias.b": 0.3, "temp_rate.k": 20.0}
    prof = TemperatureProfile.from_breakpoints(
        [(0, 20), (3600, 50), (7200, 50), (9000, 30), (12600, 30), (16200, 60),
         (18000, 60), (21600, 25)])
    return m, p, simulate(m, p, prof, seed=seed)


def test_a_rate_term_gets_the_centred_rate_half_a_window_late():
    """Each filtered bin's dT/dt is ML's (the 61-s window centred on it), the filter 30
    bins behind the newest one, and flush takes those at stop with the record's end rates:
    the regressors equal the batch's column to rounding, at the corners of the ramps too
    (the causal slope there was off by up to half the ramp rate)."""
    from gyrostand.core.model import context

    m, p, s = _chamber_6h(5)
    s = Samples.from_arrays(s.t[:8000], s.drift[:8000], s.temp[:8000])
    rate = context(s, m).temp_rate
    f = RelinLKF(m, 1.0, point={"markov.beta": 1 / 600, "temp.gamma": 2e-5, "bias.b": 0.3},
                 held={"markov.sigma": 0.05, "white.sigma": 0.02}, relinearize_every=100)
    assert f.lag == 30
    for k in range(len(s)):
        f.update(float(s.drift[k]), float(s.temp[k]))
        if k == 29:
            assert f.n == 0 and f.pending == 30  # the first window is not in yet
        if k == 3630:  # half a minute after the first ramp's end (3600 s)
            assert f.n == 3601 and f.pending == 30
            # the corner's bins, centred on the soak's first temperatures
            assert np.allclose(f.regressors[:, 0], rate[:3601], rtol=0, atol=1e-12)
            assert abs(f.regressors[3600, 0] - rate[3600]) < 1e-12
    f.flush()
    assert f.n == len(s) and f.pending == 0
    assert np.allclose(f.regressors[:, 0], rate, rtol=0, atol=1e-12)
    # a model without a rate term filters each bin at once
    g = RelinLKF(M, 1.0, point={"markov.beta": 0.03}, held={"markov.sigma": 0.1,
                                                            "white.sigma": 0.05})
    g.update(0.1, 20.0)
    assert g.lag == 0 and g.n == 1


def test_the_online_k_band_holds_through_a_ramp_corner():
    """Seed 19 of the 6-h chamber benchmark, an ML tail run (its temp_rate.k 3.7 std low
    at stop, the ML fit's too): with the causal slope the online k sat 5.0 std below the
    truth for the 1100 s after the heating ramp's end (16,300-17,400 s); centred it
    stays within its ±3σ band there, as the whole record's fixed point does."""
    from gyrostand.config import LkfConfig
    from gyrostand.core.tracking import LkfTrack

    m, p, s = _chamber_6h(19)
    track = LkfTrack(m, LkfConfig(), s.dt)
    z = {}
    for k in range(len(s)):
        track.update(float(s.drift[k]), float(s.temp[k]))
        if k + 1 in (16600, 17000):
            v, sd = track.estimate().values["temp_rate.k"]
            z[k + 1] = (v - p["temp_rate.k"]) / sd
    assert all(-3.0 < v < -2.5 for v in z.values()), z
