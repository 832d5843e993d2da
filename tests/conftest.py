import os

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


#: python-can's config files as it ships them (read before any test patches them)
_PYTHON_CAN_FILES: list[str] = []


@pytest.fixture(autouse=True)
def _no_python_can_config(monkeypatch):
    """python-can's own config (``~/.canrc``, ``/etc/can.conf``, ``CAN_*`` variables) fills
    every bus key a session leaves out: no test sees the machine's. A test that wants one
    takes :func:`python_can_home`."""
    import can.util

    if not _PYTHON_CAN_FILES:
        _PYTHON_CAN_FILES.extend(can.util.CONFIG_FILES)
    monkeypatch.setattr(can.util, "CONFIG_FILES", [])
    for var in [v for v in os.environ if v.startswith("CAN_")]:
        monkeypatch.delenv(var)


@pytest.fixture
def python_can_home(tmp_path, monkeypatch, _no_python_can_config):
    """A temporary, empty HOME, whose files python-can reads as its config (its config
    files under ``~``: ``~/can.conf``, ``~/.can``, ``~/.canrc``); no ``CAN_*`` variables."""
    import can.util

    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.setattr(can.util, "CONFIG_FILES",
                        [p for p in _PYTHON_CAN_FILES if p.startswith("~")])
    return home
