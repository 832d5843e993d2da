"""The paper's LKF one sample at a time (:class:`OnlineLKF`), and how a model's terms
enter it (:func:`lkf_terms`).

With ε = ε₀(t) + δε, β = β₀ + δβ, γ = γ₀ + δγ, b = b₀ + δb and second-order terms dropped:

    dε₀/dt = −β₀ ε₀ + γ₀ T(t)                        (the moving linearisation point)
    dδε/dt = −β₀ δε − ε₀(t) δβ + T(t) δγ + √(2σ²β₀) w
    Y_k − ε₀_k − b₀ = δε_k + δb + (other processes) + v_k

State ``[δε, δβ, (δθ_in…), (δθ_out…), (other processes…)]``: the parameter corrections
are constant states. Each term says how it enters (its ``role``): an *input* term (``temp``,
``temp2``) enters the δε row with its input u(T) (:meth:`~gyrostand.core.terms.base.Term.
input`) and drives ε₀ with its linearisation coefficient; an *output* term (``bias``,
``temp_rate``, ``hysteresis``, ``trend``, ``warmup`` with τ held, a plugin's) enters the
measurement with its regressor x_k (a time-varying H, exact since it is linear), computed
causally online (:meth:`~gyrostand.core.terms.base.Term.causal_regressors`); a further
random *process* (``random_walk``, ``markov2``) is stacked with its own dynamics
(:meth:`~gyrostand.core.terms.base.Term.states`) and enters the measurement with
coefficient 1. A term the filter cannot represent (a ``modifier`` such as ``temp_lag``) is
a ModelError naming it. Discretisation is exact in δε (φ₀ = e^{−β₀Δt}) with the inputs
ε₀(t) and u(t) linear between samples.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ...errors import ModelError
from ..aot import kernel
from ..kalman import foh_weights, kf_step
from ..model import Model
from ..terms.base import Bin, Scales, Term

#: the paper's recommended linearisation point (MODEL.md: "of order 10^-4")
PAPER_POINT = 1e-4
#: samples of the causal dT/dt estimate of the online filter (a least-squares slope)
ONLINE_RATE_WINDOW = 61


def causal_rate(temps: list[float], dt: float) -> float:
    """dT/dt (degC/s): least-squares slope of the temperatures of the last samples
    (the online filters keep ``ONLINE_RATE_WINDOW`` of them); 0 for fewer than 3."""
    n = len(temps)
    if n < 3:
        return 0.0
    x = np.arange(n) - (n - 1) / 2
    return float(x @ np.asarray(temps) / (x @ x) / dt)


@dataclass(frozen=True)
class LkfTerms:
    """How a model's terms enter the LKF: ``inputs`` and ``outputs`` as (coefficient,
    term) in model order, ``extras`` the further random processes (stacked states)."""

    inputs: tuple[tuple[str, Term], ...]
    outputs: tuple[tuple[str, Term], ...]
    extras: tuple[Term, ...]

    @property
    def estimated(self) -> tuple[str, ...]:
        """The parameters the LKF estimates: β and every input and output coefficient."""
        return ("markov.beta", *(k for k, _ in self.inputs), *(k for k, _ in self.outputs))


def lkf_terms(model: Model) -> LkfTerms:
    """The LKF's view of ``model``; a ModelError naming every term it cannot represent."""
    if "markov" not in model:
        raise ModelError("lkf linearises the 'markov' term's dynamics: the model needs it")
    bad = {t.name: why for t in model.terms if (why := t.lkf_unsupported())}
    if bad:
        raise ModelError(f"lkf does not support the term(s) {', '.join(bad)} ("
                         + "; ".join(f"{n}: {w}" for n, w in bad.items()) + "); use ml")
    return LkfTerms(
        inputs=tuple((t.linear[0], t) for t in model.terms if t.role == "input"),
        outputs=tuple((k, t) for t in model.terms if t.role == "output" for k in t.linear),
        extras=tuple(t for t in model.terms if t.role == "process" and t.name != "markov"))


def lkf_layout(model: Model) -> list[str]:
    """Names of the LKF's states, in order."""
    terms = lkf_terms(model)
    return ["delta_eps", *terms.estimated, *(t.name for t in terms.extras)]


def estimated_names(model: Model) -> tuple[str, ...]:
    """Parameters of ``model`` the LKF estimates (the others it holds)."""
    return (*(["markov.beta"] if "markov" in model else []),
            *(k for t in model.terms if t.role in ("input", "output") for k in t.linear))


def held_names(model: Model) -> list[str]:
    """Parameters the LKF holds at given values (noise levels, β₂, the warm-up's τ)."""
    est = estimated_names(model)
    return [n for n in model.param_names if n not in est]


def default_prior_std(model: Model, scales: Scales) -> dict[str, float]:
    """Each estimated coefficient's uninformative prior std, from its term
    (:meth:`~gyrostand.core.terms.base.Term.prior_std`) on the data's ``scales``."""
    out: dict[str, float] = {}
    for t in model.terms:
        if t.name == "markov" or t.role in ("input", "output"):
            out.update(t.prior_std(scales))
    return out


class OnlineLKF:
    """The LKF, one sample at a time.

    Args:
        model: the model (``markov`` required; inputs, outputs and further processes as
            :func:`lkf_terms` accepts them).
        dt: sampling step, s.
        beta0: linearisation point of ``markov.beta`` (1/s).
        gamma0: linearisation point of ``temp.gamma``.
        b0: linearisation point of ``bias.b``.
        held: values of the held parameters (see :func:`held_names`), e.g.
            ``{"markov.sigma": 0.1, "white.sigma": 0.01}``.
        prior_std: prior std of each estimated parameter's correction and of the first
            drift discrepancy (``"delta_eps"``); by default derived from the first sample.
        point: linearisation point of further coefficients (by name; default 0).
    """

    def __init__(self, model: Model, dt: float, *, beta0: float = PAPER_POINT,
                 gamma0: float = PAPER_POINT, b0: float = 0.0,
                 held: Mapping[str, float], prior_std: Mapping[str, float] | None = None,
                 point: Mapping[str, float] | None = None):
        self.model, self.dt = model, float(dt)
        self.terms = lkf_terms(model)
        self.layout = lkf_layout(model)
        self.estimated = self.terms.estimated
        held = {**model.defaults, **held}  # a shape parameter not given: its default
        missing = [n for n in held_names(model) if n not in held]
        if missing:
            raise ModelError(f"lkf needs value(s) for the held parameter(s) {', '.join(missing)}")
        if not beta0 > 0:
            raise ModelError(f"lkf linearisation point beta0 must be > 0, got {beta0}")
        self.beta0 = float(beta0)
        self.gamma0 = float(gamma0) if "temp" in model else 0.0
        self.b0 = float(b0) if "bias" in model else 0.0
        # linearisation point of every estimated coefficient (beyond β₀, γ₀, b₀: 0)
        self.point = {k: 0.0 for k in self.layout if k in self.estimated}
        self.point.update({k: float(v) for k, v in (point or {}).items() if k in self.point})
        self.point.update({"markov.beta": self.beta0})
        if "temp.gamma" in self.point:
            self.point["temp.gamma"] = self.gamma0
        if "bias.b" in self.point:
            self.point["bias.b"] = self.b0
        self._inputs = [(self.layout.index(k), k, t) for k, t in self.terms.inputs]
        self._outputs = [(self.layout.index(k), k, t) for k, t in self.terms.outputs]
        self._u_prev: dict[str, float] = {}
        self._calls = 0
        self._Tbuf: list[float] = []
        self._bin_memory: dict = {}  # causal filters of the rate (Bin.lagged_rate)
        self.held = {k: float(held[k]) for k in held_names(model)}
        self.prior_std = dict(prior_std or {})
        n = len(self.layout)
        self.phi0, self.a0, self.a1 = foh_weights(self.beta0, self.dt)
        self.A = np.eye(n)
        self.A[0, 0] = self.phi0
        self.Qd = np.zeros(n)
        sig = self.held["markov.sigma"]
        self.Qd[0] = sig * sig * -math.expm1(-2 * self.beta0 * self.dt)
        self.H = np.zeros(n)
        self.H[0] = 1.0
        self._p0 = np.zeros(n)  # prior variance of the further processes
        for t in self.terms.extras:
            i = self.layout.index(t.name)
            ((phi, q, p0),) = t.states(self.held, self.dt)
            self.H[i], self.A[i, i], self.Qd[i], self._p0[i] = 1.0, phi, q, p0
        self.r = self.held["white.sigma"] ** 2
        self.x = np.zeros(n)
        self.P = np.zeros((n, n))
        self.k = 0
        self._no_predict = np.zeros((0, 0))
        self._eps0 = 0.0
        self._T = 0.0

    @staticmethod
    def default_prior_std(model: Model, dt: float, y0: float, T0: float,
                          y_scale: float, T_scale: float) -> dict[str, float]:
        """Uninformative priors on the scale of the data (each term's
        :meth:`~gyrostand.core.terms.base.Term.prior_std`): β ≤ 1/Δt; |γ| ≲ β|ε|/|T|
        (from the steady state γT = βε); |b| ≲ |y|; ..."""
        ys = abs(y0) + y_scale
        Ts = max(abs(T0), T_scale, 1e-6)
        return default_prior_std(model, Scales(y=ys, T=Ts, rate=1.0 / dt))

    def _now(self, T: float) -> Bin:
        """The newest sample as the terms' causal regressors see it."""
        return Bin((self._calls - 1) * self.dt, T, self._causal_rate, self._bin_memory,
                   self.dt)

    def _causal(self, now: Bin) -> dict[str, float]:
        out: dict[str, float] = {}
        for _, key, t in self._outputs:
            if key not in out:
                out.update(t.causal_regressors(self.held, now))
        return out

    def _start(self, y: float, T: float) -> None:
        n = len(self.layout)
        # the moving point starts at the first measurement (less the output terms' part)
        x = self._causal(self._now(T)) if self._outputs else {}
        self._eps0 = y - sum(self.point[k] * x[k] for _, k, _ in self._outputs)
        self._T = T
        ps = self.prior_std or self.default_prior_std(
            self.model, self.dt, y, T, self.held["markov.sigma"], 1.0)
        sig = self.held["markov.sigma"]
        P = np.zeros((n, n))
        P[0, 0] = ps.get("delta_eps", math.sqrt(sig * sig + self.r)) ** 2
        for i, name in enumerate(self.layout[1:], start=1):
            P[i, i] = ps[name] ** 2 if name in self.estimated else self._p0[i]
        self.P = P

    def _causal_rate(self) -> float:
        return causal_rate(self._Tbuf, self.dt)

    def update(self, y: float, T: float,
               regressors: Mapping[str, float] | None = None) -> tuple[float, float]:
        """Process one sample: drift ``y`` (NaN = gap, predict only), temperature ``T``.

        ``regressors`` (optional) gives the output terms' regressor values at this sample
        by parameter name (the batch filter passes the same centred dT/dt as ML); those not
        given are computed causally. Returns the innovation and its variance (NaN for a gap).
        """
        self._calls += 1
        self._Tbuf.append(T)
        if len(self._Tbuf) > ONLINE_RATE_WINDOW:
            del self._Tbuf[0]
        if self.k == 0:
            if math.isnan(y):
                return math.nan, math.nan  # the filter starts at the first measured sample
            self._start(y, T)
            for _, key, t in self._inputs:
                self._u_prev[key] = t.input(T)
            A = self._no_predict
        else:
            eps_prev = self._eps0
            drive = 0.0
            for i, key, t in self._inputs:
                uk = t.input(T)
                u = self.a0 * self._u_prev[key] + self.a1 * uk
                self._u_prev[key] = uk
                drive += self.point[key] * u
                self.A[0, i] = u  # ∫u δθ (FOH weights a0, a1)
            self._eps0 = self.phi0 * eps_prev + drive
            # row of δε: φ₀ δε − ∫ε₀ δβ + Σ ∫u_j δθ_j
            self.A[0, 1] = -(self.a0 * eps_prev + self.a1 * self._eps0)
            self._T = T
            A = self.A
        self.k += 1
        z = y - self._eps0
        given = regressors or {}
        causal: dict[str, float] | None = None
        for i, key, _ in self._outputs:
            x = given.get(key)
            if x is None:
                if causal is None:
                    causal = self._causal(self._now(T))
                x = causal[key]
            self.H[i] = x
            z -= self.point[key] * x
        step = kernel("kf_step", kf_step)  # compiled at install, else numba's
        e, f = step(self.x, self.P, A, self.Qd, self.H, self.r, z)
        return float(e), float(f)

    @property
    def estimates(self) -> dict[str, tuple[float, float]]:
        """Current ``name -> (value, std)`` of the estimated parameters."""
        return {name: (self.point[name] + float(self.x[i]),
                       float(math.sqrt(max(self.P[i, i], 0.0))))
                for i, name in enumerate(self.layout) if name in self.estimated}

    @property
    def drift(self) -> float:
        """Current filtered drift ε̂ = ε₀ + δε (without bias)."""
        return self._eps0 + float(self.x[0])

    @property
    def covariance(self) -> np.ndarray:
        return self.P.copy()


#: a constant output term (``constant``: the bias) enters as an input of the drift:
#: y = ε + b with dε/dt = −βε + γT is, for ε' = ε + b, dε'/dt = −βε' + γT + βb: the
#: coefficient c = βb of the input u ≡ 1 (named ``<term>.beta_<param>``, e.g.
#: ``bias.beta_b``). The δβ column then runs along the filtered *measured* level ε̂', which
#: the data pin down; as an output state δb is confounded with δε's level, and the dropped
#: δβ·δε term biases β (measured: β −30 % with a 4× too small std on a 6-h chamber record)
BIAS_RATE = "bias.beta_b"


def offset_term(model: Model) -> tuple[Term, str, str] | None:
    """The constant output term entered as c = βb: ``(term, internal name, parameter)``."""
    for t in model.terms:
        if t.constant and t.role == "output" and len(t.linear) == 1:
            lin = t.linear[0]
            return t, f"{t.name}.beta_{lin.split('.', 1)[1]}", lin
    return None


def soaked_prior(P: np.ndarray, J: np.ndarray) -> np.ndarray:
    """Prior of ``[δε, δθ…]`` when δε(0) = J δθ + s: Cov = [[J Pθ J' + var s, J Pθ],
    [Pθ J', Pθ]] with ``Pθ`` the diagonal of P beyond row 0 and ``var s = P[0, 0]``."""
    out = P.copy()
    pt = np.diag(P).copy()
    pt[0] = 0.0
    jp = J * pt
    out[0, 0] = P[0, 0] + float(J @ jp)
    out[0, 1:] = jp[1:]
    out[1:, 0] = jp[1:]
    return out
