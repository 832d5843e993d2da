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
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from .kalman import first_order_response, foh_weights
from .names import VOCABULARY as VOCABULARY  # re-exported; defined in names.py

P = Mapping[str, float]


@dataclass(frozen=True)
class Param:
    """One parameter of a term.

    ``kind`` is ``"rate"`` (positive, 1/s, enters nonlinearly), ``"time"`` (a positive time
    constant, s, enters nonlinearly), ``"std"`` (a standard deviation or noise intensity,
    >= 0) or ``"linear"`` (a coefficient the model is linear in).
    """

    name: str
    kind: str
    unit: str
    doc: str


#: window of the temperature-rate estimate (s): a local quadratic fit (Savitzky-Golay)
RATE_WINDOW_S = 61.0
#: rate (degC/s) at which the hysteresis regressor tanh(dT/dt / r0) reaches 0.76
HYSTERESIS_RATE = 1e-3
#: reference temperature of temp2 (degC)
T_REF = 25.0


@dataclass(frozen=True)
class Context:
    """What terms need from the data: times ``t`` (s), temperature ``temp`` (degC), ``dt``."""

    t: np.ndarray
    temp: np.ndarray
    dt: float
    _cache: dict = field(default_factory=dict, compare=False, repr=False)

    def through_markov(self, u: np.ndarray, beta: float) -> np.ndarray:
        """Response of dx/dt = -beta x + u(t) to the input ``u`` (linear between samples).

        Starts in equilibrium with the first input, ``x_0 = u_0 / beta`` (the gyro has
        soaked at the starting temperature), and is exact for piecewise-linear ``u``.
        """
        phi, a0, a1 = foh_weights(beta, self.dt)
        return first_order_response(np.ascontiguousarray(u, dtype=float), phi, a0, a1,
                                    float(u[0]) / beta)

    def effective_temp(self, p: P) -> np.ndarray:
        """The temperature that drives the drift: T, or T lagged by ``temp_lag.tau``.

        dT_L/dt = (T − T_L)/τ, T_L(0) = T(0).
        """
        tau = p.get("temp_lag.tau")
        if tau is None:
            return self.temp
        return self.through_markov(self.temp / tau, 1.0 / tau)

    @property
    def temp_rate(self) -> np.ndarray:
        """dT/dt (degC/s), robust to sensor noise and quantisation.

        A naive difference of 0.05-degC steps is mostly quantisation noise; a local
        quadratic least-squares fit over ``RATE_WINDOW_S`` (Savitzky-Golay derivative)
        is exact on ramps and averages the steps out (noise std ≈ q/√12 · √(12/W³)).
        """
        if "rate" not in self._cache:
            n = self.temp.size
            w = int(round(RATE_WINDOW_S / self.dt)) | 1
            w = min(w, n if n % 2 else n - 1)
            if w < 5:
                rate = np.gradient(self.temp, self.dt) if n > 1 else np.zeros(n)
            else:
                from scipy.signal import savgol_filter  # scipy.signal imports scipy.stats

                rate = savgol_filter(self.temp, w, 2, deriv=1, delta=self.dt, mode="interp")
            self._cache["rate"] = rate
        return self._cache["rate"]


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
        return {self.key("gamma"): ctx.through_markov(ctx.effective_temp(p), p["markov.beta"])}


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


class Temp2(Term):
    """Quadratic temperature input of the drift: + γ₂ (T − T_ref)² in dε/dt, T_ref = 25 °C."""

    name = "temp2"
    params = (Param("gamma2", "linear", "y/(s*degC^2)", "quadratic temperature coefficient"),)
    requires = ("markov",)
    math = "γ₂·(T − T_ref)² into dε/dt"

    def regressors(self, p: P, ctx: Context) -> dict[str, np.ndarray]:
        u = (ctx.effective_temp(p) - T_REF) ** 2
        return {self.key("gamma2"): ctx.through_markov(u, p["markov.beta"])}


class TempLag(Term):
    """The drift is driven by a lagged temperature T_L (dT_L/dt = (T − T_L)/τ) instead of T.

    Models a sensor that is not where the heat acts: the gyro's sensitive element lags
    the built-in sensor by τ seconds.
    """

    name = "temp_lag"
    params = (Param("tau", "time", "s", "thermal lag between sensor and gyro"),)
    requires = ("temp",)
    math = "T → T_L,  dT_L/dt = (T − T_L)/τ"


class TempRate(Term):
    """Thermal-gradient effect at the output: + k · dT/dt."""

    name = "temp_rate"
    params = (Param("k", "linear", "y*s/degC", "sensitivity to the temperature rate"),)
    math = "+ k·dT/dt"

    def regressors(self, p: P, ctx: Context) -> dict[str, np.ndarray]:
        return {self.key("k"): ctx.temp_rate}


class Hysteresis(Term):
    """Different offsets when heating and cooling: + h · tanh((dT/dt) / r₀).

    A smooth sign with r₀ = 1e-3 degC/s (0.06 degC/min): +h while heating, −h while
    cooling, ≈ 0 at a soak.
    """

    name = "hysteresis"
    params = (Param("h", "linear", "y", "half the heating/cooling offset difference"),)
    math = "+ h·sign(dT/dt)"

    def regressors(self, p: P, ctx: Context) -> dict[str, np.ndarray]:
        return {self.key("h"): np.tanh(ctx.temp_rate / HYSTERESIS_RATE)}


class Trend(Term):
    """Linear drift in time (ageing, settling): + c · (t − t₀)."""

    name = "trend"
    params = (Param("c", "linear", "y/s", "drift rate of the offset"),)
    math = "+ c·(t − t₀)"

    def regressors(self, p: P, ctx: Context) -> dict[str, np.ndarray]:
        return {self.key("c"): ctx.t - ctx.t[0]}


class Warmup(Term):
    """Switch-on transient: + A · exp(−(t − t₀)/τ_w)."""

    name = "warmup"
    params = (
        Param("A", "linear", "y", "amplitude of the switch-on transient"),
        Param("tau", "time", "s", "time constant of the switch-on transient"),
    )
    math = "+ A·exp(−(t − t₀)/τ_w)"

    def regressors(self, p: P, ctx: Context) -> dict[str, np.ndarray]:
        return {self.key("A"): np.exp(-(ctx.t - ctx.t[0]) / p[self.key("tau")])}


TERMS: dict[str, type[Term]] = {
    cls.name: cls for cls in (Markov, Temp, White, Bias, Temp2, TempLag, TempRate, Hysteresis,
                              Trend, Warmup, RandomWalk, Markov2)
}
