"""Each identifier's typed, frozen options (a session file's ``lsq:``/``lkf:``/``ml:``
sections, ``identify``'s flags): pure Python, so the argument parser, the session loader and
the online trackers can read them without importing the numerics. The identifiers that take
them are :mod:`~gyrostand.core.registry`'s."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from ..errors import ModelError
from .names import LKF_VARIANTS

__all__ = ["LSQ_REGRESSORS", "LsqOptions", "LkfOptions", "MlOptions"]


#: least squares' regressor: Y_{k-1} (standard) or Y_k (the paper's text)
LSQ_REGRESSORS = ("previous", "current")


def _frozen_mapping(obj: Any, name: str) -> None:
    value = getattr(obj, name)
    if value is not None:
        object.__setattr__(obj, name, MappingProxyType(dict(value)))


@dataclass(frozen=True)
class LsqOptions:
    """``regressor``: ``previous`` (Y_{k−1}) or ``current`` (Y_k); ``sigma`` fixes
    ``markov.sigma`` in the report (the regression does not use it)."""

    regressor: str = "previous"
    sigma: float | None = None

    def __post_init__(self) -> None:
        if self.regressor not in LSQ_REGRESSORS:
            raise ModelError(f"regressor must be 'previous' or 'current', got "
                             f"{self.regressor!r}")


@dataclass(frozen=True)
class LkfOptions:
    """The LKF's options, batch and online (a session file's ``lkf:`` section).

    ``beta0`` (1/s), ``gamma0`` (drift unit per s·degC), ``b0`` (drift unit): the
    linearisation point; ``sigma`` (``markov.sigma``) and ``white_sigma`` (``white.sigma``)
    the held noise levels (drift unit); ``held`` any further held parameter by name (e.g.
    ``random_walk.q``). A value left out (None) is estimated: batch from a fit of the record
    (the paper variant: the paper's point 1e-4 for β₀, γ₀), online from a *warm-up* of the
    first ``warmup`` bins (least squares for the point, the core's held-value estimate for
    the noise levels), after which the filter starts and replays those bins.

    ``variant``: ``relin`` (the converging filter of :mod:`~gyrostand.core.lkf.relin`,
    online re-linearised every ``relinearize_every`` bins, default 100 s of bins, then every
    tenth of the record (:mod:`~gyrostand.core.lkf.schedule`), noise
    levels not given re-estimated) or ``paper`` (the paper's single pass at a fixed point;
    ``iterate`` re-linearises its batch run until it settles, at most ``max_iter`` passes,
    relative tolerance ``tol``). ``soaked``: start the moving point in equilibrium with the
    first temperature (relin). ``prior_std``: the initial state stds by state name.
    """

    beta0: float | None = None
    gamma0: float | None = None
    b0: float | None = None
    sigma: float | None = None
    white_sigma: float | None = None
    held: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))
    warmup: int = 300
    iterate: bool = False
    variant: str = "relin"
    relinearize_every: int | None = None
    soaked: bool = True
    max_iter: int = 60
    tol: float = 1e-4
    prior_std: Mapping[str, float] | None = None

    def __post_init__(self) -> None:
        if self.variant not in LKF_VARIANTS:
            raise ModelError(f"unknown lkf variant {self.variant!r}; choose one of "
                             f"{', '.join(LKF_VARIANTS)}")
        object.__setattr__(self, "held", MappingProxyType(dict(self.held or {})))
        _frozen_mapping(self, "prior_std")

    @property
    def needs_warmup(self) -> bool:
        """Whether the online filter needs a warm-up fit (a point or level left out)."""
        return None in (self.beta0, self.gamma0, self.b0, self.sigma, self.white_sigma)

    @property
    def given(self) -> dict[str, float]:
        """The held values given: ``held`` with ``sigma`` and ``white_sigma`` by name."""
        out = dict(self.held)
        if self.sigma is not None:
            out["markov.sigma"] = self.sigma
        if self.white_sigma is not None:
            out["white.sigma"] = self.white_sigma
        return out


@dataclass(frozen=True)
class MlOptions:
    """``sigma`` fixes ``markov.sigma``; ``fixed`` holds parameters at values; ``n_local``
    local optimisations from the best grid starts (None: 2, or 5 with several rates);
    ``start`` an extra start point; ``std_errors`` from ``hessian_passes`` numerical
    Hessians of the log-likelihood (see :func:`~gyrostand.core.ml.fit.ml_fit`)."""

    sigma: float | None = None
    fixed: Mapping[str, float] | None = None
    n_local: int | None = None
    start: Mapping[str, float] | None = None
    std_errors: bool = True
    hessian_passes: int = 2

    def __post_init__(self) -> None:
        _frozen_mapping(self, "fixed")
        _frozen_mapping(self, "start")
