"""The numerical core of gyrostand: numpy/scipy (and numba) only — no CAN, no YAML.

>>> from gyrostand.core import Model, identify, paper_profile, simulate
>>> m = Model.parse("markov,temp,bias")
>>> s = simulate(m, {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.01,
...                  "white.sigma": 0.01, "bias.b": 0.2}, paper_profile(), seed=1)
>>> r = identify(s, m, "ml")
>>> sorted(r.parameters) == sorted(m.param_names)
True
"""

from .candidates import Report, diagnose
from .data import Samples
from .fisher import crlb
from .identify import IDENTIFIERS, identify
from .lkf import OnlineLKF, lkf
from .lsq import OnlineLSQ, lsq
from .ml import ml
from .model import Model
from .profiles import TemperatureProfile, chamber_profile, paper_profile
from .results import Estimate, FitResult
from .simulate import simulate

__all__ = [
    "IDENTIFIERS", "Estimate", "FitResult", "Model", "OnlineLKF", "OnlineLSQ", "Report",
    "Samples", "TemperatureProfile", "chamber_profile", "crlb", "diagnose", "identify", "lkf",
    "lsq", "ml", "paper_profile", "simulate",
]
