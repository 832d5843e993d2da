"""Immutable fit results shared by every identifier."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from .model import Model
from .summary import DRIFT_UNIT, fit_table, unit_text

__all__ = ["Estimate", "FitResult"]


@dataclass(frozen=True)
class Estimate:
    """A parameter estimate: ``value`` and standard deviation ``std`` (0 when ``fixed``)."""

    value: float
    std: float
    unit: str = ""
    fixed: bool = False

    def to_dict(self) -> dict[str, Any]:
        """``{"value", "std"}``, and ``"fixed": true`` for a held value.

        >>> Estimate(1.5, 0.25, "y").to_dict()
        {'value': 1.5, 'std': 0.25}
        >>> Estimate(2.0, 0.0, "1/s", fixed=True).to_dict()
        {'value': 2.0, 'std': 0.0, 'fixed': True}
        """
        d: dict[str, Any] = {"value": float(self.value), "std": float(self.std)}
        if self.fixed:
            d["fixed"] = True
        return d


def _ro(a: np.ndarray | None) -> np.ndarray | None:
    if a is None:
        return None
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class FitResult:
    """What an identifier returns.

    Attributes:
        method: ``"lsq"``, ``"lkf"`` or ``"ml"``.
        model: the fitted :class:`Model`.
        parameters: ``<term>.<param>`` -> :class:`Estimate` (read-only mapping).
        loglik: exact Gaussian log-likelihood at the estimate, where the method has one.
        residuals: one-step innovations (LKF, ML) or regression residuals (LSQ), shape (N,)
            aligned with the samples; NaN where no residual exists (gaps, first sample).
        residual_var: predicted variance of each residual, shape (N,), where known.
        warnings: what the identifier noticed (identifiability, bounds, convergence).
        source: provenance of the data; ``n_samples`` / ``n_observed`` counts; ``dt``.
        covariance / cov_names: covariance of the estimated parameters, where known.
        info: method details (iterations, linearisation point, start values, ...).
        history: for recursive methods, estimates after every sample
            (name -> array (N,)) and their stds (``name + ':std'``).
        unit: the drift's unit (``identify --unit``); ``y`` when nothing names it, and then
            the JSON document has no ``unit`` key (as before there was one).
    """

    method: str
    model: Model
    parameters: Mapping[str, Estimate]
    loglik: float | None
    residuals: np.ndarray
    residual_var: np.ndarray | None
    warnings: tuple[str, ...]
    source: str
    n_samples: int
    n_observed: int
    dt: float
    covariance: np.ndarray | None = None
    cov_names: tuple[str, ...] = ()
    info: Mapping[str, Any] = field(default_factory=dict)
    history: Mapping[str, np.ndarray] = field(default_factory=dict)
    unit: str = DRIFT_UNIT

    def __post_init__(self) -> None:
        object.__setattr__(self, "parameters", MappingProxyType(dict(self.parameters)))
        object.__setattr__(self, "info", MappingProxyType(dict(self.info)))
        object.__setattr__(self, "history",
                           MappingProxyType({k: _ro(v) for k, v in self.history.items()}))
        object.__setattr__(self, "residuals", _ro(self.residuals))
        object.__setattr__(self, "residual_var", _ro(self.residual_var))
        object.__setattr__(self, "covariance", _ro(self.covariance))
        bad = [k for k, e in self.parameters.items()
               if not (math.isfinite(e.value) and math.isfinite(e.std))]
        if bad:
            raise ValueError(f"non-finite estimate for {', '.join(bad)} (identifier bug)")

    def value(self, name: str) -> float:
        return self.parameters[name].value

    def std(self, name: str) -> float:
        return self.parameters[name].std

    @property
    def values(self) -> dict[str, float]:
        return {k: e.value for k, e in self.parameters.items()}

    @property
    def residual_rms(self) -> float:
        r = self.residuals[np.isfinite(self.residuals)]
        return float(np.sqrt(np.mean(r * r))) if r.size else 0.0

    def to_dict(self) -> dict[str, Any]:
        """The JSON contract: method, model, parameters {name: {value, std}}, loglik, ..."""
        d: dict[str, Any] = {
            "method": self.method,
            "model": list(self.model.names),
            "parameters": {k: e.to_dict() for k, e in self.parameters.items()},
        }
        if self.loglik is not None:
            d["loglik"] = float(self.loglik)
        d["residual"] = {"rms": self.residual_rms}
        d["n_samples"] = self.n_samples
        d["n_observed"] = self.n_observed
        d["dt"] = self.dt
        d["source"] = self.source
        if self.unit != DRIFT_UNIT:
            d["unit"] = self.unit
            d["parameter_units"] = {k: unit_text(e.unit, self.unit)
                                    for k, e in self.parameters.items()}
        d["warnings"] = list(self.warnings)
        d["info"] = {k: v for k, v in self.info.items() if jsonable(v)}
        return d

    def summary(self) -> str:
        """A readable table with units (:func:`gyrostand.core.summary.fit_table`, which
        ``identify``'s text renderer prints too)."""
        return fit_table(self)


def jsonable(v: Any) -> bool:
    if isinstance(v, bool | int | str) or v is None:
        return True
    if isinstance(v, float):
        return math.isfinite(v)
    if isinstance(v, list | tuple):
        return all(jsonable(x) for x in v)
    if isinstance(v, dict):
        return all(isinstance(k, str) and jsonable(x) for k, x in v.items())
    return False
