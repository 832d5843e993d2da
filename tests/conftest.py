import numpy as np
import pytest

from gyrostand.core.model import Model
from gyrostand.core.profiles import paper_profile
from gyrostand.core.simulation import simulate

#: the paper's four cases (MODEL.md): beta (1/s), gamma
CASES = {"C1": (0.0333, -0.01), "C2": (0.0333, -0.001), "C3": (0.00055, -0.001),
         "C4": (0.00055, -0.00001)}


def truth(case: str, sigma: float = 0.1, sigma_v: float = 0.0, **extra: float) -> dict:
    beta, gamma = CASES[case]
    p = {"markov.beta": beta, "markov.sigma": sigma, "temp.gamma": gamma,
         "white.sigma": sigma_v}
    p.update(extra)
    return p


@pytest.fixture
def base_model() -> Model:
    return Model.parse("markov,temp")


@pytest.fixture
def c1_samples(base_model):
    return simulate(base_model, truth("C1"), paper_profile(), seed=7)


@pytest.fixture
def rng():
    return np.random.default_rng(0)
