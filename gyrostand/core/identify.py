"""One entry point for the identifiers of the registry (:mod:`.registry`).

``identify(samples, model, method, **options)`` is the keyword form of
``get(method).fit(samples, model, get(method).options(**options))``: the options are
checked against the identifier's typed options class (an unknown one is a
:class:`~gyrostand.errors.ModelError` naming it).

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

from .data import Samples
from .lkf import lkf
from .lsq import lsq
from .ml import ml
from .model import Model
from .registry import get
from .results import FitResult

#: each identifier's batch function by name (the registry's names)
#: (a test checks these are the registry's names)
IDENTIFIERS: dict[str, Callable[..., FitResult]] = {"lsq": lsq, "lkf": lkf, "ml": ml}


def identify(samples: Samples, model: Model, method: str, **options: Any) -> FitResult:
    """Fit ``model`` to ``samples`` with ``method`` (a name of the registry: ``lsq``,
    ``lkf`` or ``ml``) and its options by keyword."""
    ident = get(method)
    return ident.fit(samples, model, ident.options(**options))
