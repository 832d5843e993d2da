"""The design search's information (#25 item 4): the part a program changes computed
exactly, the noise's part shared by every program; the same as the Monte Carlo Fisher
information it replaces, and a search whose result does not depend on its threads."""

from __future__ import annotations

import numpy as np

from gyrostand.core.design.fisher import (
    fisher_information,
    information,
    mean_free,
    mean_information,
    noise_information,
)
from gyrostand.core.design.search import (
    ChamberLimits,
    case_temperature,
    design,
    standard_cycle,
    zigzag,
)
from gyrostand.core.model import Model

MODEL = Model.parse("markov,temp,bias,temp_rate,hysteresis,white")
TRUTH = {"markov.beta": 0.0015, "markov.sigma": 0.05, "temp.gamma": -0.0002, "bias.b": 0.1,
         "temp_rate.k": 5.0, "white.sigma": 0.01, "hysteresis.h": 0.05}
LIM = ChamberLimits(0, 50, 1 / 60, 600, 3600, legs=4)


def _std(info: np.ndarray) -> np.ndarray:
    return np.sqrt(np.diag(np.linalg.inv(info)))


def test_the_split_information_is_the_monte_carlo_one():
    """Measured on 2-h programs with 100 records: every std within 0.2 %; here 1 h and 40
    records each, within 2 % (the Monte Carlo's own spread)."""
    for prog in (standard_cycle(LIM), zigzag(LIM)):
        case = case_temperature(prog.setpoint(LIM.duration), LIM)
        mc, names = fisher_information(MODEL, TRUTH, LIM.grid, case, n_mc=40)
        split, names2 = information(MODEL, TRUTH, LIM.grid, case, n_mc=40)
        assert names == names2
        np.testing.assert_allclose(_std(split), _std(mc), rtol=0.02)


def test_the_noise_part_is_the_same_on_every_program():
    noise, _ = noise_information(MODEL, TRUTH, LIM.grid.size, n_mc=5)
    cases = [case_temperature(p.setpoint(LIM.duration), LIM)
             for p in (standard_cycle(LIM), zigzag(LIM))]
    a = information(MODEL, TRUTH, LIM.grid, cases[0], noise=noise)[0]
    b = information(MODEL, TRUTH, LIM.grid, cases[1], noise=noise)[0]
    # the linear coefficients' block moves with the program, the white noise's does not
    i = MODEL.free_names(TRUTH).index("white.sigma")
    j = MODEL.free_names(TRUTH).index("temp_rate.k")
    assert a[i, i] == b[i, i] == noise[i, i] and a[j, j] != b[j, j]


def test_the_search_is_the_same_on_one_thread_or_two():
    kw = dict(goal="worst", doubt=("temp_rate.k", "hysteresis.h"), starts=2, maxfev=25,
              n_mc_report=4)
    one = design(MODEL, TRUTH, LIM, workers=1, **kw)
    two = design(MODEL, TRUTH, LIM, workers=2, **kw)
    assert one.program == two.program and one.predicted == two.predicted


def test_noise_levels_the_mean_ignores_are_skipped_for_the_same_information():
    """#25 item 4: the noise levels' ∂μ/∂θ is 0 on every program, so the search skips
    their differences; the information is bit-for-bit the one with them differenced."""
    ref = case_temperature(standard_cycle(LIM).setpoint(LIM.duration), LIM)
    still = mean_free(MODEL, TRUTH, LIM.grid, ref)
    assert still == ("markov.sigma", "white.sigma")
    zig = case_temperature(zigzag(LIM).setpoint(LIM.duration), LIM)
    full, names = mean_information(MODEL, TRUTH, LIM.grid, zig)
    fast, names2 = mean_information(MODEL, TRUTH, LIM.grid, zig, still=still)
    assert names == names2 and np.array_equal(full, fast)
    # a parameter the mean does depend on is not skipped by mean_free, and skipping it
    # by hand changes the information (the test can fail)
    cut, _ = mean_information(MODEL, TRUTH, LIM.grid, zig, still=("markov.beta",))
    assert "markov.beta" not in still and not np.array_equal(full, cut)
