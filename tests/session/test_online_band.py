"""The online LKF's status covers every reported coefficient (issue 24, item 6): `ok` only
where each band is calibrated, a `warning` naming the coefficient otherwise.
benchmarks/lkf_accuracy.py measures the coverage among `ok` statuses on 100 runs per
scenario; the slow test here on a reduced set."""

from __future__ import annotations

import numpy as np
import pytest

from gyrostand.config import LkfConfig
from gyrostand.core.lkf.band import REL_BETA_MAX, band_warnings
from gyrostand.core.lkf.profile import profile_interval
from gyrostand.core.lkf.relin import RelinLKF
from gyrostand.core.ml.fit import ml
from gyrostand.core.model import Model
from gyrostand.core.profiles import TemperatureProfile, chamber_profile, paper_profile
from gyrostand.core.simulation import simulate
from gyrostand.session.online import LkfTrack

#: gyro x of configs/three-gyros.yaml on its first hour (20 -> 60 degC in 30 min)
X_TRUTH = {"markov.beta": 0.002, "markov.sigma": 0.05, "temp.gamma": -0.0001,
           "bias.b": 0.3, "white.sigma": 0.01}
X_MODEL = Model.parse("markov,temp,bias")
X_PROFILE = TemperatureProfile.from_breakpoints([(0, 20), (1800, 60), (3600, 60)])
CH_TRUTH = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
            "white.sigma": 0.02, "bias.b": 0.3}
CH_MODEL = Model.parse("markov,temp,bias,white")


def _covered(values, truth):
    return all(abs(values[n][0] - truth[n]) <= 3 * values[n][1]
               for n in truth if values[n][1] > 0)


def test_a_warning_names_the_coefficient_whose_band_is_not_calibrated():
    s = simulate(Model.parse("markov,temp,bias,white"), X_TRUTH, X_PROFILE, duration=3600,
                 seed=3)
    tr = LkfTrack(X_MODEL, LkfConfig(), 1.0)
    notes = {}
    for k, (y, T) in enumerate(zip(s.drift.tolist(), s.temp.tolist(), strict=True), 1):
        tr.update(y, T)
        if k in (800, 3600):
            notes[k] = tr.estimate()
    early, late = notes[800], notes[3600]
    b, sb = early.values["markov.beta"]
    # 800 s: β known to ±{sb / b:.0%}; b = c/β by the delta method is not calibrated yet
    assert sb / b > REL_BETA_MAX and early.status == "warning"
    assert "bias.b's band (b = c/β)" in early.note, early.note
    b, sb = late.values["markov.beta"]
    assert sb / b <= REL_BETA_MAX and late.status == "ok", late.note
    # before the data say anything, a coefficient still near its prior is named (its std
    # 0.91 of the prior's after one bin; β's 0.41)
    f = RelinLKF(Model.parse("markov,temp"), 1.0, point={"markov.beta": 0.03,
                                                         "temp.gamma": -0.001},
                 held={"markov.sigma": 0.1, "white.sigma": 0.05}, relinearize_every=100)
    f.update(0.05, 30.0)
    w = band_warnings(f)
    assert any(line.startswith("temp.gamma not identified yet") for line in w), w


def test_an_unsettled_point_is_reported_once_with_the_bin_where_it_began():
    truth = {**X_TRUTH, "temp_rate.k": 50.0, "hysteresis.h": 0.5}
    s = simulate(Model.parse("markov,temp,bias,white,temp_rate,hysteresis"), truth,
                 chamber_profile(1.0), seed=2)
    f = RelinLKF(Model.parse("markov,temp,bias,white"), 1.0,
                 point={"markov.beta": 0.002, "temp.gamma": -0.0001, "bias.b": 0.3},
                 held={"markov.sigma": 0.05, "white.sigma": 0.01}, relinearize_every=100)
    seen = []
    for y, T in zip(s.drift[:700].tolist(), s.temp[:700].tolist(), strict=True):
        f.update(y, T)
        seen += [w for w in band_warnings(f) if "has not settled" in w]
    first = f.schedule.unsettled_since
    assert seen and first is not None, f.last
    assert len(set(seen)) == 1 and f"since bin {first} " in seen[0], set(seen)


def test_ok_never_stands_on_a_bias_band_whose_beta_is_too_uncertain():
    """Three 1-h chamber runs, every 100 s: whenever σ_β/β > REL_BETA_MAX the status is
    not `ok` and its note names bias.b; some checkpoints are `ok` (before the rule, on the
    benchmark's 100 runs: `ok` from 500 s, b's band missing in 0.3-0.4 of the `ok` runs at
    800-1000 s)."""
    oks = named = 0
    for seed in range(3):
        s = simulate(CH_MODEL, CH_TRUTH, chamber_profile(1.0), seed=700 + seed)
        tr = LkfTrack(CH_MODEL, LkfConfig(), 1.0)
        for k, (y, T) in enumerate(zip(s.drift.tolist(), s.temp.tolist(), strict=True), 1):
            tr.update(y, T)
            if k % 100 == 0 and k >= 400:
                e = tr.estimate()
                b, sb = e.values["markov.beta"]
                if b > 0 and sb / b > REL_BETA_MAX:
                    assert e.status != "ok" and "bias.b's band" in e.note, (k, e.note)
                    named += 1
                oks += e.status == "ok"
    assert oks >= 10 and named >= 30, (oks, named)


@pytest.mark.slow
def test_coverage_among_ok_statuses_on_one_hour_runs():
    """30 runs of the three-gyro x hour, every 100 s after the warm-up: among `ok`
    statuses every coefficient's band holds the truth at once in ≥ 0.99 of the
    run-checkpoints, and b's (these runs: 404 of 405; before the band rules 596 of 608, b
    597. benchmarks/results/lkf_accuracy.txt, 100 other runs: 0.984, before 0.951 with
    checkpoints at 0.00-0.58 where b = c/β was `ok` while β's relative std was above 0.2). Not claimed for the chamber hour: there the misses
    among `ok` sit at σ_β/β 0.15-0.2 on the γ/β ridge (β 2.5-3.2 std high, b 3-6 std off),
    which a σ_β/β rule cannot separate: 0.95 of 877 `ok` run-checkpoints on 130 runs."""
    every, bias = [], []
    for seed in range(30):
        s = simulate(Model.parse("markov,temp,bias,white"), X_TRUTH, X_PROFILE,
                     duration=3600, seed=900 + seed)
        tr = LkfTrack(X_MODEL, LkfConfig(), 1.0)
        for k, (y, T) in enumerate(zip(s.drift.tolist(), s.temp.tolist(), strict=True), 1):
            tr.update(y, T)
            if k % 100 == 0 and k >= 400:
                e = tr.estimate()
                if e.status == "ok":
                    every.append(_covered(e.values, X_TRUTH))
                    bias.append(_covered(e.values, {"bias.b": X_TRUTH["bias.b"]}))
    assert len(every) >= 150, len(every)
    assert np.mean(every) >= 0.99 and np.mean(bias) >= 0.99, (np.mean(every), np.mean(bias))


def _track(model, s):
    tr = LkfTrack(model, LkfConfig(), s.dt)
    for y, T in zip(s.drift.tolist(), s.temp.tolist(), strict=True):
        tr.update(y, T)
    return tr


def test_a_flat_likelihood_short_run_is_not_ok():
    """Ten minutes at a constant temperature of a drift that is nearly all white noise:
    ML does not identify β (its search ends at β's upper bound; before gyrostand pinned the
    numerics on import, alone on an AVX-512 CPU it stopped at 0.077 and called the likelihood
    flat along β and γ); the online status is not `ok` and names β's
    likelihood, which stays within 9 of its maximum over β̂ ± 6σ (the profile is open)."""
    m = Model.parse("markov,temp,white")
    truth = {"markov.beta": 0.002, "markov.sigma": 0.002, "temp.gamma": -1e-5,
             "white.sigma": 0.05}
    s = simulate(m, truth, TemperatureProfile.from_breakpoints([(0, 25), (600, 25)]),
                 duration=600, seed=1)
    w = ml(s, m).warnings
    assert any("likelihood is flat" in x or "markov.beta is at its upper search bound" in x
               for x in w), w
    e = _track(m, s).estimate()
    assert e.status != "ok"
    assert "markov.beta's likelihood does not drop by 9 within ±6σ" in e.note, e.note


def test_a_long_clean_run_is_ok_with_the_truth_in_its_band():
    """The paper's C1 (2000 s): `ok` at stop, β's profile closed, the truth within ±3σ,
    and the band not widened (the likelihood is Gaussian there: the profile interval
    within the band)."""
    m = Model.parse("markov,temp")
    truth = {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.01}
    s = simulate(m, {**truth, "white.sigma": 0.0}, paper_profile(), seed=1)
    tr = _track(m, s)
    tr.finish()
    e = tr.estimate()
    assert e.status == "ok", e.note
    raw = tr.filter.estimates
    lo, hi, open_ = profile_interval(tr.filter)
    assert not open_
    for i, n in enumerate(("markov.beta", "temp.gamma")):
        v, sd = e.values[n]
        assert abs(v - truth[n]) <= 3 * sd, (n, v, sd)
        assert sd == pytest.approx(raw[n][1], rel=0.05)  # at most a few % wider
        # β's interval from the grid: within 15 % of the ±3σ band's half-width
        assert max(v - lo[i], hi[i] - v) == pytest.approx(3 * sd, rel=0.15), (lo, hi)


def test_the_bias_band_widens_to_its_profile_interval():
    """A chamber hour of the benchmark (seed 5061) where β came out high (1.8 std): b by
    the delta method is 3.6 std off the truth with status `ok`; its profile-likelihood
    interval is 1.56 times wider and holds the truth (2.3 std)."""
    s = simulate(CH_MODEL, CH_TRUTH, chamber_profile(1.0), seed=5061)
    tr = _track(CH_MODEL, s)
    e = tr.estimate()
    v, sd = e.values["bias.b"]
    v0, sd0 = tr.filter.estimates["bias.b"]
    assert v == v0 and abs(v0 - CH_TRUTH["bias.b"]) > 3 * sd0
    assert sd / sd0 == pytest.approx(1.56, abs=0.05)
    assert abs(v - CH_TRUTH["bias.b"]) <= 3 * sd and e.status == "ok", e.note


def test_an_estimate_off_its_own_likelihood_maximum_is_not_ok():
    """benchmarks/lkf_accuracy.py's 6-h chamber run, seed 171, at 4200 s (the checkpoint
    where 2 of 300 runs were ok and both missed β): the filter sits at β̂ ≈ 0.51 1/s while
    ML on the same 4200 s finds 0.0063 ± 0.0031 (the truth 0.0017); β's profile from the
    filter's own record is highest near 0.40, 6 of its stds below β̂, where D(β̂) ≈ 38: the
    point is not the record's maximum, and the status says so instead of ok."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    try:
        from lkf_accuracy import CHAMBER_MODEL, CHAMBER_PROFILE, CHAMBER_TRUTH
    finally:
        sys.path.pop(0)
    from gyrostand.core.data import Samples
    from gyrostand.core.lkf.band import OFF_MAXIMUM
    from gyrostand.core.lkf.profile import profile_check

    s = simulate(CHAMBER_MODEL, CHAMBER_TRUTH, CHAMBER_PROFILE, seed=171)
    tr = LkfTrack(CHAMBER_MODEL, LkfConfig(), s.dt)
    for y, T in zip(s.drift[:4200].tolist(), s.temp[:4200].tolist(), strict=True):
        tr.update(y, T)
    e = tr.estimate()
    b, sb = e.values["markov.beta"]
    assert abs(b - CHAMBER_TRUTH["markov.beta"]) > 6 * sb  # the band misses, far
    r = ml(Samples.from_arrays(s.t[:4200], s.drift[:4200], s.temp[:4200], dt=s.dt), CHAMBER_MODEL)
    assert abs(r.value("markov.beta") - CHAMBER_TRUTH["markov.beta"]) < 3 * r.std("markov.beta")
    *_, d_hat = profile_check(tr.filter)
    assert d_hat > OFF_MAXIMUM
    assert e.status != "ok" and "not its likelihood's maximum" in e.note, e.note
