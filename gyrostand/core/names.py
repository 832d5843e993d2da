"""The names the command line offers before any numerics is imported: the model-term
vocabulary and the identifiers. Pure Python, so that building the ``gyrostand`` argument
parser (and validating a session file's ``model:``) costs no numpy/scipy/numba import.

:mod:`gyrostand.core.terms` maps each vocabulary name to its term class and
:mod:`gyrostand.core.registry` each method name to its function (tests check both match).
"""

from __future__ import annotations

#: the vocabulary of PRODUCT.md, in its order (the contract)
VOCABULARY: tuple[str, ...] = (
    "markov", "temp", "white", "bias", "temp2", "temp_lag", "temp_rate", "hysteresis",
    "trend", "warmup", "random_walk", "markov2",
)

#: the identifiers of ``gyrostand identify --method`` and a session's ``identifiers:``
METHODS: tuple[str, ...] = ("lsq", "lkf", "ml")

#: the LKF's variants (``identify --variant``, a session's ``lkf.variant``): ``relin`` the
#: converging filter run to its fixed point, ``paper`` the paper's single pass
LKF_VARIANTS: tuple[str, ...] = ("relin", "paper")
