"""A synthetic 1-hour chamber run (3601 samples) with a hidden temp_rate effect, and its
report (written once per module: a report diagnoses the model, which takes seconds)."""

from pathlib import Path

import numpy as np
import pytest

from gyrostand.core.data import Samples
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate

TRUTH = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
         "white.sigma": 0.02, "bias.b": 0.3, "temp_rate.k": 8.0}


def chamber_samples(hours: float = 1.0, seed: int = 11) -> Samples:
    m = Model.parse("markov,temp,bias,temp_rate")
    s = simulate(m, TRUTH, chamber_profile(hours), seed=seed)
    rng = np.random.default_rng(seed + 1)
    temp = np.round((s.temp + 0.01 * rng.standard_normal(len(s))) / 0.05) * 0.05
    return Samples.from_arrays(s.t, s.drift, temp)


@pytest.fixture(scope="module")
def chamber_csv(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("report") / "chamber.csv"
    chamber_samples().to_csv(path)
    return path
