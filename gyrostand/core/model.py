"""A drift model: an immutable list of named terms that compiles to a state space.

>>> m = Model.parse("markov,temp,bias")
>>> m.names
('markov', 'temp', 'white', 'bias')
>>> m.param_names
('markov.beta', 'markov.sigma', 'temp.gamma', 'white.sigma', 'bias.b')
>>> m.add("random_walk").names
('markov', 'temp', 'white', 'bias', 'random_walk')
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..errors import ModelError
from .data import Samples
from .kalman import kf_innovations
from .terms.builtin import TERMS, Context, Param, Term

LOG_2PI = float(np.log(2.0 * np.pi))


@dataclass(frozen=True)
class StateSpace:
    """The random part of a model at given parameters, compiled: independent scalar
    states ``x_i,k = phi_i x_i,k−1 + w_i,k`` (``var w = q_i``, ``x_i,0 ~ N(0, p0_i)``) summed
    with the white noise (variance ``r``) into the measurement. ``states`` names the term
    of each state. What ML, the LKF's noise search, Fisher information, simulation and the
    diagnostics all filter with."""

    states: tuple[str, ...]
    phi: np.ndarray
    q: np.ndarray
    p0: np.ndarray
    r: float

    def __post_init__(self) -> None:
        for name in ("phi", "q", "p0"):  # contiguous for the compiled filters
            object.__setattr__(self, name, np.ascontiguousarray(getattr(self, name),
                                                                dtype=float))


@dataclass(frozen=True)
class Model:
    """Immutable model spec. Build with :meth:`parse`; ``white`` is always included."""

    terms: tuple[Term, ...]

    @classmethod
    def parse(cls, spec: str | Iterable[str]) -> Model:
        """From ``"markov,temp,bias"`` or a list of term names (order does not matter)."""
        names = [s.strip() for s in spec.split(",")] if isinstance(spec, str) else list(spec)
        names = [n for n in names if n]
        seen: set[str] = set()
        for n in names:
            if n not in TERMS:
                raise ModelError(
                    f"unknown model term {n!r}; the vocabulary is: {', '.join(TERMS)}"
                    " (a plugin's term: is its package installed, or listed in plugins:?)"
                )
            if n in seen:
                raise ModelError(f"model term {n!r} is listed twice")
            seen.add(n)
        seen.add("white")
        for n in seen:
            for req in TERMS[n].requires:
                if req not in seen:
                    raise ModelError(f"model term {n!r} needs {req!r} (it is an input of it)")
        if not any(TERMS[n].n_states for n in seen):
            raise ModelError(
                "a model needs at least one stochastic drift term (markov, random_walk or markov2)"
            )
        ordered = [n for n in TERMS if n in seen]
        return cls(tuple(TERMS[n]() for n in ordered))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.terms)

    @cached_property
    def modifiers(self) -> tuple[Term, ...]:
        """The terms that change the temperature driving the others' inputs (``temp_lag``),
        in the model's order: what its :class:`~.terms.base.Context` applies."""
        return tuple(t for t in self.terms if t.role == "modifier")

    def __contains__(self, name: object) -> bool:
        return name in self.names

    def __str__(self) -> str:
        return ",".join(self.names)

    def add(self, *names: str) -> Model:
        """A new model with the given terms added."""
        dup = [n for n in names if n in self.names]
        if dup:
            raise ModelError(f"model already has term(s) {', '.join(dup)}")
        return Model.parse(list(self.names) + list(names))

    def remove(self, *names: str) -> Model:
        """A new model without the given terms (``white`` cannot be removed)."""
        for n in names:
            if n not in self.names:
                raise ModelError(f"model has no term {n!r} to remove")
            if n == "white":
                raise ModelError("'white' (measurement noise) is always part of the model")
        return Model.parse([n for n in self.names if n not in names])

    # ---- parameters -------------------------------------------------------------------
    @cached_property
    def params(self) -> tuple[tuple[str, Param], ...]:
        return tuple((t.key(p.name), p) for t in self.terms for p in t.params)

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(n for n, _ in self.params)

    @cached_property
    def _owner(self) -> dict[str, Term]:
        return {t.key(q.name): t for t in self.terms for q in t.params}

    def term_of(self, name: str) -> Term:
        """The term a parameter ``<term>.<param>`` belongs to."""
        try:
            return self._owner[name]
        except KeyError:
            raise ModelError(f"{name!r} is not a parameter of the model {self}") from None

    @cached_property
    def defaults(self) -> dict[str, float]:
        """The default of every shape parameter (:class:`~gyrostand.core.terms.base.Param`'s
        ``default``: the term's plain shape), for a simulation or a filter not given it."""
        return {t.key(q.name): float(q.default) for t in self.terms for q in t.params
                if q.default is not None}

    def free_names(self, p: Mapping[str, float]) -> tuple[str, ...]:
        """Every parameter but a shape parameter that ``p`` leaves out or holds at its
        default (the plain shape, held as the online filters hold it): what an
        information matrix is taken over by default."""
        d = self.defaults
        return tuple(n for n in self.param_names if n not in d or (n in p and p[n] != d[n]))

    def kind(self, name: str) -> str:
        return dict(self.params)[name].kind

    def unit(self, name: str) -> str:
        return dict(self.params)[name].unit

    def names_of_kind(self, kind: str) -> tuple[str, ...]:
        return tuple(n for n, p in self.params if p.kind == kind)

    @property
    def n_states(self) -> int:
        return sum(t.n_states for t in self.terms)

    @property
    def is_single_process(self) -> bool:
        """True when the drift has one random process (what least squares can represent)."""
        return self.n_states == 1 and "markov" in self.names

    # ---- compilation ------------------------------------------------------------------
    def check_params(self, p: Mapping[str, float]) -> None:
        missing = [n for n in self.param_names if n not in p]
        if missing:
            raise ModelError(f"missing parameter value(s): {', '.join(missing)}")

    def regressors(self, p: Mapping[str, float], ctx: Context) -> np.ndarray:
        """Regressor matrix, shape (N, n_linear), columns in ``names_of_kind('linear')``."""
        cols = self.columns(p, ctx)
        lin = self.names_of_kind("linear")
        if not lin:
            return np.zeros((ctx.t.size, 0))
        return np.column_stack([cols[n] for n in lin])

    def columns(self, p: Mapping[str, float], ctx: Context,
                terms: Sequence[Term] | None = None) -> dict[str, np.ndarray]:
        """The regressor columns at ``p`` of every term (or of ``terms`` alone: ML's
        score moves only those a parameter changes), by linear parameter, the context
        bound to the model's modifiers."""
        cols: dict[str, np.ndarray] = {}
        ctx = ctx.bound(self.modifiers)
        for t in self.terms if terms is None else terms:
            cols.update(t.regressors(p, ctx))
        return cols

    def filter_input(self, p: Mapping[str, float], ctx: Context, y: np.ndarray) -> np.ndarray:
        """``[y, X(p)]`` (N, 1 + n_linear), the Kalman filter's input: :meth:`regressors`
        written into it column by column (one copy of them, not a matrix and then its
        copy: ML's every new point of the search)."""
        cols = self.columns(p, ctx)
        lin = self.names_of_kind("linear")
        Y = np.empty((ctx.t.size, 1 + len(lin)))
        Y[:, 0] = y
        for j, n in enumerate(lin):
            Y[:, 1 + j] = cols[n]
        return Y

    def state_space(self, p: Mapping[str, float], dt: float) -> StateSpace:
        """The random part compiled at ``p`` for the step ``dt`` (:class:`StateSpace`)."""
        names, st = [], []
        for t in self.terms:
            for s in t.states(p, dt):
                names.append(t.name)
                st.append(s)
        arr = np.array(st, dtype=float).reshape(-1, 3)
        r = sum(t.measurement_var(p) for t in self.terms)
        return StateSpace(tuple(names), arr[:, 0], arr[:, 1], arr[:, 2], float(r))

    def stochastic(self, p: Mapping[str, float], dt: float):
        """``(phi, q, p0, r)`` of :meth:`state_space` (kept for older callers)."""
        ss = self.state_space(p, dt)
        return ss.phi, ss.q, ss.p0, ss.r

    def filter_columns(self, p: Mapping[str, float], samples: Samples, X: np.ndarray):
        """Innovations of ``[y, X]`` through the model's Kalman filter: ``(E, f)``."""
        Y = np.empty((len(samples), 1 + X.shape[1]))
        Y[:, 1:] = X
        return self.filter_matrix(p, samples, Y)

    def filter_matrix(self, p: Mapping[str, float], samples: Samples, Y: np.ndarray):
        """:meth:`filter_columns` of ``Y[:, 1:]`` written into the filter's input ``Y``
        (N, 1 + m) by the caller (no copy of them); its column 0 is set here."""
        ss = self.state_space(p, samples.dt)
        Y[:, 0] = samples.drift
        return kf_innovations(ss.phi, ss.q, ss.p0, ss.r, Y, samples.noise_weights)

    def innovations(self, p: Mapping[str, float], samples: Samples):
        """One-step innovations ``e`` and their variances ``f`` at the parameters ``p``."""
        self.check_params(p)
        X = self.regressors(p, context(samples, self))
        E, f = self.filter_columns(p, samples, X)
        theta = np.array([p[n] for n in self.names_of_kind("linear")])
        e = E[:, 0] - E[:, 1:] @ theta if theta.size else E[:, 0].copy()
        return e, f

    def loglik(self, p: Mapping[str, float], samples: Samples) -> float:
        """Exact Gaussian log-likelihood of the samples (prediction-error decomposition)."""
        return loglik_of(*self.innovations(p, samples))


def loglik_of(e: np.ndarray, f: np.ndarray) -> float:
    """The Gaussian log-likelihood of innovations ``e`` with variances ``f`` (NaN ``e``:
    a missing sample), as :meth:`Model.loglik` gives it from its own innovations."""
    ok = np.isfinite(e)
    if np.any(f[ok] <= 0):
        return -np.inf
    return float(-0.5 * np.sum(LOG_2PI + np.log(f[ok]) + e[ok] ** 2 / f[ok]))


def context(samples: Samples, model: Model | None) -> Context:
    """What ``model``'s terms need from ``samples`` (:class:`~.terms.base.Context`), its
    modifier terms included; ``model=None`` for what needs the data alone (the temperature
    rate, the segments): a term's input then refuses (it cannot know the modifiers)."""
    return Context(t=np.asarray(samples.t), temp=np.asarray(samples.temp), dt=samples.dt,
                   modifiers=model.modifiers if model is not None else None)
