"""The numerical core of gyrostand: numpy/scipy (and numba) only — no CAN, no YAML.

>>> from gyrostand.core import Model, identify, paper_profile, simulate
>>> m = Model.parse("markov,temp,bias")
>>> s = simulate(m, {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.01,
...                  "white.sigma": 0.01, "bias.b": 0.2}, paper_profile(), seed=1)
>>> r = identify(s, m, "ml")
>>> sorted(r.parameters) == sorted(m.param_names)
True

Subpackages, each with its public modules: :mod:`.terms` (the model terms), :mod:`.ml`
(exact maximum likelihood, one run and several), :mod:`.lkf` (the paper's linearised
Kalman filter), :mod:`.lsq` (the paper's least squares), :mod:`.diagnose` (where a model
fails, which effect is missing), :mod:`.design` (the next chamber run). Beside them the
shared foundations: :mod:`.names`, :mod:`.data`, :mod:`.profiles`, :mod:`.model`,
:mod:`.results`, :mod:`.kalman`, :mod:`.registry` (the identifiers), :mod:`.simulation`.

The names below are imported on first use (PEP 562): ``import gyrostand.core`` (or any
of its light submodules, e.g. :mod:`gyrostand.core.names`) costs no scipy.stats and no
numba, so the command line starts fast.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .jit import choose_cache_dir
from .lazy import exports

choose_cache_dir()  # numba's kernel cache: beside the package if writable, else the user's

if TYPE_CHECKING:
    from .data import Samples
    from .design.fisher import crlb
    from .diagnose.results import DiagnoseResult
    from .lkf.filter import OnlineLKF
    from .lsq.fit import OnlineLSQ
    from .model import Model
    from .profiles import TemperatureProfile, chamber_profile, paper_profile
    from .registry import REGISTRY, identify
    from .results import Estimate, FitResult
    from .simulation import simulate

#: each public name and the submodule that defines it
EXPORTS: dict[str, str] = {
    "DiagnoseResult": "diagnose.results", "Samples": "data", "crlb": "design.fisher",
    "REGISTRY": "registry", "identify": "registry", "OnlineLKF": "lkf.filter",
    "OnlineLSQ": "lsq.fit", "Model": "model", "TemperatureProfile": "profiles",
    "chamber_profile": "profiles", "paper_profile": "profiles", "Estimate": "results",
    "FitResult": "results", "simulate": "simulation",
}

__all__ = [
    "REGISTRY", "Estimate", "FitResult", "Model", "OnlineLKF", "OnlineLSQ", "DiagnoseResult",
    "Samples", "TemperatureProfile", "chamber_profile", "crlb", "identify", "paper_profile",
    "simulate",
]
__getattr__, __dir__ = exports(__name__, EXPORTS, globals())
