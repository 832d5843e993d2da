"""Model terms: the named building blocks of a drift model (PRODUCT.md vocabulary).

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

from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .kalman import first_order_response, foh_weights

P = Mapping[str, float]


@dataclass(frozen=True)
class Param:
    """One parameter of a term.

    ``kind`` is ``"rate"`` (positive, enters nonlinearly: 1/s or s), ``"std"`` (a standard
    deviation or noise intensity, >= 0) or ``"linear"`` (a coefficient the model is linear in).
    """

    name: str
    kind: str
    unit: str
    doc: str


@dataclass(frozen=True)
class Context:
    """What terms need from the data: times ``t`` (s), temperature ``temp`` (degC), ``dt``."""

    t: np.ndarray
    temp: np.ndarray
    dt: float

    def through_markov(self, u: np.ndarray, beta: float) -> np.ndarray:
        """Response of dx/dt = -beta x + u(t) to the input ``u`` (linear between samples).

        Starts in equilibrium with the first input, ``x_0 = u_0 / beta`` (the gyro has
        soaked at the starting temperature), and is exact for piecewise-linear ``u``.
        """
        phi, a0, a1 = foh_weights(beta, self.dt)
        return first_order_response(np.ascontiguousarray(u, dtype=float), phi, a0, a1,
                                    float(u[0]) / beta)


class Term:
    """Base class. Subclasses set ``name``, ``params`` and override what they contribute."""

    name: ClassVar[str]
    params: ClassVar[tuple[Param, ...]] = ()
    requires: ClassVar[tuple[str, ...]] = ()
    n_states: ClassVar[int] = 0
    math: ClassVar[str] = ""

    def key(self, short: str) -> str:
        return f"{self.name}.{short}"

    def regressors(self, p: P, ctx: Context) -> dict[str, np.ndarray]:
        """Regressor column of each linear parameter, keyed by full name."""
        return {}

    def states(self, p: P, dt: float) -> list[tuple[float, float, float]]:
        """``(phi, q, p0)`` of each stochastic state this term adds."""
        return []

    def measurement_var(self, p: P) -> float:
        return 0.0

    def __repr__(self) -> str:
        return self.name

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Term) and other.name == self.name

    def __hash__(self) -> int:
        return hash(self.name)


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

    def states(self, p: P, dt: float) -> list[tuple[float, float, float]]:
        beta, sigma = p[self.key("beta")], p[self.key("sigma")]
        phi = float(np.exp(-beta * dt))
        return [(phi, sigma * sigma * -np.expm1(-2.0 * beta * dt), sigma * sigma)]


class Markov2(Markov):
    """A second, independent Gauss-Markov process (β₂, σ₂), added at the output."""

    name = "markov2"
    params = (
        Param("beta", "rate", "1/s", "inverse correlation time of the second process"),
        Param("sigma", "std", "y", "stationary standard deviation of the second process"),
    )
    math = "dε₂/dt = −β₂ ε₂ + √(2σ₂²β₂) w₂"


class Temp(Term):
    """Temperature input of the Gauss-Markov drift: + γ T(t) in dε/dt."""

    name = "temp"
    params = (Param("gamma", "linear", "y/(s*degC)", "temperature coefficient"),)
    requires = ("markov",)
    math = "γ·T(t) into dε/dt"

    def regressors(self, p: P, ctx: Context) -> dict[str, np.ndarray]:
        return {self.key("gamma"): ctx.through_markov(ctx.temp, p["markov.beta"])}


class Bias(Term):
    """Constant offset b at the output."""

    name = "bias"
    params = (Param("b", "linear", "y", "constant offset"),)
    math = "+ b"

    def regressors(self, p: P, ctx: Context) -> dict[str, np.ndarray]:
        return {self.key("b"): np.ones_like(ctx.t)}


class White(Term):
    """White measurement noise v in Y = ε + v (always part of a model)."""

    name = "white"
    params = (Param("sigma", "std", "y", "measurement noise standard deviation"),)
    math = "+ v,  v ~ N(0, σ_v²)"

    def measurement_var(self, p: P) -> float:
        s = p[self.key("sigma")]
        return s * s


class RandomWalk(Term):
    """Rate random walk at the output: r_k = r_{k−1} + q √Δt w_k, r_0 = 0."""

    name = "random_walk"
    params = (Param("q", "std", "y/sqrt(s)", "random-walk intensity"),)
    n_states = 1
    math = "dr/dt = q w"

    def states(self, p: P, dt: float) -> list[tuple[float, float, float]]:
        q = p[self.key("q")]
        return [(1.0, q * q * dt, 0.0)]


#: the vocabulary of PRODUCT.md, in its order (the contract); None = not implemented yet
VOCABULARY: tuple[str, ...] = (
    "markov", "temp", "white", "bias", "temp2", "temp_lag", "temp_rate", "hysteresis",
    "trend", "warmup", "random_walk", "markov2",
)

TERMS: dict[str, type[Term]] = {
    cls.name: cls for cls in (Markov, Temp, White, Bias, RandomWalk, Markov2)
}
