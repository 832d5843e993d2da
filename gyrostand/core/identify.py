"""One entry point for the three identifiers.

>>> from gyrostand.core.profiles import paper_profile
>>> from gyrostand.core.simulate import simulate
>>> m = Model.parse("markov,temp")
>>> s = simulate(m, {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.01,
...                  "white.sigma": 0.0}, paper_profile(), seed=1)
>>> r = identify(s, m, "ml", sigma=0.1)
>>> abs(r.value("markov.beta") / 0.0333 - 1) < 0.15
True
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..errors import ModelError
from .data import Samples
from .lkf import lkf
from .lsq import lsq
from .ml import ml
from .model import Model
from .results import FitResult

IDENTIFIERS: dict[str, Callable[..., FitResult]] = {"lsq": lsq, "lkf": lkf, "ml": ml}


def identify(samples: Samples, model: Model, method: str, **options: Any) -> FitResult:
    """Fit ``model`` to ``samples`` with ``method`` (``lsq``, ``lkf`` or ``ml``)."""
    try:
        fn = IDENTIFIERS[method]
    except KeyError:
        raise ModelError(
            f"unknown identifier {method!r}; choose one of {', '.join(IDENTIFIERS)}"
        ) from None
    return fn(samples, model, **options)
