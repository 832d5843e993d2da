"""The numerical core of gyrostand: numpy/scipy (and numba) only — no CAN, no YAML.

>>> from gyrostand.core import Model, identify, paper_profile, simulate
>>> m = Model.parse("markov,temp,bias")
>>> s = simulate(m, {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.01,
...                  "white.sigma": 0.01, "bias.b": 0.2}, paper_profile(), seed=1)
>>> r = identify(s, m, "ml")
>>> sorted(r.parameters) == sorted(m.param_names)
True

The names below are imported on first use (PEP 562): ``import gyrostand.core`` (or any
of its light submodules, e.g. :mod:`gyrostand.core.names`) costs no scipy.stats and no
numba, so the command line starts fast.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
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

#: each public name and the submodule that defines it
_SOURCES: dict[str, str] = {
    "Report": "candidates", "diagnose": "candidates", "Samples": "data", "crlb": "fisher",
    "IDENTIFIERS": "identify", "identify": "identify", "OnlineLKF": "lkf", "lkf": "lkf",
    "OnlineLSQ": "lsq", "lsq": "lsq", "ml": "ml", "Model": "model",
    "TemperatureProfile": "profiles", "chamber_profile": "profiles",
    "paper_profile": "profiles", "Estimate": "results", "FitResult": "results",
    "simulate": "simulate",
}

__all__ = [
    "IDENTIFIERS", "Estimate", "FitResult", "Model", "OnlineLKF", "OnlineLSQ", "Report",
    "Samples", "TemperatureProfile", "chamber_profile", "crlb", "diagnose", "identify", "lkf",
    "lsq", "ml", "paper_profile", "simulate",
]


def __getattr__(name: str) -> Any:
    """Import the submodule defining ``name`` on first access, and keep the value."""
    try:
        source = _SOURCES[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(importlib.import_module(f".{source}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _Core(types.ModuleType):
    """Importing a submodule binds it on its package (``gyrostand.core.ml`` = the module);
    where the package exports a function of the submodule's name (``identify``, ``lkf``,
    ``lsq``, ``ml``, ``simulate``), the package's attribute stays that function, as it was
    when this package imported everything eagerly."""

    def __setattr__(self, name: str, value: Any) -> None:
        if isinstance(value, types.ModuleType) and _SOURCES.get(name) == name:
            value = getattr(value, name)
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Core
