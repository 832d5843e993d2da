"""The built-in model terms (PRODUCT.md's vocabulary, in its order) and the registry of
every term, built-in or plugin.

Each term is one class: its parameters, role, regressors (batch and causal), prior scale,
diagnostic signature, null hypothesis, look-alikes and summary bit (the facts are
described in :class:`~gyrostand.core.terms.base.Term`). A user's term registers with
:func:`register` (:mod:`gyrostand.plugins` finds them).
"""

from __future__ import annotations

import math
import re

import numpy as np

from ...errors import ModelError
from ..names import VOCABULARY as VOCABULARY  # re-exported; defined in names.py
from .base import (
    HYSTERESIS_RATE,
    NULLS,
    POSITIVE_KINDS,
    RATE_WINDOW_S,
    ROLES,
    T_REF,
    Bin,
    Context,
    P,
    Param,
    Scales,
    Term,
)

__all__ = ["TERMS", "BUILTIN", "ORIGIN", "register", "term_class", "summary_bits",
           "separation", "Term", "Param", "Context", "Bin", "Scales", "ROLES", "NULLS",
           "HYSTERESIS_RATE", "T_REF", "RATE_WINDOW_S", "VOCABULARY", "POSITIVE_KINDS"]


RANDOM = "a random process: no deterministic signature (it shows in the autocorrelation)"


class Markov(Term):
    """First-order Gauss-Markov drift (model (1) of the paper).

    dε/dt = −β ε + (inputs) + √(2σ²β) w;  exact: ε_k = φ ε_{k−1} + w_k, φ = e^{−βΔt},
    var w_k = σ²(1 − φ²), ε_0 ~ N(0, σ²) (stationary). σ is the stationary std.
    """

    name = "markov"
    params = (
        Param("beta", "rate", "1/s", "inverse correlation time"),
        Param("sigma", "std", "y", "stationary standard deviation of the drift"),
    )
    n_states = 1
    math = "dε/dt = −β ε + inputs + √(2σ²β) w"
    role = "process"
    bit = 0
    no_signature = RANDOM

    def states(self, p: P, dt: float) -> list[tuple[float, float, float]]:
        beta, sigma = p[self.key("beta")], p[self.key("sigma")]
        phi = float(np.exp(-beta * dt))
        return [(phi, sigma * sigma * -np.expm1(-2.0 * beta * dt), sigma * sigma)]

    def prior_std(self, s: Scales) -> dict[str, float]:
        return {self.key("beta"): s.rate}  # β ≤ 1/Δt

    def start_values(self, q: Param, duration: float, dt: float) -> list[float]:
        if self.name == "markov" and q.name == "beta":
            # least squares' β seeds ML's grid too (ml.py), but with measurement noise it
            # is biased by orders of magnitude (errors in variables): a wide geometric axis
            return list(np.geomspace(2.0 / duration, 0.5 / dt, 5))
        return super().start_values(q, duration, dt)


class Markov2(Markov):
    """A second, independent Gauss-Markov process (β₂, σ₂), added at the output."""

    name = "markov2"
    params = (
        Param("beta", "rate", "1/s", "inverse correlation time of the second process"),
        Param("sigma", "std", "y", "stationary standard deviation of the second process"),
    )
    math = "dε₂/dt = −β₂ ε₂ + √(2σ₂²β₂) w₂"
    bit = 11
    null = "nuisance"  # β₂ is not identified when σ₂ = 0


class Temp(Term):
    """Temperature input of the Gauss-Markov drift: + γ T(t) in dε/dt."""

    name = "temp"
    params = (Param("gamma", "linear", "y/(s*degC)", "temperature coefficient"),)
    requires = ("markov",)
    math = "γ·T(t) into dε/dt"
    role = "input"
    bit = 1
    no_signature = ("the drift's own temperature input: its filtered response follows the "
                    "markov state; its likelihood-ratio test alone judges it")

    def input(self, T):
        return T

    def prior_std(self, s: Scales) -> dict[str, float]:
        return {self.key("gamma"): s.y * s.rate / s.T}  # |γ| ≲ β|ε|/|T| (γT = βε)


class Bias(Term):
    """Constant offset b at the output."""

    name = "bias"
    params = (Param("b", "linear", "y", "constant offset"),)
    math = "+ b"
    bit = 3
    constant = True
    per_run = True  # the turn-on bias: each switch-on has its own
    no_signature = "a constant: the residuals' cross-correlation removes their mean"

    def regressors(self, p: P, ctx: Context) -> dict[str, np.ndarray]:
        return {self.key("b"): np.ones_like(ctx.t)}

    def causal_regressors(self, p: P, now: Bin) -> dict[str, float]:
        return {self.key("b"): 1.0}


class White(Term):
    """White measurement noise v in Y = ε + v (always part of a model)."""

    name = "white"
    params = (Param("sigma", "std", "y", "measurement noise standard deviation"),)
    math = "+ v,  v ~ N(0, σ_v²)"
    role = "noise"
    bit = 2
    no_signature = "white noise: no deterministic signature"

    def measurement_var(self, p: P) -> float:
        s = p[self.key("sigma")]
        return s * s

    def start_values(self, q: Param, duration: float, dt: float) -> list[float]:
        return [1e-3, 0.03, 0.3, 1.0]  # σ_v/σ


class RandomWalk(Term):
    """Rate random walk at the output: r_k = r_{k−1} + q √Δt w_k, r_0 = 0."""

    name = "random_walk"
    params = (Param("q", "std", "y/sqrt(s)", "random-walk intensity"),)
    n_states = 1
    math = "dr/dt = q w"
    role = "process"
    bit = 10
    null = "boundary"  # q = 0 is the edge of its range
    no_signature = RANDOM
    look_alikes = {"markov2": "a longer run: a second Gauss–Markov process levels off at its "
                              "σ₂, a random walk keeps growing"}

    def states(self, p: P, dt: float) -> list[tuple[float, float, float]]:
        q = p[self.key("q")]
        return [(1.0, q * q * dt, 0.0)]

    def start_values(self, q: Param, duration: float, dt: float) -> list[float]:
        r = np.sqrt(duration)
        return [0.03 / r, 0.3 / r, 3 / r]  # q/σ: a walk of 0.03..3 σ over the record


class Temp2(Term):
    """Quadratic temperature input of the drift: + γ₂ (T − T_ref)² in dε/dt, T_ref = 25 °C."""

    name = "temp2"
    params = (Param("gamma2", "linear", "y/(s*degC^2)", "quadratic temperature coefficient"),)
    requires = ("markov",)
    math = "γ₂·(T − T_ref)² into dε/dt"
    role = "input"
    bit = 4
    signature_needs = ("markov.beta",)
    look_alikes = {
        "temp_lag": "visit the same temperatures while heating and while cooling (a "
                    "symmetric cycle): a quadratic term is the same both ways, a lag is not",
        "hysteresis": "a symmetric heating/cooling cycle over the same range separates them",
    }

    def input(self, T):
        return (T - T_REF) ** 2

    def prior_std(self, s: Scales) -> dict[str, float]:
        return {self.key("gamma2"): s.y * s.rate / (s.T * s.T)}


class TempLag(Term):
    """The drift is driven by a lagged temperature T_L (dT_L/dt = (T − T_L)/τ) instead of T.

    Models a sensor that is not where the heat acts: the gyro's sensitive element lags
    the built-in sensor by τ seconds.
    """

    name = "temp_lag"
    params = (Param("tau", "time", "s", "thermal lag between sensor and gyro"),)
    requires = ("temp",)
    math = "T → T_L,  dT_L/dt = (T − T_L)/τ"
    role = "modifier"
    bit = 5
    null = "nuisance"  # τ is not identified when the lag has no effect
    signature_needs = ("markov.beta",)

    def modify_temperature(self, p: P, ctx: Context, T: np.ndarray) -> np.ndarray:
        # dT_L/dt = (T − T_L)/τ, T_L(0) = T(0)
        tau = p[self.key("tau")]
        return ctx.through_markov(T / tau, 1.0 / tau)

    def signature(self, p: P, ctx: Context) -> np.ndarray:
        # the change a small lag makes: −τ · (response to dT/dt)
        return -ctx.through_markov(ctx.temp_rate, p["markov.beta"])


#: the gyro's internal thermal lag that an effect of the temperature rate acts through
#: (shared by temp_rate and hysteresis; 0 = none: the plain shape)
LAG_PARAM = Param("tau", "time", "s", "internal thermal lag the temperature rate acts "
                  "through (0: none)", default=0.0, physical_bounds=("lower",))
#: that lag's search range: 3·Δt … a tenth of the record. A longer lag turns the rate into
#: a slow curve that a warm-up or a trend explains (measured: on a warm-up + (T − T0)² run
#: a temp_rate lagged by up to the record outranked warmup and lost to random_walk)
LAG_RANGE = (3.0, 0.1)  # (steps Δt, records)


def _lag_bounds(ctx: Context, duration: float) -> tuple[float, float]:
    lo = LAG_RANGE[0] * ctx.dt
    return lo, max(LAG_RANGE[1] * duration, 10 * lo)


class TempRate(Term):
    """Thermal-gradient effect at the output: + k · dT_g/dt.

    The gradient is that of the gyro's element, whose temperature T_g lags the sensor's by
    its internal thermal lag τ (dT_g/dt = (T − T_g)/τ, :meth:`Context.lagged_rate`);
    τ = 0 is the plain k · dT/dt. ML estimates τ (3·Δt … a tenth of the record; at the
    lower bound: no lag measurable); the online filters hold it at its given value, else 0.
    """

    name = "temp_rate"
    params = (Param("k", "linear", "y*s/degC", "sensitivity to the temperature rate"),
              LAG_PARAM)
    rate_input = True
    math = "+ k·dT_g/dt,  dT_g/dt = (T − T_g)/τ"
    bit = 6
    look_alikes = {
        "temp_lag": "a lag τ acts like −τ·γ·dT/dt during slow ramps; fast ramps or steps "
                    "(faster than 1/τ) followed by long soaks separate them: the lag keeps "
                    "acting after the ramp ends, the rate term stops at once",
        "hysteresis": "both follow dT/dt; ramps of clearly different rates separate them: "
                      "the rate term scales with the ramp rate, hysteresis does not",
    }

    def regressors(self, p: P, ctx: Context) -> dict[str, np.ndarray]:
        return {self.key("k"): ctx.lagged_rate(self.shape(p, "tau"))}

    def causal_regressors(self, p: P, now: Bin) -> dict[str, float]:
        return {self.key("k"): now.lagged_rate(self.shape(p, "tau"))}

    def prior_std(self, s: Scales) -> dict[str, float]:
        return {self.key("k"): 10 * s.y * 600.0}  # |k| dT/dt ≲ |y| at 0.1 degC/min

    def search_bounds(self, q: Param, ctx: Context, duration: float) -> tuple[float, float] | None:
        return _lag_bounds(ctx, duration) if q.name == "tau" else None


#: step (in the log of τ) of the lagged rate's central difference in
#: :meth:`Hysteresis.regressor_slopes` (as ML's score steps: ~1e-10 relative)
SLOPE_STEP = 1e-6
#: the hysteresis width's search range, as fractions of the fastest (lagged) rate of the
#: record: from a sharp switch (1 %) to a response that is nearly linear in the rate (1×)
WIDTH_RANGE = (0.01, 1.0)


class Hysteresis(Term):
    """Different offsets when heating and cooling: + h · tanh((dT_g/dt) / w).

    A smooth sign that switches over a width w of temperature rates (degC/s; the default
    1e-3 degC/s = 0.06 degC/min): +h while heating, −h while cooling, ≈ 0 at a soak. The
    rate is the gyro element's, lagged by its internal thermal lag τ as in ``temp_rate``.
    ML estimates w (1 % … 100 % of the record's fastest rate) and τ; the online filters
    hold them at their given values, else the defaults (w = 1e-3, τ = 0).
    """

    name = "hysteresis"
    rate_input = True
    params = (
        Param("h", "linear", "y", "half the heating/cooling offset difference"),
        LAG_PARAM,
        Param("w", "width", "degC/s", "temperature rate over which the offset switches",
              default=HYSTERESIS_RATE, physical_bounds=("lower",)),
    )
    math = "+ h·tanh(dT_g/dt / w),  dT_g/dt = (T − T_g)/τ"
    bit = 7
    look_alikes = {"temp_lag": "long soaks after each ramp separate them: a lag decays "
                               "during the soak, hysteresis holds until the direction "
                               "changes"}

    def regressors(self, p: P, ctx: Context) -> dict[str, np.ndarray]:
        rate = ctx.lagged_rate(self.shape(p, "tau"))
        return {self.key("h"): np.tanh(rate / self.shape(p, "w"))}

    def regressor_slopes(self, p: P, ctx: Context, name: str) -> dict[str, np.ndarray] | None:
        """d tanh(r/w)/d ln w = −(r/w)·sech²(r/w); d/d ln τ = sech²(r/w)·(dr/d ln τ)/w,
        the lagged rate r's slope by central differences of the lag alone: one tanh for
        each shape parameter at a step of ML's search, where central differences of the
        regressor took two each (0.1 s of a 6-h diagnose's hysteresis refit)."""
        tau, w = self.shape(p, "tau"), self.shape(p, "w")
        if name != self.key("w") and not (name == self.key("tau") and tau > 0):
            return None
        x = ctx.lagged_rate(tau) / w
        t = np.tanh(x)
        if name == self.key("w"):
            return {self.key("h"): -x * (1.0 - t * t)}
        up = ctx.lagged_rate(float(np.exp(np.log(tau) + SLOPE_STEP)))
        dn = ctx.lagged_rate(float(np.exp(np.log(tau) - SLOPE_STEP)))
        return {self.key("h"): (1.0 - t * t) * ((up - dn) / (2 * SLOPE_STEP * w))}

    def causal_regressors(self, p: P, now: Bin) -> dict[str, float]:
        rate = now.lagged_rate(self.shape(p, "tau"))
        return {self.key("h"): math.tanh(rate / self.shape(p, "w"))}

    def search_bounds(self, q: Param, ctx: Context, duration: float) -> tuple[float, float] | None:
        if q.name == "tau":
            return _lag_bounds(ctx, duration)
        if q.name != "w":
            return None
        fastest = float(np.max(np.abs(ctx.temp_rate))) if ctx.temp.size else 0.0
        fastest = max(fastest, 10 * HYSTERESIS_RATE * WIDTH_RANGE[0])
        return WIDTH_RANGE[0] * fastest, WIDTH_RANGE[1] * fastest

    def start_values(self, q: Param, duration: float, dt: float) -> list[float]:
        if q.name == "w":
            return [HYSTERESIS_RATE / 3, HYSTERESIS_RATE, 3 * HYSTERESIS_RATE]
        return super().start_values(q, duration, dt)


class Trend(Term):
    """Linear drift in time (ageing, settling): + c · (t − t₀)."""

    name = "trend"
    params = (Param("c", "linear", "y/s", "drift rate of the offset"),)
    math = "+ c·(t − t₀)"
    bit = 8
    look_alikes = {
        "random_walk": "a longer run or repeated cycles: a trend keeps its rate, a random "
                       "walk wanders",
        "warmup": "a longer record after switch-on: the warm-up settles, the trend does not",
    }

    def regressors(self, p: P, ctx: Context) -> dict[str, np.ndarray]:
        return {self.key("c"): ctx.t - ctx.t[0]}

    def causal_regressors(self, p: P, now: Bin) -> dict[str, float]:
        return {self.key("c"): now.t}

    def prior_std(self, s: Scales) -> dict[str, float]:
        return {self.key("c"): 10 * s.y / 3600.0}  # ≲ |y| per hour


class Warmup(Term):
    """Switch-on transient: + A · exp(−(t − t₀)/τ_w)."""

    name = "warmup"
    params = (
        Param("A", "linear", "y", "amplitude of the switch-on transient"),
        Param("tau", "time", "s", "time constant of the switch-on transient"),
    )
    math = "+ A·exp(−(t − t₀)/τ_w)"
    bit = 9
    per_run = True  # each switch-on has its own transient
    look_alikes = {"random_walk": "repeat the switch-on: a warm-up repeats, a random walk "
                                  "does not"}

    def regressors(self, p: P, ctx: Context) -> dict[str, np.ndarray]:
        return {self.key("A"): np.exp(-(ctx.t - ctx.t[0]) / p[self.key("tau")])}

    def causal_regressors(self, p: P, now: Bin) -> dict[str, float]:
        return {self.key("A"): math.exp(-now.t / p[self.key("tau")])}

    def signature(self, p: P, ctx: Context) -> np.ndarray:
        # τ is not known before the fit: a tenth of the record (at least 10 steps)
        tau = max(0.1 * (ctx.t[-1] - ctx.t[0]), 10 * ctx.dt)
        return np.exp(-(ctx.t - ctx.t[0]) / tau)


#: every term gyrostand knows: the built-ins in PRODUCT.md's order (their ``bit``), then
#: the plugins in the order registered (:func:`register`)
TERMS: dict[str, type[Term]] = {
    cls.name: cls for cls in (Markov, Temp, White, Bias, Temp2, TempLag, TempRate, Hysteresis,
                              Trend, Warmup, RandomWalk, Markov2)
}
BUILTIN: dict[str, type[Term]] = dict(TERMS)
if tuple(TERMS) != VOCABULARY or [c.bit for c in TERMS.values()] != list(range(len(TERMS))):
    raise RuntimeError("terms.TERMS must follow names.VOCABULARY, bit i = term i")
#: where each registered plugin term came from (name -> "module:Class" and how it was found)
ORIGIN: dict[str, str] = {}
_NAME_RE = re.compile(r"^[a-z][a-z0-9_]*$")
_KINDS = (*POSITIVE_KINDS, "std", "linear")


def register(cls: type[Term], origin: str = "") -> type[Term]:
    """Add a user's term class to :data:`TERMS` (a plugin: see :mod:`gyrostand.plugins`).

    Its summary bit is the next free one after the built-ins' unless it sets ``bit``.
    Registering the same class again is a no-op; a name or bit another term has is an
    error naming both; a term that does not keep the contract of its role
    (:meth:`~gyrostand.core.terms.base.Term.contract_gaps`: e.g. an output term without
    ``regressors()``, an LKF-capable coefficient without ``prior_std()``) is an error
    naming what it lacks.
    """
    where = origin or f"{cls.__module__}.{getattr(cls, '__qualname__', cls)}"
    if not (isinstance(cls, type) and issubclass(cls, Term)):
        raise ModelError(f"plugin {where}: not a subclass of gyrostand.core.terms.Term")
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise ModelError(f"plugin {where}: term name {name!r} must be lower-case letters, "
                         "digits and '_' (starting with a letter)")
    old = TERMS.get(name)
    if old is cls:
        return cls
    if old is not None:
        what = "the built-in term" if name in BUILTIN else "the plugin term"
        other = f"{old.__module__}.{old.__qualname__}"
        raise ModelError(f"plugin {where}: term name {name!r} clashes with {what} {name!r} "
                         f"({ORIGIN.get(name, other)})")
    gaps = cls.contract_gaps()
    if gaps:
        raise ModelError(f"plugin {where}: term {name!r} (role {cls.role!r}) lacks what a "
                         f"term must state: {'; '.join(gaps)}")
    for q in cls.params:
        if not isinstance(q, Param) or q.kind not in _KINDS or not _NAME_RE.match(q.name):
            raise ModelError(f"plugin {where}: parameter {q!r} must be a Param with a kind "
                             f"of {', '.join(_KINDS)}")
    used = {int(c.bit): n for n, c in TERMS.items() if c.bit is not None}
    if cls.bit is None:
        cls.bit = max(used) + 1
    elif cls.bit in used or cls.bit < 0:
        raise ModelError(f"plugin {where}: summary bit {cls.bit} is taken by term "
                         f"{used.get(cls.bit)!r}" if cls.bit in used else
                         f"plugin {where}: summary bit {cls.bit} must be >= 0")
    TERMS[name] = cls
    ORIGIN[name] = where
    return cls


def term_class(name: str) -> type[Term]:
    """The class of the term ``name``; a :class:`ModelError` naming it and the known terms
    when there is none."""
    try:
        return TERMS[name]
    except KeyError:
        raise ModelError(f"unknown model term {name!r}; the vocabulary is: "
                         f"{', '.join(TERMS)}") from None


def summary_bits() -> dict[str, int]:
    """Bit of every known term in the CAN summary's ``ModelTerms``."""
    return {n: int(c.bit) for n, c in TERMS.items() if c.bit is not None}


def separation(a: str, b: str) -> str | None:
    """What temperature profile tells the look-alike terms ``a`` and ``b`` apart, as either
    term states it (None when neither does)."""
    ca, cb = TERMS.get(a), TERMS.get(b)
    return ((ca.look_alikes.get(b) if ca else None) or
            (cb.look_alikes.get(a) if cb else None))
