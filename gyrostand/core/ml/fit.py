"""Exact Gaussian maximum likelihood from the Kalman-filter innovations.

The log-likelihood of the samples under a model (prediction-error decomposition,
Harvey 1989, 3.4):

    ln L = −½ Σ_k [ ln 2π + ln f_k + e_k² / f_k ],   e_k = y_k − ŷ_{k|k−1}

where the filter is the model's exact discretisation. It is maximised over every free
parameter. Two exact reductions keep the search small and fast:

* the linear parameters θ (``temp.gamma``, ``bias.b``, ...) are concentrated out: the filter
  is linear in the data, so the innovations of ``y − Xθ`` are ``e_y − E_X θ`` and the
  best θ is generalised least squares on the filtered columns (de Jong 1991);
* unless a noise level is fixed (the paper's "σ known"), the common scale of all noise
  variances is concentrated out too: ``s² = (1/n) Σ e_k²/f̃_k``.

What remains — log rates (β, β₂, ...) and log noise ratios — is searched with L-BFGS-B
(:mod:`.search`) from the best points of a start grid seeded by least squares, its gradient
the analytic score (:mod:`.score`). Standard errors come from the
observed information (numerical Hessian of ln L in the natural parameters).
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import threading
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

from ...errors import IdentificationError, ModelError
from ..data import Samples
from ..kalman import kf_run
from ..model import LOG_2PI, Model, context, loglik_of
from ..results import Estimate, FitResult
from ..terms.base import POSITIVE_KINDS
from ..threads import one_blas_thread, pool_width
from ..validate import prepare, require_samples
from .cov import covariance_from_hessian as covariance_from_hessian  # re-exported
from .cov import hessian as hessian
from .cov import observed_covariance
from .gls import concentrated_loglik, fill_natural
from .plain import plain_shapes
from .score import score
from .search import optimise

log = logging.getLogger(__name__)

RATIO_BOUNDS = (1e-6, 1e3)


#: a time constant (warm-up, thermal lag) lies between this many steps Δt ...
TIME_MIN_STEPS = 3.0
#: ... and this many record lengths: shorter is one sample's noise, longer is a trend
TIME_MAX_RECORDS = 1.0
#: points of the scan over a nonlinear parameter new to a refit (see ml_fit's ``start``)
SCAN_POINTS = 13
#: filter inputs [y, X] a problem keeps (>= 2; by the parameters its regressors depend on)
X_CACHE = 8
#: filter outputs (G, Σ ln f, n) a problem keeps, by every parameter but the coefficients:
#: a Hessian's ~2d(d−1) distinct filter passes among its 2d² points
G_CACHE = 64
#: most threads one fit evaluates its likelihood on (see :func:`_evaluator`)
MAX_THREADS = 4


class _Evaluator:
    """Values of a function at several points, in order: on a thread pool when this fit
    runs in the main thread of a process with several CPUs, else one after the other.

    The points of a finite-difference gradient, of a Hessian and of the start grid are
    independent, and an evaluation's time is mostly the compiled Kalman filter, which
    releases the GIL: on 2 CPUs two of them run side by side. Each value is the same
    computation whichever thread makes it, so the fit is the same number for number.
    Inside a worker thread (diagnose's candidate refits, one thread per CPU already) the
    evaluations stay sequential.
    """

    def __init__(self) -> None:
        workers = pool_width(MAX_THREADS)
        self.pool = ThreadPoolExecutor(workers, thread_name_prefix="ml") if workers > 1 \
            else None

    def __call__(self, fun: Callable[[np.ndarray], float],
                 points: Sequence[np.ndarray]) -> list[float]:
        if self.pool is None or len(points) < 2:
            return [fun(z) for z in points]
        return list(self.pool.map(fun, points))

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown()


def time_bounds(dt: float, duration: float) -> tuple[float, float]:
    """Search bounds of ln τ for a physical time constant: several Δt .. the record length."""
    return float(np.log(TIME_MIN_STEPS * dt)), float(np.log(TIME_MAX_RECORDS * duration))


class Problem:
    """The concentrated likelihood of one model on one data set."""

    def __init__(self, model: Model, samples: Samples, fixed: Mapping[str, float]):
        self.model, self.samples, self.fixed = model, samples, dict(fixed)
        unknown = [k for k in self.fixed if k not in model.param_names]
        if unknown:
            raise ModelError(f"cannot fix {', '.join(unknown)}: not a parameter of {model}")
        self.ctx = context(samples, model)
        self.weights = samples.noise_weights
        self.linear = model.names_of_kind("linear")
        self.lin_free = [n for n in self.linear if n not in self.fixed]
        self.free_cols = [1 + j for j, n in enumerate(self.linear) if n not in self.fixed]
        #: the residual's coefficients on [y, X] with the free ones at 0: [1, −θ_fixed]
        self.c0 = np.zeros(1 + len(self.linear))
        self.c0[0] = 1.0
        for j, name in enumerate(self.linear):
            if name in self.fixed:
                self.c0[1 + j] = -self.fixed[name]
        # positive nonlinear parameters (rates 1/s and time constants s), searched in log
        self.rates = [n for n, q in model.params
                      if q.kind in POSITIVE_KINDS and n not in self.fixed]
        stds = [n for n in model.names_of_kind("std") if n not in self.fixed]
        # a noise level fixed at 0 stays 0 under a common scale: it does not stop concentration
        fixed_std = [n for n in model.names_of_kind("std")
                     if n in self.fixed and self.fixed[n] != 0]
        for n in model.names_of_kind("std"):
            if n in self.fixed and self.fixed[n] < 0:
                raise ModelError(f"fixed {n} must be >= 0, got {self.fixed[n]}")
        self.concentrate = not fixed_std and bool(stds)
        self.ref: str | None = None
        self.ref_scale = 1.0
        if self.concentrate:
            self.ref = "markov.sigma" if "markov.sigma" in stds else stds[0]
        elif fixed_std:
            self.ref_scale = float(self.fixed[fixed_std[0]])
        self.stds = [n for n in stds if n != self.ref]
        self.znames = self.rates + self.stds
        dur = max(samples.t[-1] - samples.t[0], 10 * samples.dt)
        self.duration = dur
        params = dict(model.params)

        def rate_bounds(n: str) -> tuple[float, float]:
            own = model.term_of(n).search_bounds(params[n], self.ctx, dur)
            if own is not None:  # the term's own range (a hysteresis width)
                return float(np.log(own[0])), float(np.log(own[1]))
            if model.kind(n) == "time":
                return time_bounds(samples.dt, dur)
            return np.log(1e-3 / dur), np.log(5.0 / samples.dt)

        lo = [rate_bounds(n)[0] for n in self.rates] + \
             [np.log(RATIO_BOUNDS[0] * self.ref_scale)] * len(self.stds)
        hi = [rate_bounds(n)[1] for n in self.rates] + \
             [np.log(RATIO_BOUNDS[1] * self.ref_scale)] * len(self.stds)
        self.bounds = list(zip(lo, hi, strict=True))
        self.n_obs = samples.n_observed
        self.nevals = 0
        self._count = threading.Lock()  # profile() may run on several threads at once
        # regressors depend on rates, times and widths, not on noise levels or coefficients
        self.x_names = [n for n, q in model.params if q.kind not in ("std", "linear")]
        self._x_cache: dict[tuple, np.ndarray] = {}
        #: by searched parameter, the terms whose regressors move with it (.score)
        self.x_deps: dict[str, tuple] = {}
        # the filter's output depends on every parameter but the coefficients
        self._g_names = [n for n, q in model.params if q.kind != "linear"]
        self._g_cache: dict[tuple, tuple[np.ndarray, float, int]] = {}

    def kind(self, name: str) -> str:
        """The kind of a searched parameter (``rate``, ``time``, ``std``)."""
        return self.model.kind(name)

    def unpack(self, z: np.ndarray) -> dict[str, float]:
        p = dict(self.fixed)
        for n, v in zip(self.znames, z, strict=True):
            p[n] = float(np.exp(v))
        if self.ref is not None:
            p[self.ref] = 1.0
        for n in self.lin_free:
            p[n] = 0.0
        return p

    def gram(self, p: Mapping[str, float]) -> tuple[np.ndarray, float, int]:
        """Filter ``[y, X(p)]`` with the model's gains at ``p``: Gram matrix Σ e e'/f of
        the innovations, Σ ln f, and the number of observed samples."""
        key = tuple(p.get(n) for n in self._g_names)
        out = self._g_cache.get(key)  # a Hessian's steps in a coefficient: the same G
        if out is None:
            Y = self.filter_input(p)
            ss = self.model.state_space(p, self.samples.dt)
            _, _, G, slogf, n = kf_run(ss.phi, ss.q, ss.p0, ss.r, self.weights, Y, False)
            out = (G, slogf, n)
            with self._count:
                self._g_cache = {**dict(list(self._g_cache.items())[1 - G_CACHE:]), key: out}
        return out

    def filter_input(self, p: Mapping[str, float]) -> np.ndarray:
        """``[y, X(p)]``, which the filter only reads: kept for the last :data:`X_CACHE`
        values of the parameters the regressors depend on (:attr:`x_names`)."""
        key = tuple(p.get(n) for n in self.x_names)
        Y = self._x_cache.get(key)
        if Y is None:
            Y = self.model.filter_input(p, self.ctx, self.samples.drift)
            with self._count:  # the oldest out: a gradient's points are near each other
                self._x_cache = {**dict(list(self._x_cache.items())[1 - X_CACHE:]), key: Y}
        return Y

    def profile(self, z: np.ndarray):
        """Concentrated ln L at ``z``; also θ̂, scale s² and the GLS information."""
        with self._count:
            self.nevals += 1
        p = self.unpack(z)
        G, slogf, n = self.gram(p)
        if not np.isfinite(slogf):
            return -np.inf, None
        # e = E c0 - E_free θ with c0 = [1, -θ_fixed...]: S(θ) = c0'Gc0 - 2 b'θ + θ'Aθ
        c0 = self.c0
        S = float(c0 @ G @ c0)
        free = self.free_cols
        if free:
            A = G[np.ix_(free, free)]
            b = G[free] @ c0
            theta, *_ = np.linalg.lstsq(A, b, rcond=1e-13)
            S -= float(b @ theta)
        else:
            A = np.zeros((0, 0))
            theta = np.zeros(0)
        ll, s2 = concentrated_loglik(S, n, slogf, self.concentrate)
        return ll, (p, theta, s2, A)

    #: :meth:`score` gives the search its gradient (else central differences)
    analytic_score = True

    def score(self, z: np.ndarray, theta: np.ndarray, s2: float) -> np.ndarray:
        """∂ ln L / ∂z of the concentrated ln L at ``z``, its GLS ``theta`` and ``s2``
        (:func:`.score.score`: one tangent-linear filter pass)."""
        return score(self, z, theta, s2)

    def full_loglik(self, p: Mapping[str, float]) -> float:
        """Exact ln L at natural parameters ``p`` (nothing concentrated): equals
        :meth:`Model.loglik`, from the Gram matrix of the filtered columns."""
        G, slogf, n = self.gram(p)
        if not np.isfinite(slogf):
            return -np.inf
        c = np.empty(G.shape[0])
        c[0] = 1.0
        for j, name in enumerate(self.linear):
            c[1 + j] = -p[name]
        return float(-0.5 * (n * LOG_2PI + slogf + c @ G @ c))

    def natural(self, z: np.ndarray) -> tuple[dict[str, float], np.ndarray, float]:
        """Full parameter dict at ``z`` (scale and θ̂ filled in), GLS info matrix, ln L."""
        ll, extra = self.profile(z)
        if extra is None:
            raise IdentificationError("likelihood is not finite at the optimum")
        p, theta, s2, A = extra
        return (fill_natural(self.model, self.concentrate, self.lin_free, p, theta, s2),
                A / s2, ll)


def start_grid(prob: Problem, seeds: Mapping[str, float | None]) -> list[np.ndarray]:
    """Candidate start points: each term's start values of its searched parameters
    (:meth:`~gyrostand.core.terms.base.Term.start_values`; noise levels as ratios), and
    around each seed value (least squares' β) a factor 3 either way."""
    axes = []
    dur, dt = prob.duration, prob.samples.dt
    model = prob.model
    params = dict(model.params)
    for n in prob.rates:
        vals = model.term_of(n).start_values(params[n], dur, dt)
        seed = seeds.get(n)
        if seed is not None:
            vals += [seed, seed * 3, seed / 3]
        axes.append([np.log(v) for v in vals])
    for n in prob.stds:
        rel = model.term_of(n).start_values(params[n], dur, dt)
        axes.append([np.log(v * prob.ref_scale) for v in rel])
    pts = [np.array(c) for c in itertools.product(*axes)]
    if len(pts) > 150:
        rng = np.random.default_rng(0)
        pts = [pts[i] for i in rng.choice(len(pts), 150, replace=False)]
    lo = np.array([b[0] for b in prob.bounds])
    hi = np.array([b[1] for b in prob.bounds])
    return [np.clip(p, lo + 1e-9, hi - 1e-9) for p in pts]


def lsq_beta(samples: Samples, model: Model) -> float | None:
    """β from least squares on the part of the model it represents (a start value)."""
    from ..lsq.fit import SUPPORTED, lsq

    if "markov" not in model:
        return None
    base = Model.parse([n for n in model.names if n in SUPPORTED and n != "white"])
    try:
        b = lsq(samples, base).value("markov.beta")
    except Exception:  # noqa: BLE001 - a start value only; ML goes on with its grid
        return None
    return b if b > 0 else None


def starts_from(prob, grid: list[np.ndarray], start: Mapping[str, float]
                 ) -> list[np.ndarray]:
    """Start points from a previous fit's natural values ``start`` (by searched name), and
    a scan of each searched rate or time the previous fit lacks; where it lacks noise
    levels only (a random walk's q), a scan of each of them, its lower search bound (the
    previous model itself) included."""
    # a previous fit's values; parameters it lacks start mid-grid
    z0 = []
    mid = np.mean(grid, axis=0) if grid else np.zeros(len(prob.znames))
    for i, n in enumerate(prob.znames):
        ref = start.get(prob.ref, 1.0) if prob.ref and n in prob.stds else 1.0
        if n not in start or not start[n] > 0 or not ref > 0:
            z0.append(mid[i])
        else:
            z0.append(np.log(start[n] / ref))
    z0 = np.clip(z0, [b[0] for b in prob.bounds], [b[1] for b in prob.bounds])
    out = [z0]
    # a nonlinear parameter the previous fit lacks (a warm-up's or a lag's time
    # constant, a second correlation time): scanned over its whole range, Δt to the
    # record length, with the others at the previous fit, so the local search starts
    # in the right basin (a coarse grid alone stops at local optima)
    lacks = [n for n in prob.znames if n not in start]
    # a new noise level alone: its scan (measured on 4-h runs, diagnose's random_walk
    # candidate: the same LR on 15 of 15 runs, walk or none, in 0-16 iterations instead of
    # 13-26 — from mid-range the search crawled to the bound where the walk adds nothing);
    # a new rate's σ with it (a second Markov process) keeps its mid-range start: scanned
    # too, its refit found other optima both ways (LR 1.04 -> 0.003, 0 -> 45); scanned at
    # lower levels with two searches it reaches the higher optimum (LR 26-45 on a lag + walk,
    # 41-57 on a lag alone), where it stands in for the lag and diagnose's advice on those
    # runs fell 7/20 -> 0/20 (benchmarks/results/advice_sequence.txt, session 20)
    scanned = prob.rates if any(n in prob.rates for n in lacks) else [*prob.rates, *prob.stds]
    for i, n in enumerate(prob.znames):
        if n in start or n not in scanned:
            continue
        for v in np.linspace(prob.bounds[i][0], prob.bounds[i][1], SCAN_POINTS):
            z = z0.copy()
            z[i] = v
            out.append(z)
    return out


def ml(samples: Samples, model: Model, **options: Any) -> FitResult:
    """Exact maximum-likelihood fit of every free parameter of ``model``.

    Options as :func:`ml_fit`. BLAS is held to one thread meanwhile: the algebra here is on
    tiny matrices, where OpenBLAS's thread hand-offs cost more than the work (measured:
    0.65 s → 0.24 s for a 6-hour fit, benchmarks/ml_speed.py).
    """
    with one_blas_thread():
        return ml_fit(samples, model, **options)


def ml_fit(samples: Samples, model: Model, *, sigma: float | None = None,
       fixed: Mapping[str, float] | None = None, n_local: int | None = None,
       start: Mapping[str, float] | Sequence[Mapping[str, float]] | None = None,
       std_errors: bool = True,
       hessian_passes: int = 2, grid: bool = True,
       known: FitResult | None = None) -> FitResult:
    """Exact maximum-likelihood fit of every free parameter of ``model``.

    Args:
        sigma: fix ``markov.sigma`` (the paper's "σ known"); same as ``fixed``.
        fixed: parameters held at given values.
        n_local: how many of the best grid starts get a local optimisation (default 2,
            or 5 when the model has several rates, whose likelihood has several basins).
        start: extra start point(s): natural parameter values (e.g. a previous fit).
        std_errors: compute standard errors from the observed information.
        hessian_passes: numerical Hessians behind them (the second with steps set from
            the first pass's stds; one pass is enough to judge identification).
        grid: start from the start grid too (:func:`start_grid`); ``False``: only from
            ``start`` and the scans of the parameters it lacks (:func:`starts_from`), for a
            refit from a neighbouring model's optimum (diagnose's candidates).
        known: the fit of a smaller model (a candidate's current fit): where the
            parameters ``model`` adds sit at a bound, one Hessian pass takes the others'
            covariance from it (:func:`~.cov.observed_covariance`).
    """
    evaluate = _Evaluator()
    try:
        def search(held: Mapping[str, float] | None, n: int | None,
                   at: Mapping[str, float] | Sequence[Mapping[str, float]] | None
                   ) -> tuple[FitResult, Finish]:
            return _ml_fit(samples, model, evaluate, sigma, held, n, at, hessian_passes,
                           grid, known)

        res, finish = plain_shapes(*search(fixed, n_local, start), model, fixed,
                                   lambda held, at: search(held, 1, at))
        # the covariance of the fit kept only: a plain shape's refit made the other's
        # Hessian wasted work (0.03-0.06 s a diagnose candidate)
        return finish(res) if std_errors else res
    finally:
        evaluate.close()


#: adds the observed-information covariance to the fit :func:`_ml_fit` found (or to that
#: fit as :func:`~.plain.plain_shapes` kept it: warnings and info added)
Finish = Callable[[FitResult], FitResult]


def _ml_fit(samples: Samples, model: Model, evaluate: _Evaluator, sigma: float | None,
            fixed: Mapping[str, float] | None, n_local: int | None,
            start: Mapping[str, float] | Sequence[Mapping[str, float]] | None,
            hessian_passes: int, grid: bool = True,
            known: FitResult | None = None) -> tuple[FitResult, Finish]:
    """:func:`ml_fit`'s search, its likelihood evaluated by ``evaluate``: the fit without
    standard errors, and what adds them (:data:`Finish`)."""
    fixed = dict(fixed or {})
    if sigma is not None:
        fixed["markov.sigma"] = float(sigma)
    samples = prepare(samples, "ml")
    prob = Problem(model, samples, fixed)
    n_free = len(prob.znames) + len(prob.lin_free) + (1 if prob.concentrate else 0)
    require_samples(samples, samples.n_observed, n_free + 2, "ml")
    warnings = list(samples.warnings)
    seed = lsq_beta(samples, model) if grid or not start else None  # grid points' only
    starts = start_grid(prob, {"markov.beta": seed})
    n_grid = len(starts)
    for one in ([start] if isinstance(start, Mapping) else start or []):
        starts += starts_from(prob, starts, one) if one else []
    if not grid and len(starts) > n_grid:
        starts = starts[n_grid:]
    z, info, more = optimise(prob, starts, n_local, evaluate)
    warnings += more
    at_bound = info.get("at_bound", [])
    p, gls_info, ll_prof = prob.natural(z)
    e, f = model.innovations(p, samples)  # once: ln L and the fit's residuals
    loglik = loglik_of(e, f)
    if not np.isfinite(loglik):
        raise IdentificationError(f"{samples.source}: ml found no finite likelihood")
    free = [n for n in model.param_names if n not in fixed]

    def parameters(std: Mapping[str, float]) -> dict[str, Estimate]:
        return {n: Estimate(float(fixed[n]), 0.0, model.unit(n), fixed=True) if n in fixed
                else Estimate(float(p[n]), std[n], model.unit(n)) for n in model.param_names}

    params = parameters(dict.fromkeys(free, 0.0))
    info.update({"evaluations": prob.nevals, "concentrated_scale": prob.concentrate,
                 "start_points": len(starts)})
    found = FitResult(
        method="ml", model=model, parameters=params, loglik=float(loglik), residuals=e,
        residual_var=f, warnings=tuple(dict.fromkeys(warnings)), source=samples.source,
        n_samples=len(samples), n_observed=samples.n_observed, dt=samples.dt,
        covariance=None, cov_names=(), info=info,
    )

    def finish(res: FitResult) -> FitResult:
        """``res`` (``found``, or ``found`` with warnings and info added) with the standard
        errors of ``found``'s optimum, the covariance's warnings after the search's."""
        if not free:
            return res
        cov, cw = observed_covariance(
            model, samples, p, free, gls_info, prob, at_bound, hessian_passes, evaluate,
            (list(known.cov_names), known.covariance)
            if known is not None and known.covariance is not None else None)
        std = {n: float(np.sqrt(cov[i, i])) for i, n in enumerate(free)}
        k = len(found.warnings)
        return dataclasses.replace(
            res, parameters=parameters(std), covariance=cov, cov_names=tuple(free),
            warnings=tuple(dict.fromkeys((*res.warnings[:k], *cw, *res.warnings[k:]))))

    return found, finish
