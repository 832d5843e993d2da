"""A floor the misfit cannot raise, where a candidate shows the misfit (issue 23): when the
lack-of-fit test alone does not see one effect (its 17-25 df dilute it) but a candidate is
significant and the misfit moved the fit's random part, the floor is the saturated
reference's (:func:`~gyrostand.core.diagnose.reference.misfit_floor`), so the headline's
unexplained part is the missing effect's size — checked against an independent estimate,
the reference's own deterministic misfit — and not "0 beside a significant trend"; and once a
candidate has shown the misfit, the headline gives its size also inside the floor's
sampling spread (:meth:`~gyrostand.core.diagnose.prederror.ModelError.misfit_shown`)."""

from __future__ import annotations

import numpy as np
import pytest

from gyrostand.core.diagnose.prederror import MIN_FILL, deterministic_part
from gyrostand.core.diagnose.reference import REPORT_ALPHA, misfit_floor, reference_fit
from gyrostand.core.diagnose.verdict import diagnose, fit_error
from gyrostand.core.ml.fit import ml
from gyrostand.workbench import open_subject, run_fit

from .framelike import frame_run


def _reference_misfit(rep, samples) -> float:
    """RMS of the 60-s means of the reference's deterministic part less the model's: the
    effect the reference's rich basis finds beyond the model, by another route than the
    floor's (it holds the basis's own estimation noise, ~0.015-0.022 deg/h on clean 4-h
    runs, so it is an upper estimate)."""
    ref = rep.reference
    u = deterministic_part(ref.fit.model, ref.fit.values, samples) - rep.model_error.simulated
    ok = np.isfinite(samples.drift)
    m = int(rep.model_error.headline()["window_s"])
    n = len(u) // m * m  # consecutive windows, each at least MIN_FILL observed
    filled = ok[:n].reshape(-1, m).mean(axis=1) >= MIN_FILL
    means = np.nanmean(np.where(ok, u, np.nan)[:n].reshape(-1, m), axis=1)[filled]
    return float(np.sqrt(np.mean(means ** 2)))


@pytest.fixture(scope="module")
def trend(tmp_path_factory):
    """A 4-h run with a trend of 1e-5 deg/h/s whose lack of fit stands below the report's
    level (p 0.039): the trend is significant, the fit's Markov process absorbed it."""
    path = frame_run(tmp_path_factory.mktemp("misfit") / "trend.csv", ["trend"],
                     {"trend.c": 1e-5}, seed=6, drop=0.01)
    sub = open_subject(path)
    return sub, diagnose(sub.samples, sub.model)


def test_a_significant_trend_takes_the_floor_from_the_reference(trend):
    sub, rep = trend
    ref = rep.reference
    assert not ref.p_value < REPORT_ALPHA  # the lack-of-fit test alone: no misfit
    assert rep.significant and rep.significant[0].term == "trend"
    assert set(ref.traded) == {"markov.beta", "markov.sigma"}
    assert ref.noise == dict(ref.fit.values)  # the floor's random part: the reference's
    h = rep.model_error.headline()
    # the fit's random part, inflated by the trend, raised the floor to the error
    old = fit_error(rep.fit, sub.samples, rep.unit,
                    reference_fit(sub.samples, sub.model, rep.fit)).headline()
    assert old["floor"] > 1.15 * h["floor"]
    assert (old["unexplained"] or 0.0) < 0.5 * h["unexplained"]
    # the headline's unexplained part: the trend's size, by two routes
    assert h["unexplained"] >= 0.5 * h["rms"]
    assert h["unexplained"] == pytest.approx(_reference_misfit(rep, sub.samples), rel=0.2)
    assert not rep.adequate and any("above its floor" in r for r in rep.reasons)


def test_fit_add_shows_the_same_floor_and_the_error_falls(trend):
    """``fit --add trend``: its "before" is diagnose's headline, number for number, and
    the unexplained part falls by more than 70 %."""
    sub, rep = trend
    step = run_fit(sub, add=["trend"], record=False)
    before, after = step.before_error.headline(), step.after_error.headline()
    assert before == rep.model_error.headline()
    assert (after["unexplained"] or 0.0) <= 0.3 * before["unexplained"]


def test_a_clean_run_keeps_its_own_floor(tmp_path):
    """Clean 4-h run seed 5: the reference's random part is beyond ±3 std of the fit's
    (markov.beta and sigma: the basis eats low frequencies) but no candidate is
    significant, so nothing shows a misfit and the floor stays the fit's: ADEQUATE."""
    sub = open_subject(frame_run(tmp_path / "clean.csv", seed=5, drop=0.01))
    rep = diagnose(sub.samples, sub.model)
    assert misfit_floor(rep.reference, rep.fit) is not None  # it would move ...
    assert rep.reference.traded == () and not rep.significant  # ... but nothing shows one
    assert rep.adequate and rep.model_error.headline()["unexplained"] == 0.0


def test_once_a_misfit_is_shown_the_headline_gives_its_size(tmp_path):
    """:meth:`ModelError.misfit_shown`: the run rows' unexplained part without the floor's
    limit (the limit tests whether there is a misfit; a significant candidate has answered
    that), exactly √(rms² − floor²); the segments and the verdict's at-floor test as they
    were. Clean 4-h run seed 4: the error 0.0466 deg/h lies between its floor 0.0431 and
    the floor's 99 % point, so the limit gives 0."""
    sub = open_subject(frame_run(tmp_path / "clean.csv", seed=4, drop=0.01))
    fit = ml(sub.samples, sub.model)
    err = fit_error(fit, sub.samples, "y", reference_fit(sub.samples, sub.model, fit))
    shown = err.misfit_shown()
    for key, rows in err.entries.items():
        run, new = rows[0], shown.entries[key][0]
        assert new["unexplained"] == np.sqrt(max(run["rms"] ** 2 - run["floor"] ** 2, 0.0))
        assert {k: v for k, v in new.items() if k != "unexplained"} == \
            {k: v for k, v in run.items() if k != "unexplained"}
        assert shown.entries[key][1:] == rows[1:]
    h, hs = err.headline(), shown.headline()
    assert h["floor"] < h["rms"] <= h["floor_limit"] and h["unexplained"] == 0.0
    assert hs["unexplained"] > 0.3 * hs["rms"]
    assert shown.at_floor() and err.at_floor()
