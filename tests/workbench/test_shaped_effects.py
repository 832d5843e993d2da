"""Effects with the shapes real ones have: a temperature-rate effect that acts through the
gyro's internal thermal lag (temp_rate.tau), and hysteresis that switches over a width of
rates (hysteresis.w) behind a lag (hysteresis.tau).

Each run is a 4-hour chamber cycle (ramps at 0.5, 1 and 2 degC/min) built from frames the
way a real log arrives (framelike.py: jitter, 1 % drops, a log that starts and ends inside
a bin, 0.05-degC quantized temperature); the analysed model is ``markov,temp,bias``. The
workbench must rank the true effect first, fit its shape parameters (recovered within 3
std and 35 %), end ADEQUATE after adding it, and the unexplained open-loop error (60-s
means, over the floor) must fall by at least 70 %.
"""

import numpy as np
import pytest

from gyrostand.workbench import open_subject, run_diagnose, run_fit

from .framelike import frame_run

#: hidden term -> its true parameters (the amplitude first, then the shape parameters).
#: k < 0: a lag of the drift's temperature input (temp_lag, τ_L) acts like a lagged rate
#: term of k ≈ −γ·τ_L/β > 0 (here γ < 0), so with k > 0 the two are look-alikes on this
#: profile (k = +20, τ = 600 s: LR 48 for temp_rate, 40 for temp_lag, and ΔBIC prefers
#: temp_lag's one parameter); a k of the other sign no lag can mimic
SHAPED = {
    "temp_rate": {"temp_rate.k": -15.0, "temp_rate.tau": 600.0},
    "hysteresis": {"hysteresis.h": 0.15, "hysteresis.w": 0.01, "hysteresis.tau": 300.0},
}
#: relative tolerance on a recovered shape parameter (besides 3 std)
SHAPE_TOL = 0.35


@pytest.mark.parametrize("term", list(SHAPED))
def test_a_lagged_or_switching_effect_is_found_and_its_shape_recovered(term, tmp_path):
    truth = SHAPED[term]
    path = frame_run(tmp_path / "run.csv", [term], truth, seed=61, drop=0.01)
    rep = run_diagnose(open_subject(path))
    table = [(c.term, round(c.lr_stat, 1), c.df, c.note) for c in rep.candidates]
    assert not rep.adequate and rep.candidates[0].term == term, table
    assert rep.candidates[0].ranked, table

    step = run_fit(open_subject(path), add=[term])
    eb, ea = step.before_error, step.after_error
    floor = ea.floor
    before = np.sqrt(max(eb.rms**2 - floor**2, 0.0))
    after = np.sqrt(max(ea.rms**2 - floor**2, 0.0))
    print(f"{term}: open-loop error {eb.rms:.4f} -> {ea.rms:.4f}, floor {floor:.4f}, "
          f"unexplained {before:.4f} -> {after:.4f} ({100 * (1 - after / before):.0f} % fall)")
    assert after <= 0.3 * before
    for name, value in truth.items():
        est = step.after.parameters[name]
        print(f"  {name}: {est.value:.4g} ± {est.std:.2g} (truth {value:g})")
        assert abs(est.value - value) <= 3 * est.std, (name, est, value)
        assert abs(est.value / value - 1) < SHAPE_TOL, (name, est, value)

    final = run_diagnose(open_subject(path))
    assert term in final.model.names
    assert final.adequate, (final.reasons,
                            [(c.term, round(c.lr_stat, 1), c.note) for c in final.candidates])


def test_the_plain_shape_is_the_default_everywhere():
    """temp_rate without a lag and hysteresis at the old fixed width are still the
    defaults: a simulation, the online filters and least-squares-style callers that leave
    the shape out get exactly the old regressors."""
    from gyrostand.core.model import Model
    from gyrostand.core.profiles import chamber_profile
    from gyrostand.core.terms.base import HYSTERESIS_RATE, Bin, Context

    m = Model.parse("markov,temp,temp_rate,hysteresis")
    assert m.defaults == {"temp_rate.tau": 0.0, "hysteresis.tau": 0.0,
                          "hysteresis.w": HYSTERESIS_RATE}
    t, temp = chamber_profile(1.0).grid(1.0)
    ctx = Context(t=t, temp=temp, dt=1.0)
    cols = {}
    for term in m.terms:
        if term.name in ("temp_rate", "hysteresis"):
            cols.update(term.regressors({}, ctx))
    assert np.array_equal(cols["temp_rate.k"], ctx.temp_rate)
    assert np.array_equal(cols["hysteresis.h"], np.tanh(ctx.temp_rate / HYSTERESIS_RATE))
    # a lag of τ smooths the rate: the causal filter follows the batch one
    tau = 300.0
    lagged = ctx.lagged_rate(tau)
    memory: dict = {}
    causal = [Bin(float(k), float(temp[k]), lambda k=k: float(ctx.temp_rate[k]), memory,
                  1.0).lagged_rate(tau) for k in range(t.size)]
    assert np.max(np.abs(np.array(causal) - lagged)) < 0.02 * np.max(np.abs(lagged))
    with pytest.raises(Exception, match="keeps no memory"):
        Bin(0.0, 20.0, lambda: 0.0).lagged_rate(tau)
