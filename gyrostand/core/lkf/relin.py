"""The paper's LKF made to converge: error-state feedback and periodic re-linearisation.

Same filter as :mod:`gyrostand.core.lkf.filter` (state ``[δε, δβ, δθ_in, δθ_out, other
processes]``, moving point ε₀(t), Algorithm 2 of MODEL.md), with three changes that make it
reach the exact-likelihood accuracy (measured by ``benchmarks/lkf_accuracy.py``):

1. **Feedback.** The δβ column of F is taken along the filtered drift ε̂ = ε₀ + δε̂, not
   along ε₀ alone, so the random part of the drift — most of the information on β when
   the process noise dominates — enters the estimate of β (the term δβ·δε the paper drops).
2. **Re-linearisation.** On a geometric schedule (:mod:`~gyrostand.core.lkf.schedule`:
   every ``relinearize_every`` bins at first, then every tenth of the record, backing off
   while the point does not settle: linear total cost) the point (β₀ and every linear
   coefficient) is moved to the current estimate and the stored history is filtered again
   at that point, repeatedly, until the estimate equals its point (a fixed point
   θ = g(θ)); each pass is one compiled loop over the record
   (:func:`~gyrostand.core.lkf.kernel.lkf_pass`).
3. **Noise levels re-estimated.** Before the passes, the held noise levels that the caller
   did not fix are re-estimated at the current point by a 1-D likelihood search: the
   common scale concentrated out (``s² = Σ e²/f̃ / n``) and the ratio σ_v/σ searched
   (bounded Brent in ln ratio). Other processes (``random_walk``, ``markov2``) keep their
   ratio to σ.

4. **A rate term's dT/dt centred** (:mod:`~gyrostand.core.lkf.centred`): with
   ``temp_rate`` or ``hysteresis`` in the model each bin goes through once the half rate
   window after it is in (30 bins at Δt = 1 s; :meth:`RelinLKF.flush` at stop), with ML's
   rate for it.

Between re-linearisations the filter runs one bin at a time at the last point (cost: one
small Kalman step). ``soaked=True`` starts ε₀ in equilibrium with the first temperature,
ε₀(0) = Σ θ_j u_j(T₀)/β₀, with δε(0) correlated with δβ, δθ accordingly (the start ML
assumes); otherwise ε₀(0) is the first measurement.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping

import numpy as np

from ...errors import ModelError
from ..aot import kernel
from ..kalman import foh_weights
from ..model import Model
from ..terms.base import Bin, Context, Scales, Term
from .centred import CentredRates
from .kernel import lkf_pass
from .noise import BOUND_STEP as BOUND_STEP  # re-exported (moved to lkf_noise)
from .noise import NOISE_STEP as NOISE_STEP
from .noise import RATIO_BOUNDS as RATIO_BOUNDS
from .noise import inflation, reestimate
from .online import (
    ONLINE_RATE_WINDOW,
    causal_rate,
    default_prior_std,
    lkf_terms,
    offset_term,
    soaked_prior,
)
from .schedule import Relinearization, RelinSchedule
from .squarem import fixed_point

log = logging.getLogger(__name__)

#: β is kept within (0, BETA_MAX_DT/Δt]: a correlation time shorter than Δt is white noise
BETA_MAX_DT = 1.0
#: a re-linearisation has settled when no coefficient moved by more than this many stds
#: (the last one at stop, and the batch's); the periodic online ones stop at
#: ONLINE_SETTLE_SIGMA: the next one, ``relinearize_every`` bins later, goes on from there
SETTLE_SIGMA = 1e-3
ONLINE_SETTLE_SIGMA = 2e-2


class RelinLKF:
    """The converging LKF, one bin at a time, with the record kept for re-filtering.

    Args:
        model: the model (``markov`` required; the terms :func:`~.lkf_online.lkf_terms` takes).
        dt: bin width, s.
        point: start linearisation point: ``markov.beta`` (> 0) and any linear
            coefficient (others start at 0).
        held: every held value (``markov.sigma``, ``white.sigma``, ``random_walk.q``,
            ``markov2.beta``, ``markov2.sigma``, ``warmup.tau`` as the model has them).
        fixed: names in ``held`` that stay as given (not re-estimated).
        relinearize_every: the shortest spacing of the periodic re-linearisations, bins
            (0: never, a single pass); they space out geometrically
            (:mod:`~gyrostand.core.lkf.schedule`).
        soaked: start ε₀ in equilibrium with the first temperature.
        feedback: δβ column along ε̂ (True) or ε₀ (False, the paper's).
        prior_std: prior std of the corrections (by name, and ``delta_eps``).
        max_passes: passes per re-linearisation.
    """

    def __init__(self, model: Model, dt: float, *, point: Mapping[str, float],
                 held: Mapping[str, float], fixed: tuple[str, ...] = (),
                 relinearize_every: int = 100, soaked: bool = True, feedback: bool = True,
                 prior_std: Mapping[str, float] | None = None, max_passes: int = 30):
        terms = lkf_terms(model)  # a ModelError naming any term the filter cannot represent
        self.model, self.dt = model, float(dt)
        off = offset_term(model)
        offset = off[0] if off else None
        self._offset_key: str | None = off[1] if off else None
        self.inputs = [k for k, _ in terms.inputs]
        #: the input term of each input (None: the constant output's u ≡ 1)
        self._in_terms: list[Term | None] = [t for _, t in terms.inputs]
        if off is not None:
            self.inputs.append(off[1])
            self._in_terms.append(None)
        self.output_terms = [(k, t) for k, t in terms.outputs if t is not offset]
        self.outputs = [k for k, _ in self.output_terms]
        self._extra_terms = terms.extras
        self.extras = [t.name for t in terms.extras]
        self.names = ["markov.beta", *self.inputs, *self.outputs]
        self.layout = ["delta_eps", *self.names, *self.extras]
        self.held = {**model.defaults, **{k: float(v) for k, v in held.items()}}
        self.params = [off[2] if off and n == off[1] else n for n in self.names]
        need = [n for n in model.param_names if n not in self.params and n not in self.held]
        if need:
            raise ModelError(f"lkf needs value(s) for the held parameter(s) {', '.join(need)}")
        self.fixed = tuple(fixed)
        beta = float(point.get("markov.beta", 0.0))
        if not beta > 0:
            raise ModelError(f"lkf linearisation point markov.beta must be > 0, got {beta}")
        self.beta_max = BETA_MAX_DT / self.dt
        self.point = np.array([float(point.get(n, 0.0)) for n in self.params])
        self.point[0] = min(beta, self.beta_max)
        if self._offset_key is not None:
            self.point[self.names.index(self._offset_key)] *= self.point[0]
        self.every = int(relinearize_every)
        self.soaked, self.feedback = bool(soaked), bool(feedback)
        self.prior_std = dict(prior_std or {})
        self.max_passes = int(max_passes)
        self.n = 0
        cap = 1024
        self._y = np.empty(cap)
        self._T = np.empty(cap)
        self._X = np.empty((cap, len(self.outputs)))
        self._Uin = np.empty((cap, len(self.inputs)))  # the inputs u_j(T_k) of every bin
        self._E = np.empty(cap)
        self._F = np.empty(cap)
        self._Tbuf: list[float] = []
        #: bins waiting for a rate term's centred dT/dt (:mod:`.centred`)
        self._waiting = CentredRates(self.dt, any(t.rate_input for _, t in self.output_terms))
        self._rate_now = math.nan
        self._bin_memory: dict = {}  # causal filters of the rate (Bin.lagged_rate)
        self.last: Relinearization | None = None
        self.relinearizations = 0
        self.total_passes = 0
        #: re-filter work: Σ passes × bins re-filtered (inflation passes not counted)
        self.refiltered = 0
        self.schedule = RelinSchedule(self.every)
        self._qd: float | None = None
        #: (apply, ẑ, var ẑ, steps (h, k) of the inflation passes, at bound) of the last
        #: noise search, or None
        self._noise: tuple[Callable[[float], None], float, float,
                           tuple[tuple[float, float], ...], bool] | None = None
        self._infl = np.zeros((len(self.names),) * 2)
        self.prior_sd = np.full(len(self.names), np.inf)
        self._configure()
        self.x = np.zeros(len(self.layout))
        self.P = np.zeros((len(self.layout),) * 2)
        self._st = np.zeros(1)

    # ---- set-up -------------------------------------------------------------------------
    def _configure(self) -> None:
        """Discretisation at the current point and noise levels."""
        b0 = float(self.point[0])
        self.phi0, self.a0, self.a1 = foh_weights(b0, self.dt)
        if self._qd is not None:
            # the re-estimated noise is held as the drift's diffusion per bin, σ²(1 − φ²):
            # β and σ²β are nearly uncorrelated, β and σ are not (σ²β is what the short
            # term shows), so holding it keeps the passes' β free of the held level and
            # its std honest; σ follows β
            self.q0 = self._qd
            self.held["markov.sigma"] = math.sqrt(self._qd / -math.expm1(-2.0 * b0 * self.dt))
        else:
            sig = self.held["markov.sigma"]
            self.q0 = sig * sig * -math.expm1(-2.0 * b0 * self.dt)
        self.r = self.held["white.sigma"] ** 2
        # the further processes' own dynamics (phi, q, p0), from their terms
        st = [s for t in self._extra_terms for s in t.states(self.held, self.dt)]
        self.phix = np.array([s[0] for s in st], dtype=float)
        self.qx = np.array([s[1] for s in st], dtype=float)
        self.p0x = np.array([s[2] for s in st], dtype=float)

    def _prior_std(self, y0: float) -> dict[str, float]:
        """Uninformative priors on the scale of the data and of the point."""
        ps = {"delta_eps": math.sqrt(self.held["markov.sigma"] ** 2 + self.r)}
        ys = abs(y0) + self.held["markov.sigma"]
        Ts = max(float(np.max(np.abs(self._T[: max(self.n, 1)]))), 1.0)
        scale = default_prior_std(self.model, Scales(y=ys, T=Ts, rate=self.beta_max))
        if self._offset_key is not None:  # c = βb: b's scale times β's
            scale[self._offset_key] = scale[self.params[self.names.index(
                self._offset_key)]] * self.beta_max
        for i, name in enumerate(self.names):
            ps[name] = min(scale[name], 10.0 * abs(float(self.point[i])) + 1e-3 * scale[name])
        ps.update(self.prior_std)
        return ps

    def _start(self) -> None:
        """Prior at bin 0 for the current point."""
        y0, T0 = float(self._y[0]), float(self._T[0])
        ps = self._prior_std(y0)
        n = len(self.layout)
        P = np.zeros((n, n))
        for i, name in enumerate(self.names, start=1):
            P[i, i] = ps[name] ** 2
        for i, p0 in enumerate(self.p0x, start=1 + len(self.names)):
            P[i, i] = p0
        b0 = float(self.point[0])
        if self.soaked:
            # ε(0) = Σθ_j u_j(T₀)/β + s, s ~ N(0, σ²): linearised, δε(0) = J δθ + s
            eps0 = sum(float(self.point[1 + j]) * self._u(j, T0)
                       for j in range(len(self.inputs))) / b0
            J = np.zeros(n)
            J[1] = -eps0 / b0
            for j in range(len(self.inputs)):
                J[2 + j] = self._u(j, T0) / b0
            P[0, 0] = self.held["markov.sigma"] ** 2
            P = soaked_prior(P, J)
        else:
            xo = self.point[1 + len(self.inputs):]
            eps0 = y0 - float(xo @ self._X[0]) if len(xo) else y0
            P[0, 0] = ps["delta_eps"] ** 2
        self._st[0] = eps0
        self.x[:] = 0.0
        self.P = P
        #: prior std of each internal coefficient (``names``) at the last start
        self.prior_sd = np.sqrt(np.diag(P)[1: 1 + len(self.names)])

    # ---- data ---------------------------------------------------------------------------
    def _grow(self) -> None:
        cap = 2 * self._y.size
        for name in ("_y", "_T", "_E", "_F"):
            a = getattr(self, name)
            b = np.empty(cap)
            b[: self.n] = a[: self.n]
            setattr(self, name, b)
        for name in ("_X", "_Uin"):
            a = getattr(self, name)
            b = np.empty((cap, a.shape[1]))
            b[: self.n] = a[: self.n]
            setattr(self, name, b)

    def _u(self, j: int, T: np.ndarray | float):
        """The input u_j(T) of input ``j``: its term's, or 1 for the constant output."""
        term = self._in_terms[j]
        if term is None:
            return np.ones_like(T) if isinstance(T, np.ndarray) else 1.0
        return term.input(T)

    def _causal_regressors(self, T: float) -> np.ndarray:
        """Output regressors at the newest bin from past bins only (online): each term's
        :meth:`~gyrostand.core.terms.base.Term.causal_regressors`."""
        now = Bin((self.n - 1) * self.dt, T, self._causal_rate, self._bin_memory, self.dt)
        vals: dict[str, float] = {}
        for key, term in self.output_terms:
            if key not in vals:
                vals.update(term.causal_regressors(self.held, now))
        return np.array([vals[k] for k in self.outputs], dtype=float)

    def _causal_rate(self) -> float:
        if self.lag:
            return self._rate_now  # centred (.centred), set as the bin goes in
        return causal_rate(self._Tbuf, self.dt)

    def _context(self) -> Context:
        """The filtered bins as terms see them; with bins waiting (``lag``), dT/dt of the
        last filtered ones centred on the waiting ones' temperatures, as online."""
        n = self.n
        ctx = Context(t=self.dt * np.arange(n), temp=self._T[:n].copy(), dt=self.dt,
                      modifiers=self.model.modifiers)
        rates = self._waiting.rates_of(self._T[:n])
        if rates is not None:
            ctx._cache["rate"] = rates
        return ctx

    def _U(self) -> np.ndarray:
        return self._Uin[: self.n]

    # ---- filtering ----------------------------------------------------------------------
    def _pass(self, k0: int, k1: int, U: np.ndarray) -> tuple[float, float, int]:
        ni = len(self.inputs)
        # compiled at install, else numba's; every array this object's own (float64, C)
        run = kernel("lkf_pass", lkf_pass, made_here=True)
        return run(self._y, U, self._X, self.point[1: 1 + ni].copy(),
                   self.point[1 + ni:].copy(), self.phi0, self.a0, self.a1, self.q0,
                   self.r, self.phix, self.qx, self.feedback, self.x, self.P, self._st,
                   k0, k1, self._E, self._F)

    def update(self, y: float, T: float, regressors: np.ndarray | None = None) -> None:
        """One bin: drift ``y`` (NaN = gap), temperature ``T`` (degC). The first bin must be
        observed. Re-linearises every ``relinearize_every`` bins.

        ``regressors``: the output terms' regressors of this bin, given (the batch's, as ML
        computes them); else each output term's causal one. With a rate term (``lag`` > 0)
        and none given, the bin waits until ``lag`` later ones are in, and its rate is the
        centred one (module docstring); :meth:`flush` takes the waiting bins at stop."""
        if self.n == 0 and not self.pending and math.isnan(y):
            return  # the filter starts at the first observed bin
        if regressors is not None or not self.lag:
            self._take(y, T, regressors)
            return
        for y0, T0, rate in self._waiting.push(y, T):
            self._rate_now = rate
            self._take(y0, T0, None)

    def flush(self) -> None:
        """Take every bin still waiting for its centred rate (at stop)."""
        for y0, T0, rate in self._waiting.flush(self._T[: self.n]):
            self._rate_now = rate
            self._take(y0, T0, None)

    @property
    def lag(self) -> int:
        """Bins a bin waits for (a rate term's centred dT/dt; 0: none)."""
        return self._waiting.lag

    @property
    def pending(self) -> int:
        """Bins received and not yet filtered (waiting for their centred rate)."""
        return len(self._waiting)

    def _take(self, y: float, T: float, regressors: np.ndarray | None) -> None:
        """Filter one bin (:meth:`update`)."""
        if self.n == self._y.size:
            self._grow()
        k = self.n
        self._y[k], self._T[k] = y, T
        self._Tbuf.append(T)
        if len(self._Tbuf) > ONLINE_RATE_WINDOW:
            del self._Tbuf[0]
        self.n += 1
        if self.outputs:
            self._X[k] = self._causal_regressors(T) if regressors is None else regressors
        for j in range(len(self.inputs)):
            self._Uin[k, j] = self._u(j, T)
        if k == 0:
            self._start()
        self._pass(k, k + 1, self._Uin)
        if self.schedule.is_due(self.n):
            self.relinearize(self.schedule.max_passes(self.max_passes),
                             settle_sigma=ONLINE_SETTLE_SIGMA)

    def relinearize(self, max_passes: int | None = None,
                    settle_sigma: float = SETTLE_SIGMA) -> Relinearization:
        """Move the point to the current estimate and re-filter the record until the
        estimate equals its point within ``settle_sigma`` of its std (at most
        ``max_passes`` passes); the next periodic one is then due as
        :class:`~gyrostand.core.lkf.schedule.RelinSchedule` says."""
        n = self.n
        if n == 0:
            raise ModelError("lkf: no observed bin to re-linearise on")
        before = self.values.copy()
        sd_before = self.stds.copy()
        ctx = self._context()
        if self.outputs:
            p = {**self.held, **self._model_point()}
            for j, (key, term) in enumerate(self.output_terms):
                self._X[:n, j] = term.regressors(p, ctx)[key]
        U = self._U()
        self.point = self._clip(before, self.point)
        self._reestimate_noise(ctx)
        state = {"passes": 0}

        def g(pt: np.ndarray) -> tuple[np.ndarray, np.ndarray, None]:
            """One pass over the record linearised at ``pt``: its estimate and std."""
            self.point = np.array(pt, dtype=float)
            self._configure()
            self._start()
            self._pass(0, n, U)
            state["passes"] += 1
            return self.values.copy(), self.stds.copy(), None

        limit = self.max_passes if max_passes is None else max_passes
        x0 = self.point.copy()
        x1, sd, _ = g(x0)
        x0, _, _, _, settled = fixed_point(g, lambda: state["passes"], x0, x1, sd, None,
                                            limit, 0.0, [0], self.beta_max,
                                            settle_sigma=settle_sigma)
        passes = state["passes"]
        self._noise_inflation(n, U)
        scale = np.where(sd_before > 0, sd_before, 1.0)
        step = float(np.max(np.abs(self.values - before) / scale)) if np.all(
            np.isfinite(before)) else math.inf
        self.relinearizations += 1
        self.total_passes += passes
        self.refiltered += passes * n
        self.schedule.record(n, passes, settled)
        self.last = Relinearization(n, passes, settled, step,
                                    {k: v for k, v in self.held.items()
                                     if self.model.kind(k) == "std"},
                                    self._noise is not None and self._noise[4])
        return self.last

    def _clip(self, est: np.ndarray, old: np.ndarray) -> np.ndarray:
        """Next point: β kept in (old/10, min(10·old, β_max)]; β ≤ 0 → old/3."""
        new = est.copy()
        b_old = float(old[0])
        b = float(new[0])
        if not b > 0 or not math.isfinite(b):
            b = b_old / 3
        new[0] = min(max(b, b_old / 10), 10 * b_old, self.beta_max)
        return new

    def _noise_inflation(self, n: int, U: np.ndarray) -> None:
        """The held noise levels' share of the covariance (:func:`.lkf_noise.inflation`)."""
        inflation(self, n, U)

    def _reestimate_noise(self, ctx: Context) -> None:
        """The held noise levels not fixed by the caller, at the current point
        (:func:`.lkf_noise.reestimate`)."""
        reestimate(self, ctx)

    # ---- results ------------------------------------------------------------------------
    @property
    def offset_key(self) -> str | None:
        """Internal name of the constant output entered as c = βb (``bias.beta_b``), or
        None."""
        return self._offset_key

    @property
    def values(self) -> np.ndarray:
        """Current estimate of :attr:`names` (point + correction)."""
        return self.point + self.x[1: 1 + len(self.names)]

    @property
    def stds(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self._cov()), 0.0))

    def _model_point(self) -> dict[str, float]:
        """The point in model parameters (``bias.b`` = c/β)."""
        return dict(zip(self.params, self.to_model(self.point)[0], strict=True))

    def to_model(self, v: np.ndarray, C: np.ndarray | None = None):
        """Internal values ``v`` (and covariance ``C``) to model parameters: b = c/β, with
        the Jacobian for the covariance."""
        if self._offset_key is None:
            return v, C
        i = self.names.index(self._offset_key)
        out = v.copy()
        out[i] = v[i] / v[0]
        if C is None:
            return out, None
        J = np.eye(v.size)
        J[i, i] = 1.0 / v[0]
        J[i, 0] = -v[i] / (v[0] * v[0])
        return out, J @ C @ J.T

    @property
    def estimates(self) -> dict[str, tuple[float, float]]:
        """``name -> (value, std)`` of the estimated model parameters."""
        v, C = self.to_model(self.values, self._cov())
        sd = np.sqrt(np.maximum(np.diag(C), 0.0))
        return {n: (float(a), float(b)) for n, a, b in zip(self.params, v, sd, strict=True)}

    def _cov(self) -> np.ndarray:
        """Covariance of the internal estimate: the filter's, plus the held noise levels'
        share (:meth:`_noise_inflation`)."""
        k = len(self.names)
        return self.P[1: 1 + k, 1: 1 + k] + self._infl

    @property
    def covariance(self) -> np.ndarray:
        """Covariance of the estimated model parameters, in the order of ``params``."""
        return self.to_model(self.values, self._cov())[1]

    @property
    def innovations(self) -> tuple[np.ndarray, np.ndarray]:
        """``(e, f)`` of the stored bins, from the last pass (or the bins since)."""
        return self._E[: self.n].copy(), self._F[: self.n].copy()

    @property
    def regressors(self) -> np.ndarray:
        """The output terms' regressors of the filtered bins (rows; columns
        :attr:`outputs`), as the filter used them."""
        return self._X[: self.n].copy()

    @property
    def last_innovation(self) -> tuple[float, float]:
        """``(e, f)`` of the newest bin (NaN for a gap)."""
        k = self.n - 1
        return (float(self._E[k]), float(self._F[k])) if k >= 0 else (math.nan, math.nan)

    @property
    def drift(self) -> float:
        """Filtered drift ε̂ = ε₀ + δε̂ at the newest bin (without output terms)."""
        return float(self._st[0] + self.x[0])
