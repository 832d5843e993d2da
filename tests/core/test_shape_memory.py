"""A shaped candidate's curvature grid on a long record holds a bounded share of it in
memory (issue 25: the cost of a 24-h record): hysteresis's 61 × 7 grid is measured one
slice of 61 columns at a time, filtered and projected 32 columns at a time, and the coarse
grid keeps a copy of its half slice, not a view that keeps a whole slice alive. Measured
with numpy's allocations traced (tracemalloc): 7.2 slices of N × 61 before, 5.3 now."""

import tracemalloc

from gyrostand.core.data import Samples
from gyrostand.core.diagnose.shapes import shape_curvatures
from gyrostand.core.ml.fit import ml_fit
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate

TRUTH = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
         "white.sigma": 0.02, "bias.b": 0.3}


def test_the_hysteresis_grid_holds_at_most_six_slices_of_the_record():
    sim = simulate(Model.parse("markov,temp,bias,white"), TRUTH, chamber_profile(2.0), seed=3)
    s = Samples.from_arrays(sim.t, sim.drift, sim.temp)
    model = Model.parse("markov,temp,white,bias")
    fit = ml_fit(s, model)
    tracemalloc.start()
    try:
        rim, area = shape_curvatures(s, model, fit, "hysteresis")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    slice_bytes = len(s) * 61 * 8
    assert peak <= 6.0 * slice_bytes, peak / slice_bytes
    assert rim > 0 and area > 0
