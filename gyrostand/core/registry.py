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

:func:`identify` is the keyword form of ``get(method).fit(samples, model,
get(method).options(**options))``: the options are checked against the identifier's typed
options class (an unknown one is a :class:`~gyrostand.errors.ModelError` naming it).

>>> from gyrostand.core.model import Model
>>> from gyrostand.core.profiles import paper_profile
>>> from gyrostand.core.simulation import simulate
>>> m = Model.parse("markov,temp")
>>> s = simulate(m, {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.01,
...                  "white.sigma": 0.0}, paper_profile(), seed=1)
>>> r = identify(s, m, "ml", sigma=0.1)
>>> abs(r.value("markov.beta") / 0.0333 - 1) < 0.15
True
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields, is_dataclass, replace
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, ClassVar

from ..errors import ModelError
from .options import LkfOptions, LsqOptions, MlOptions

if TYPE_CHECKING:
    from .data import Samples
    from .model import Model
    from .results import FitResult
    from .tracking import LkfPoint, OnlineTrack

__all__ = ["Identifier", "REGISTRY", "get", "identify", "names"]

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

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """An identifier's contract, checked when its class is defined: a ``name``, an
        ``Options`` dataclass, a ``help`` line and its own :meth:`fit`; an ``online`` one
        also its own :meth:`track`. A gap is a :class:`ModelError` naming it."""
        super().__init_subclass__(**kwargs)
        gaps = []
        if not isinstance(getattr(cls, "name", None), str):
            gaps.append("name (its name in identifiers:, --method and the CAN tables)")
        if not is_dataclass(getattr(cls, "Options", None)):
            gaps.append("Options (a frozen dataclass of its options)")
        if not cls.help:
            gaps.append("help (one line for the command line)")
        if cls.fit is Identifier.fit:
            gaps.append("fit() (the batch fit)")
        if cls.online and cls.track is Identifier.track:
            gaps.append("track() (it says it runs online)")
        if gaps:
            raise ModelError(f"identifier {cls.__module__}.{cls.__qualname__} lacks what "
                             f"an identifier must state: {'; '.join(gaps)}")

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
        from .lsq.fit import check_lsq_model

        check_lsq_model(model)  # names the term, and says why (it needs markov, too)

    def fit(self, samples: Samples, model: Model, options: Any = None) -> FitResult:
        from .lsq.fit import lsq

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
        from .lkf.filter import lkf_layout

        lkf_layout(model)  # names the term (it needs markov, too)

    def fit(self, samples: Samples, model: Model, options: Any = None) -> FitResult:
        from .lkf.filter import lkf

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
        from .ml.fit import ml

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


def identify(samples: Samples, model: Model, method: str, **options: Any) -> FitResult:
    """Fit ``model`` to ``samples`` with ``method`` (a name of the registry: ``lsq``,
    ``lkf`` or ``ml``) and its options by keyword."""
    ident = get(method)
    return ident.fit(samples, model, ident.options(**options))
