"""The term protocol: what a model term is and every fact it owns (PRODUCT.md vocabulary).

A :class:`Term` owns every fact about its effect: its parameters (names, kinds, units),
its role in the state space, its regressor for a batch fit and its causal regressor for
the online filter (or its input u(T)), the LKF's prior scale of its coefficients, its
signature for the residual cross-correlation, its null hypothesis in a candidate test,
its look-alikes and what separates them, and its bit in the CAN summary. The identifiers,
diagnostics, candidate tests and the CAN summary read these facts; none keeps a table of
terms. The built-in terms and the registry are in :mod:`gyrostand.core.terms`; a user's
own term is a subclass registered there (see :mod:`gyrostand.plugins`).

Every model is ``y_k = sum_j theta_j X_j,k(eta) + sum_i x_i,k + v_k``:

* *linear* parameters ``theta`` (e.g. ``temp.gamma``, ``bias.b``) multiply regressors
  ``X_j`` that may depend on the nonlinear parameters ``eta`` (e.g. the temperature input
  is filtered through the Gauss-Markov dynamics, so its regressor depends on ``markov.beta``);
* independent stochastic scalar states ``x_i`` (``markov``, ``random_walk``, ``markov2``),
  each ``x_{i,k} = phi_i x_{i,k-1} + w_{i,k}``, and the white measurement noise ``v``.

Units: ``y`` stands for the drift's unit (e.g. deg/h), ``degC`` for temperature, ``s`` for
time.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np

from ...errors import ModelError
from ..kalman import first_order_response, foh_weights

P = Mapping[str, float]


@dataclass(frozen=True)
class Param:
    """One parameter of a term.

    ``kind`` is ``"rate"`` (positive, 1/s, enters nonlinearly), ``"time"`` (a positive time
    constant, s, enters nonlinearly), ``"width"`` (a positive scale in another unit, e.g. a
    switching width in degC/s, enters nonlinearly), ``"std"`` (a standard deviation or
    noise intensity, >= 0) or ``"linear"`` (a coefficient the model is linear in).

    ``default`` marks a *shape* parameter: a nonlinear parameter whose ``default`` value
    gives the term its plain shape (``temp_rate.tau = 0``: no thermal lag). Maximum
    likelihood estimates it like any other (within :meth:`Term.search_bounds`); the online
    filters and least squares hold it at the value given, else at ``default``; a
    simulation or design that leaves it out uses ``default``. ``physical_bounds`` names the
    search bounds ("lower"/"upper") where the shape is still a physical one (a lag of a
    few Δt: none measurable; the narrowest width: a sharp switch): an estimate there is
    reported, but is no sign of an unphysical fit, so a candidate stays ranked.
    """

    name: str
    kind: str
    unit: str
    doc: str
    default: float | None = None
    physical_bounds: tuple[str, ...] = ()


#: window of the temperature-rate estimate (s): a local quadratic fit (Savitzky-Golay)
RATE_WINDOW_S = 61.0
#: default switching width w (degC/s) of hysteresis: tanh(dT/dt / w) reaches 0.76 at w
HYSTERESIS_RATE = 1e-3
#: reference temperature of temp2 (degC)
T_REF = 25.0
#: the kinds of positive nonlinear parameters (searched on a log scale)
POSITIVE_KINDS = ("rate", "time", "width")
#: lagged temperature rates a context keeps, by τ (:meth:`Context.lagged_rate`): a
#: hysteresis shape grid (:mod:`~gyrostand.core.diagnose.shapes`) visits its 81 lags once
#: per width (9 widths), and a score pass of hysteresis asks for τ ± a step and τ. 96 of
#: a 6-h run hold 17 MB, of a 24-h run 66 MB
LAGGED_RATES = 96
_LAG_LOCK = threading.Lock()


@dataclass(frozen=True)
class Context:
    """What terms need from the data: times ``t`` (s), temperature ``temp`` (degC), ``dt``,
    and the model's own ``modifier`` terms (:meth:`effective_temp`; ``None``: built without
    a model, see :func:`~gyrostand.core.model.context`)."""

    t: np.ndarray
    temp: np.ndarray
    dt: float
    modifiers: tuple[Term, ...] | None = field(default=None, compare=False, repr=False)
    _cache: dict = field(default_factory=dict, compare=False, repr=False)

    def bound(self, modifiers: tuple[Term, ...]) -> Context:
        """This context for a model whose modifier terms are ``modifiers`` (the data and
        what was computed from them shared)."""
        if self.modifiers == modifiers:
            return self
        return replace(self, modifiers=modifiers, _cache=self._cache)

    def through_markov(self, u: np.ndarray, beta: float) -> np.ndarray:
        """Response of dx/dt = -beta x + u(t) to the input ``u`` (linear between samples).

        Starts in equilibrium with the first input, ``x_0 = u_0 / beta`` (the gyro has
        soaked at the starting temperature), and is exact for piecewise-linear ``u``.
        """
        phi, a0, a1 = foh_weights(beta, self.dt)
        return first_order_response(np.ascontiguousarray(u, dtype=float), phi, a0, a1,
                                    float(u[0]) / beta)

    def effective_temp(self, p: P) -> np.ndarray:
        """The temperature that drives the drift: T, changed by each of the model's
        ``modifier`` terms whose parameters ``p`` holds (:meth:`Term.modify_temperature`;
        ``temp_lag``: T lagged by τ)."""
        if self.modifiers is None:
            raise ModelError("a term's input needs the model's context: this one was built "
                             "without a model (context(samples, model))")
        T = self.temp
        for term in self.modifiers:
            if term.params and all(term.key(q.name) in p for q in term.params):
                T = term.modify_temperature(p, self, T)
        return T

    @property
    def temp_rate(self) -> np.ndarray:
        """dT/dt (degC/s), robust to sensor noise and quantisation.

        A naive difference of 0.05-degC steps is mostly quantisation noise; a local
        quadratic least-squares fit over ``RATE_WINDOW_S`` (Savitzky-Golay derivative)
        is exact on ramps and averages the steps out (noise std ≈ q/√12 · √(12/W³)).
        """
        if "rate" not in self._cache:
            self._cache["rate"] = temperature_rate(self.temp, self.dt)
        return self._cache["rate"]

    def lagged_rate(self, tau: float) -> np.ndarray:
        """The rate of the temperature T_g the gyro's element feels, lagged behind the
        sensor by its internal thermal lag τ:

            dT_g/dt = (T − T_g)/τ   ⇒   Ṫ_g = lag_τ(Ṫ),   d(Ṫ_g)/dt = (Ṫ − Ṫ_g)/τ

        (the lag is linear and time-invariant, so the rate of the lagged temperature is the
        lagged rate; both start soaked). τ ≤ 0 is no lag: :attr:`temp_rate` itself.
        """
        if not tau > 0:
            return self.temp_rate
        with _LAG_LOCK:
            kept = self._cache.setdefault("lagged_rates", {})
            hit = kept.get(tau)
        if hit is not None:
            return hit
        rate = self.temp_rate
        out = self.through_markov(rate / tau, 1.0 / tau)
        with _LAG_LOCK:
            kept[tau] = out
            while len(kept) > LAGGED_RATES:  # the oldest out
                del kept[next(iter(kept))]
        return out


#: where a term enters the model: a random ``process`` (a state of its own), the white
#: measurement ``noise``, an ``input`` of the drift's dynamics (u(T) into dε/dt), an
#: ``output`` effect added to the measurement, or a ``modifier`` of another term's input
#: (a lag of the temperature)
ROLES = ("process", "noise", "input", "output", "modifier")
#: the hooks a term of each role must define (:meth:`Term.contract_gaps`)
REQUIRED_HOOKS: Mapping[str, tuple[str, ...]] = {
    "process": ("states",),
    "noise": ("measurement_var",),
    "input": ("input",),
    "output": ("regressors",),
    "modifier": ("modify_temperature",),
}
#: the null hypothesis of a candidate test of the term: an ``interior`` point (χ²(df)), on
#: the ``boundary`` of the parameter space (a noise intensity 0: ½χ²(0) + ½χ²(df), Self &
#: Liang 1987), or with a ``nuisance`` parameter not identified under it (a time constant
#: when the amplitude is 0, Davies 1987: one more df, no halving)
NULLS = ("interior", "boundary", "nuisance")


@dataclass(frozen=True)
class Scales:
    """Scales of the data an uninformative prior is set on: the drift ``y`` (its unit),
    the temperature ``T`` (degC) and the largest plausible rate ``rate`` (1/s, 1/Δt)."""

    y: float
    T: float
    rate: float


class Bin:
    """What an online filter knows at its newest bin, from that bin and earlier ones only:
    the time ``t`` (s) since its first bin, the temperature ``T`` (degC) and the causal
    temperature rate (degC/s, computed on first use by ``rate_of()``). ``memory`` is a dict
    the filter keeps from bin to bin (its step ``dt``), where causal filters of the rate
    (:meth:`lagged_rate`) keep their state."""

    __slots__ = ("t", "T", "_rate_of", "_rate", "_memory", "_dt")

    def __init__(self, t: float, T: float, rate_of: Callable[[], float],
                 memory: dict | None = None, dt: float | None = None):
        self.t, self.T, self._rate_of = t, T, rate_of
        self._rate: float | None = None
        self._memory, self._dt = memory, dt

    @property
    def rate(self) -> float:
        if self._rate is None:
            self._rate = self._rate_of()
        return self._rate

    def lagged_rate(self, tau: float) -> float:
        """The causal rate lagged by τ (:meth:`Context.lagged_rate`): a first-order filter
        of :attr:`rate`, x_k = φ x_{k−1} + (1 − φ) rate_k, φ = e^{−Δt/τ}, started soaked at
        the first bin's rate. τ ≤ 0: :attr:`rate`."""
        if not tau > 0:
            return self.rate
        if self._memory is None or self._dt is None:
            raise ModelError("this online filter keeps no memory between bins: a thermal "
                             "lag of the temperature rate needs it")
        key = ("lagged_rate", float(tau))
        last = self._memory.get(key)
        if last is not None and last[0] == self.t:
            return last[1]
        r = self.rate
        if last is None:
            x = r
        else:
            phi = math.exp(-self._dt / tau)
            x = phi * last[1] + (1.0 - phi) * r
        self._memory[key] = (self.t, x)
        return x


class Term:
    """Base class. A subclass sets ``name``, ``params``, ``role`` and overrides what it
    contributes; every fact gyrostand needs about the effect lives here.

    Class attributes: ``requires`` (terms it needs in the model), ``n_states`` (stochastic
    states it adds), ``math`` (its equation, for reports), ``role`` (:data:`ROLES`),
    ``bit`` (its bit in the CAN summary's ``ModelTerms``; a plugin's is assigned after the
    built-ins when not set), ``null`` (:data:`NULLS`), ``look_alikes`` (term -> the
    temperature profile that tells the two apart), ``no_signature`` (why the term has no
    deterministic signature for the residual cross-correlation; empty: it has one),
    ``signature_needs`` (parameters of the fitted model its signature uses),
    ``constant`` (its regressor is identically 1: the converging LKF enters it as an input
    of the drift, see :mod:`gyrostand.core.lkf.relin`), ``per_run`` (its parameters
    belong to one switch-on, not to the gyro: a joint fit of several runs,
    :mod:`gyrostand.core.ml.joint`, gives each run its own), ``rate_input`` (its regressor
    is a function of the temperature rate dT/dt: the converging online LKF then takes
    each bin's rate centred, as ML does, and runs half the rate window behind the newest
    bin, see :mod:`gyrostand.core.lkf.relin`).
    """

    name: ClassVar[str]
    params: ClassVar[tuple[Param, ...]] = ()
    requires: ClassVar[tuple[str, ...]] = ()
    n_states: ClassVar[int] = 0
    math: ClassVar[str] = ""
    role: ClassVar[str] = "output"
    bit: ClassVar[int | None] = None
    null: ClassVar[str] = "interior"
    look_alikes: ClassVar[Mapping[str, str]] = {}
    no_signature: ClassVar[str] = ""
    signature_needs: ClassVar[tuple[str, ...]] = ()
    constant: ClassVar[bool] = False
    per_run: ClassVar[bool] = False
    rate_input: ClassVar[bool] = False

    def key(self, short: str) -> str:
        return f"{self.name}.{short}"

    # ---- the contract -------------------------------------------------------------------
    @classmethod
    def overrides(cls, hook: str) -> bool:
        """Whether this term defines ``hook`` itself rather than inheriting :class:`Term`'s."""
        return getattr(cls, hook) is not getattr(Term, hook)

    @classmethod
    def contract_gaps(cls) -> list[str]:
        """What this term lacks of the contract of its role (empty: it keeps it).

        Every term states ``name``, ``params`` (:class:`Param`), ``math``, a ``role`` of
        :data:`ROLES` and a ``null`` of :data:`NULLS`, and defines the hooks
        :data:`REQUIRED_HOOKS` names for its role; a process adds at least one state, an
        input has one linear parameter; a term the online LKF can run
        (:meth:`lkf_unsupported` empty) whose coefficient is not in the drift's unit
        defines :meth:`prior_std` (the LKF's prior scale of that coefficient).
        :func:`~gyrostand.core.terms.builtin.register` refuses a term with a gap, naming it.
        """
        gaps = []
        if not isinstance(getattr(cls, "name", None), str):
            gaps.append("name (a class attribute: the term's name in a model)")
        if not isinstance(cls.params, tuple) or not all(isinstance(q, Param)
                                                        for q in cls.params):
            gaps.append("params (a tuple of Param)")
            return gaps
        if not cls.math:
            gaps.append("math (its equation, for reports)")
        if cls.role not in ROLES:
            return gaps + [f"role (one of {', '.join(ROLES)}; got {cls.role!r})"]
        if cls.null not in NULLS:
            gaps.append(f"null (one of {', '.join(NULLS)}; got {cls.null!r})")
        gaps += [f"{hook}() (every {cls.role} term defines it)"
                 for hook in REQUIRED_HOOKS[cls.role] if not cls.overrides(hook)]
        if cls.role == "process" and cls.n_states < 1:
            gaps.append("n_states (a process adds at least one stochastic state)")
        linear = [q for q in cls.params if q.kind == "linear"]
        if cls.role == "input" and len(linear) != 1:
            gaps.append("one linear parameter (an input term's coefficient θ of u(T))")
        if not gaps and not cls.overrides("prior_std"):
            odd = [f"{q.name} (unit {q.unit})" for q in linear if q.unit != "y"]
            if odd and not cls().lkf_unsupported():
                gaps.append(f"prior_std() (the online LKF's prior scale of {', '.join(odd)}, "
                            "not in the drift's unit)")
        return gaps

    @property
    def linear(self) -> tuple[str, ...]:
        """Full names of the parameters the model is linear in."""
        return tuple(self.key(q.name) for q in self.params if q.kind == "linear")

    # ---- batch: the model's regressors and states ---------------------------------------
    def regressors(self, p: P, ctx: Context) -> dict[str, np.ndarray]:
        """Regressor column of each linear parameter, keyed by full name. A function of the
        model's rates, time constants and widths (any kind but ``std`` and ``linear``):
        ML keeps the columns of the points it has seen by those values
        (:class:`~gyrostand.core.ml.fit.Problem`), so they must not depend on a noise level.

        An input term's regressor is its input through the drift's dynamics,
        ``X = ∫ e^{−β(t−s)} u(T_L(s)) ds`` (:meth:`input` of the effective temperature).
        """
        if self.role == "input":
            (lin,) = self.linear
            u = self.input(ctx.effective_temp(p))
            return {lin: ctx.through_markov(u, p["markov.beta"])}
        return {}

    def regressor_slopes(self, p: P, ctx: Context, name: str) -> dict[str, np.ndarray] | None:
        """Optional (speed only): the derivative of each of this term's regressor columns
        in the log of its parameter ``name`` at ``p``, keyed as :meth:`regressors`; ``None``
        (the default): ML's score takes central differences of :meth:`regressors`, two
        evaluations of them per parameter at each step of the search. A term whose
        regressors are costly (a ``tanh`` of 21,600 samples is 0.35 ms) and whose slope
        reuses their value defines it; it must agree with those differences to ~1e-8
        relative (``tests/core/test_ml_score.py``)."""
        return None

    def states(self, p: P, dt: float) -> list[tuple[float, float, float]]:
        """``(phi, q, p0)`` of each stochastic state this term adds."""
        return []

    def measurement_var(self, p: P) -> float:
        return 0.0

    def modify_temperature(self, p: P, ctx: Context, T: np.ndarray) -> np.ndarray:
        """A ``modifier`` term's change of the temperature that drives the drift's inputs."""
        raise ModelError(f"term {self.name!r} (role {self.role}) does not modify the "
                         "temperature")

    # ---- online: the linearised Kalman filter -------------------------------------------
    def input(self, T):
        """An input term's input u(T) (float or array), entering dε/dt as θ·u."""
        raise ModelError(f"term {self.name!r} (role {self.role}) has no input u(T)")

    def causal_regressors(self, p: P, now: Bin) -> dict[str, float]:
        """An output term's regressor value of each linear parameter at the newest bin,
        from that bin and earlier ones only (``p`` holds the held parameters)."""
        raise ModelError(f"term {self.name!r} defines no causal regressor "
                         "(causal_regressors): the online LKF cannot use it; use ml")

    def lkf_unsupported(self) -> str:
        """Why the LKF cannot represent this term ('' when it can)."""
        if self.role == "modifier":
            return "it modifies another term's input through a time constant"
        if self.role == "input":
            ok = self.overrides("input") and len(self.linear) == 1
            return "" if ok else "an input term needs one linear parameter and input()"
        if self.role == "output":
            ok = self.overrides("causal_regressors")
            return "" if ok else "it defines no causal regressor (causal_regressors)"
        if self.role == "process":
            return "" if self.n_states == 1 else "the LKF stacks one state per process"
        return ""

    def prior_std(self, s: Scales) -> dict[str, float]:
        """Uninformative prior std of each coefficient the LKF estimates, on the scale of
        the data. Default: 10·|y| for a coefficient in the drift's unit ``y``."""
        out = {}
        for q in self.params:
            if q.kind != "linear":
                continue
            if q.unit != "y":
                raise ModelError(f"term {self.name!r}: no prior scale for {self.key(q.name)} "
                                 f"(unit {q.unit}); define prior_std()")
            out[self.key(q.name)] = 10 * s.y
        return out

    # ---- maximum likelihood ---------------------------------------------------------------
    def search_bounds(self, q: Param, ctx: Context, duration: float) -> tuple[float, float] | None:
        """ML's search range (natural units) of a positive nonlinear parameter; None: the
        rule of its kind (a time constant 3·Δt … the record, a rate 1e-3/record … 5/Δt)."""
        return None

    def shape(self, p: P, short: str) -> float:
        """A shape parameter's value in ``p``, else its default (:class:`Param`)."""
        key = self.key(short)
        if key in p:
            return float(p[key])
        (q,) = [q for q in self.params if q.name == short]
        if q.default is None:
            raise ModelError(f"missing parameter value: {key}")
        return float(q.default)

    def start_values(self, q: Param, duration: float, dt: float) -> list[float]:
        """ML's start grid of a searched parameter: values of a rate (1/s) or a time (s);
        of a noise level, its ratio to the reference noise level."""
        if q.kind == "time":
            return list(np.geomspace(10 * dt, duration / 3, 4))
        if q.kind == "rate":
            return list(np.geomspace(3.0 / duration, 0.3 / dt, 4))
        return [0.3, 3.0]

    # ---- diagnosis ------------------------------------------------------------------------
    def signature(self, p: P, ctx: Context) -> np.ndarray:
        """The term's signature in the data (before filtering), for the cross-correlation
        of the residuals: by default the regressor of its one linear parameter."""
        lin = self.linear
        if self.no_signature or len(lin) != 1 or self.role not in ("input", "output"):
            raise ModelError(f"term {self.name!r} has no diagnostic signature: define "
                             "signature(), or say why not in no_signature")
        return self.regressors(p, ctx)[lin[0]]

    def __repr__(self) -> str:
        return self.name

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Term) and other.name == self.name

    def __hash__(self) -> int:
        return hash(self.name)




def rate_window(dt: float) -> int:
    """Samples of the temperature-rate window at step ``dt`` (odd): ``RATE_WINDOW_S``."""
    return int(round(RATE_WINDOW_S / dt)) | 1


def temperature_rate(temp: np.ndarray, dt: float) -> np.ndarray:
    """dT/dt of a temperature series (:attr:`Context.temp_rate`): the Savitzky-Golay
    derivative over :func:`rate_window` samples (fewer on a shorter series; a plain
    difference below 5)."""
    n = temp.size
    w = min(rate_window(dt), n if n % 2 else n - 1)
    if w < 5:
        return np.gradient(temp, dt) if n > 1 else np.zeros(n)
    return savgol_slope(temp, w, dt)


def slope_kernel(w: int, dt: float) -> np.ndarray:
    """The weights of the centred linear least-squares slope over an odd window of ``w``
    samples, ``j / Σ j² / dt`` (j = −h..h, h = (w − 1)/2): :func:`savgol_slope` inside a
    series is the window's dot product with them."""
    h = (w - 1) // 2
    j = np.arange(-h, h + 1, dtype=float)
    return j / float(j @ j) / dt


def savgol_slope(x: np.ndarray, w: int, dt: float) -> np.ndarray:
    """First derivative of a local quadratic least-squares fit over an odd window of ``w``
    samples (Savitzky–Golay, polynomial order 2, scipy's ``savgol_filter(x, w, 2, deriv=1,
    delta=dt, mode="interp")`` to rounding: the same fits, without importing
    scipy.signal, which imports scipy.stats, ~0.6 s of a command's start).

    Inside, the derivative of a centred quadratic fit is the centred linear fit's slope,
    ``Σ j x_{i+j} / Σ j²`` (j = −h..h, h = (w − 1)/2); in the first and last ``h``
    samples it is the derivative of the quadratic fitted to the first (last) ``w``
    samples, evaluated there (``mode="interp"``).
    """
    x = np.asarray(x, dtype=float)
    n, h = x.size, (w - 1) // 2
    kernel = slope_kernel(w, dt)
    out = np.empty(n)
    # np.convolve flips its second argument: correlate with the kernel
    out[h:n - h] = np.convolve(x, kernel[::-1], mode="valid")
    pos = np.arange(w, dtype=float)
    for lo, idx in ((0, pos[:h]), (n - w, pos[w - h:])):
        a2, a1, _ = np.polyfit(pos, x[lo:lo + w], 2)
        out[lo + idx.astype(int)] = (2.0 * a2 * idx + a1) / dt
    return out
