"""The identifiers' one registry: each identifier, its options and what it accepts.

An identifier (:class:`Identifier`) declares its ``name``; the terms a model must have
for it (``requires``) and, in one method (:meth:`Identifier.check`), whether it can
represent a model (a :class:`~gyrostand.errors.ModelError` naming the term it cannot
handle); its typed, frozen options (``Options``, a dataclass); a batch :meth:`fit`; and,
if it runs online (``online``), :meth:`track`, the per-bin counterpart with one interface:
``update(y, T)`` per bin, ``estimate()`` the current :class:`~.tracking.OnlineEstimate`,
``finish()`` at stop. The session file's ``identifiers:``, ``identify --method``, the
daemon's online tracking, the final fits and the CAN identifier names all come from
:data:`REGISTRY`; a new identifier is one subclass here plus its numerics module.

Pure Python at import (the numerics are imported by the methods that need them), so the
argument parser and the session loader can ask it without importing numpy.

>>> get("lsq").options(regressor="current")
LsqOptions(regressor='current', sigma=None)
>>> get("lsq").options(beta0=1.0)
Traceback (most recent call last):
    ...
gyrostand.errors.ModelError: lsq has no option beta0; its options: regressor, sigma
>>> names()
('lkf', 'lsq', 'ml')
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, ClassVar

from ..errors import ModelError
from .names import LKF_VARIANTS

if TYPE_CHECKING:
    from .data import Samples
    from .model import Model
    from .results import FitResult
    from .tracking import LkfPoint, OnlineTrack

__all__ = ["Identifier", "LkfOptions", "LsqOptions", "MlOptions", "REGISTRY", "get", "names",
           "LSQ_REGRESSORS"]

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

    ``variant``: ``relin`` (the converging filter of :mod:`~gyrostand.core.lkf_relin`,
    online re-linearised every ``relinearize_every`` bins, default 100 s of bins, noise
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
    Hessians of the log-likelihood (see :func:`~gyrostand.core.ml.ml_fit`)."""

    sigma: float | None = None
    fixed: Mapping[str, float] | None = None
    n_local: int | None = None
    start: Mapping[str, float] | None = None
    std_errors: bool = True
    hessian_passes: int = 2

    def __post_init__(self) -> None:
        _frozen_mapping(self, "fixed")
        _frozen_mapping(self, "start")


class Identifier:
    """Base of the identifiers; a subclass sets the class attributes and :meth:`fit`."""

    #: the name in ``identifiers:``, ``--method``, result files and the CAN value tables
    name: ClassVar[str]
    #: its options (a frozen dataclass whose defaults are the identifier's)
    Options: ClassVar[type]
    #: the terms a model must contain for this identifier at all
    requires: ClassVar[tuple[str, ...]] = ()
    #: whether it runs online, per bin (:meth:`track`); the others only in the final fit
    online: ClassVar[bool] = False
    #: the online estimate at stop is the result under ``name`` (what the bus got); the
    #: batch refit is ``<name>_batch``
    reports_online: ClassVar[bool] = False
    #: one line for the command line's help
    help: ClassVar[str] = ""

    def check(self, model: Model) -> None:
        """Raise :class:`ModelError` naming the term this identifier cannot handle."""
        missing = [t for t in self.requires if t not in model]
        if missing:
            raise ModelError(f"{self.name} needs the term(s) {', '.join(missing)} in the "
                             f"model ({', '.join(model.names)}); use ml")

    def refusal(self, model: Model) -> str | None:
        """Why :meth:`check` refuses ``model`` (None: it accepts it)."""
        try:
            self.check(model)
        except ModelError as exc:
            return str(exc)
        return None

    def options(self, **values: Any) -> Any:
        """Typed options from keyword values; an unknown option is a :class:`ModelError`
        naming it and the known ones."""
        known = [f.name for f in fields(self.Options)]
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise ModelError(f"{self.name} has no option{'s' if len(unknown) > 1 else ''} "
                             f"{', '.join(unknown)}; its options: {', '.join(known)}")
        return self.Options(**values)

    def cli_options(self, args: Any) -> Any:
        """Typed options from an ``argparse`` namespace: each option the command line
        offers under its own name (``--regressor``, ``--beta0``, ...), when given."""
        return self.options(**{f.name: getattr(args, f.name) for f in fields(self.Options)
                               if getattr(args, f.name, None) is not None})

    def _typed(self, options: Any) -> Any:
        if options is None:
            return self.Options()
        if not isinstance(options, self.Options):
            raise TypeError(f"{self.name}: options must be {self.Options.__name__}, got "
                            f"{type(options).__name__}")
        return options

    def fit(self, samples: Samples, model: Model, options: Any = None) -> FitResult:
        """Batch fit of ``model`` to ``samples``."""
        raise NotImplementedError

    def track(self, model: Model, dt: float, options: Any = None) -> OnlineTrack:
        """The online counterpart for bins of ``dt`` s (``online`` identifiers only)."""
        raise ModelError(f"{self.name} does not run online (it runs in the final fit)")

    def final_options(self, options: Any, model: Model, samples: Samples,
                      point: LkfPoint | None = None) -> Any:
        """The options of the final batch fit over the whole record (``point``: where the
        online counterpart stood, if it has one)."""
        return self._typed(options)

    def __repr__(self) -> str:
        return f"<identifier {self.name}>"


class Lsq(Identifier):
    name = "lsq"
    Options = LsqOptions
    requires = ("markov",)
    online = True
    help = "the paper's least squares"

    def check(self, model: Model) -> None:
        from .lsq import check_lsq_model

        check_lsq_model(model)  # names the term, and says why (it needs markov, too)

    def fit(self, samples: Samples, model: Model, options: Any = None) -> FitResult:
        from .lsq import lsq

        o = self._typed(options)
        return lsq(samples, model, regressor=o.regressor, sigma=o.sigma)

    def track(self, model: Model, dt: float, options: Any = None) -> OnlineTrack:
        from .tracking import LsqTrack

        return LsqTrack(model, dt, self._typed(options))


class Lkf(Identifier):
    name = "lkf"
    Options = LkfOptions
    requires = ("markov",)
    online = True
    reports_online = True
    help = "its linearized Kalman filter"

    def check(self, model: Model) -> None:
        from .lkf import lkf_layout

        lkf_layout(model)  # names the term (it needs markov, too)

    def fit(self, samples: Samples, model: Model, options: Any = None) -> FitResult:
        from .lkf import lkf

        o = self._typed(options)
        held = dict(o.held)
        if o.white_sigma is not None:
            held["white.sigma"] = o.white_sigma
        return lkf(samples, model, variant=o.variant, beta0=o.beta0, gamma0=o.gamma0,
                   b0=o.b0, sigma=o.sigma, held=held or None, iterate=o.iterate,
                   max_iter=o.max_iter, tol=o.tol, prior_std=o.prior_std, soaked=o.soaked)

    def track(self, model: Model, dt: float, options: Any = None) -> OnlineTrack:
        from .tracking import LkfTrack

        return LkfTrack(model, self._typed(options), dt)

    def final_options(self, options: Any, model: Model, samples: Samples,
                      point: LkfPoint | None = None) -> Any:
        """relin: the options as given (values given held fixed, the rest from the
        record); paper: one pass at the online filter's point, or values the options leave
        out from a fit of the record."""
        o = self._typed(options)
        if o.variant != "paper":
            return o
        from .tracking import resolve_lkf_point

        pt = point or resolve_lkf_point(model, o, samples)
        return replace(o, beta0=pt.beta0, gamma0=pt.gamma0, b0=pt.b0, sigma=None,
                       white_sigma=None, held=dict(pt.held))


class Ml(Identifier):
    name = "ml"
    Options = MlOptions
    help = "exact maximum likelihood"

    def fit(self, samples: Samples, model: Model, options: Any = None) -> FitResult:
        from .ml import ml

        o = self._typed(options)
        return ml(samples, model, sigma=o.sigma, fixed=o.fixed, n_local=o.n_local,
                  start=o.start, std_errors=o.std_errors, hessian_passes=o.hessian_passes)


#: every identifier by name, in the order of the project DBC's ``Identifier`` value table
REGISTRY: Mapping[str, Identifier] = MappingProxyType(
    {i.name: i for i in (Lkf(), Lsq(), Ml())})


def get(name: str) -> Identifier:
    """The identifier called ``name``; :class:`ModelError` naming the known ones."""
    try:
        return REGISTRY[name]
    except KeyError:
        raise ModelError(f"unknown identifier {name!r}; choose one of "
                         f"{', '.join(REGISTRY)}") from None


def names() -> tuple[str, ...]:
    """Every identifier's name."""
    return tuple(REGISTRY)
