"""Candidates screened by score (Lagrange-multiplier) tests before any refit.

At the current fit (the null: a candidate's coefficient θ_c = 0, the current model's
estimates held) the score of θ_c and its information come from the current model's one
Kalman-filter pass (Harvey 1989, 5.2; Engle 1984): with ε_k = e_k / √f_k the whitened
innovations and x the candidate's regressor through the same filter, whitened,

    S = x'ε,    I = x'M x,    LM = S² / I = Z²          (one coefficient)

M = I − T V T' the metric of the efficient score (:func:`~.shapes.efficient_metric`: the
current parameters readjust with the candidate; T their whitened mean tangents, V their
covariance). A term with k coefficients (columns C, each through √M): LM = ε'C(C'C)⁻¹C'ε
~ χ²(k). A term shaped by a parameter not identified under the null (a lag τ, a width w):
Z(θ) over the same log grid the LR's calibration measures (:func:`~.shapes.shape_grid`),
LM = sup_θ Z(θ)², referred to the supremum of a χ²(1) process over the shape with the
same curvatures (:func:`~.chisq.sup_chi2_sf`), computed in the same pass; the LR's p-value
then reuses those curvatures (no second pass).

Screened (not refitted) is a candidate whose score p ≥ :data:`SCREEN_P` (0.5) and that is not
among the :data:`SCREEN_TOP` best by score, and only when the saturated reference shows
no lack of fit (``diagnose`` screens nothing otherwise). Measured
(benchmarks/results/screen_misses.txt, first version: screened also under a lack of fit,
p < 0.2): on a hidden warm-up, temp_rate's refit LR 26.3 (p 2e-6, significant) had an LM
of 3.4 at the fit and at the reference's random part — the refit trades the misfit
against the random part, which a local test at either point cannot see; and on a
random walk with random_walk in the model, warmup's LR 10.3 (p 0.009) had an LM of 2.9
(p 0.38). So the LM is a lower bound of the LR only where the current model fits. A screened candidate stays in the table with
its LM statistic in place of an LR, not ranked. Not screened, always refitted: random
processes (their variance's null is the boundary q = 0, where the score of q is a
second-order quantity: the first derivative of ln L in q at 0 is the one-sided score, but
its information needs the filter's derivative in q, a pass per state — and a random walk
or a second Markov process that the drift's Markov process partly absorbs is where the
LM's quadratic approximation is poorest), modifiers (``temp_lag``: a lag changes every
input term's regressor, its τ not identified under the null: no one coefficient),
candidate terms with a nonlinear parameter whose test is not calibrated, and a joint
diagnosis of several runs.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..chisq import chi2_sf, sup_chi2_sf
from ..data import Samples
from ..model import Model, context
from ..results import FitResult
from ..terms.builtin import TERMS
from ..threads import one_blas_thread
from ..validate import prepare
from .results import TEST_SCORE, TEST_SUP, Candidate
from .shapes import (
    efficient_metric,
    lag_params,
    mean_tangents,
    shape_curvatures,
    shape_grid,
    shape_params,
)

__all__ = ["SCREEN_P", "SCREEN_TOP", "Score", "efficient_columns", "score_testable",
           "score_tests", "screenable", "screened_candidate", "to_refit"]

#: a candidate whose score p-value is below this is refitted (conservative — the LM ran
#: to a third of the LR, LM p 0.38 for a refit's p 0.009 — because a screen
#: that misses a significant candidate costs a wrong diagnosis; one that lets an
#: insignificant one through costs only a refit)
SCREEN_P = 0.5
#: ... and always the best few by score, whatever their p
SCREEN_TOP = 2
MAX_THREADS = 4


@dataclass(frozen=True)
class Score:
    """A candidate's score test at the current fit: ``stat`` the LM statistic (the sup
    over the shape for a shaped term), ``df``, ``p_value``, ``shape_lkc`` the shape
    range's curvatures (``()`` for a term without a calibrated shape), ``seconds``."""

    term: str
    stat: float
    df: int
    p_value: float
    shape_lkc: tuple[float, ...]
    seconds: float


def screenable(samples: Samples | tuple[Samples, ...], model: Model, term: str) -> bool:
    """Whether ``term``'s refit may be replaced by a score test (see the module's text):
    one run, a deterministic input or output term whose nonlinear parameters, if any, are its
    calibrated shape."""
    if isinstance(samples, tuple):
        return False
    cls = TERMS[term]
    if cls.n_states or cls.role not in ("input", "output"):
        return False
    bigger = model.add(term)
    nonlin = [f"{term}.{q.name}" for q in cls.params if q.kind != "linear"]
    return not nonlin or set(nonlin) == set(shape_params(bigger, term))


def score_testable(samples: Samples | tuple[Samples, ...], model: Model, term: str) -> bool:
    """Whether ``term`` has a score test at the current fit: a :func:`screenable` term, or
    (one run) a modifier with one shape, tested by its chord (temp_lag's τ,
    :func:`~.shapes.lag_params`) — its test guards the LR's p
    (:func:`~.candidates.guarded`), but it is always refitted."""
    if screenable(samples, model, term):
        return True
    return not isinstance(samples, tuple) and bool(lag_params(model.add(term), term))


@dataclass(frozen=True)
class _Point:
    """Parameters at which a score is taken, fit-like for :func:`~.shapes.shape_grid`:
    ``values``, and a covariance (``None``: the metric projects the tangents out,
    M = I − P_T, which can only raise the LM — conservative for a screen)."""

    values: dict[str, float]
    covariance: np.ndarray | None = None
    cov_names: tuple[str, ...] = ()


def _whitened(samples: Samples, model: Model, base: FitResult | _Point
              ) -> tuple[Samples, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None,
                         np.ndarray]:
    """The filter at ``base`` once: (the samples used, observed mask, 1/√f, ε, K, d)
    with ``K, d`` the efficient metric (:func:`~.shapes.efficient_metric`)."""
    used = prepare(samples, "candidates")
    vals = dict(base.values)
    names, Tx = mean_tangents(model, vals, context(used, model))
    E, f = model.filter_columns(vals, used, Tx)
    ok = np.isfinite(E[:, 0]) & (f > 0)
    scale = 1.0 / np.sqrt(f[ok])
    lin = model.names_of_kind("linear")
    theta = np.array([vals[n] for n in lin])
    e = E[ok, 0] - (E[ok, 1:1 + len(lin)] @ theta if theta.size else 0.0)
    K, d = efficient_metric(E[ok, 1:] * scale[:, None], names, base)
    return used, ok, scale, e * scale, K, d


def _second_point(samples: Samples, model: Model, base: FitResult,
                  also: Mapping[str, float]) -> _Point:
    """The current model at the random part ``also`` (the saturated reference's: one the
    misfit cannot have inflated), its coefficients by GLS there and the noise's common
    scale concentrated: a √n-consistent nuisance under the alternative, so that the
    score there is a C(α) test (Neyman 1959) of the candidate too. A misfit the current
    fit's random part absorbed (measured: a hidden T² on a 2-h cycle, LM 6.3 at the fit
    against its refit's LR 88.7) whitens the candidate's score away at the fit; the
    screen takes the larger of the two."""
    used = prepare(samples, "candidates")
    vals = {**base.values, **also}
    lin = model.names_of_kind("linear")
    X = model.regressors(vals, context(used, model))
    E, f = model.filter_columns(vals, used, X)
    ok = np.isfinite(E[:, 0]) & (f > 0)
    w = 1.0 / np.sqrt(f[ok])
    if lin:
        theta, *_ = np.linalg.lstsq(E[ok, 1:] * w[:, None], E[ok, 0] * w, rcond=1e-12)
        vals.update({n: float(v) for n, v in zip(lin, theta, strict=True)})
        r = (E[ok, 0] - E[ok, 1:] @ theta) * w
    else:
        r = E[ok, 0] * w
    s = float(np.sqrt(np.mean(r ** 2)))
    for n in model.names_of_kind("std"):
        vals[n] *= s
    return _Point(vals)


def _linear_score(used: Samples, model: Model, base: FitResult | _Point, term: str,
                  ok: np.ndarray, scale: np.ndarray, eps: np.ndarray,
                  K: np.ndarray | None, d: np.ndarray) -> tuple[float, int]:
    """LM = ε'C(C'C)⁻¹C'ε of a term without shape parameters; (LM, its coefficients)."""
    bigger = model.add(term)
    vals = {**base.values, **{n: 0.0 for n in bigger.param_names
                              if n not in base.values}}
    X = np.column_stack(_regressors(bigger, term, vals, context(used, bigger)))
    C = model.filter_columns(base.values, used, X)[0][ok, 1:] * scale[:, None]
    if K is not None:
        C -= K @ (d[:, None] * (K.T @ C))
    b = C.T @ eps
    sol, *_ = np.linalg.lstsq(C.T @ C, b, rcond=1e-12)
    return max(float(b @ sol), 0.0), X.shape[1]


def efficient_columns(samples: Samples, model: Model, base: FitResult,
                      make: Callable[[Samples], np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(C, ε): the columns ``make(used)`` ((N, k) regressors on the samples the fit uses)
    through the current model's filter at ``base``, whitened and efficient (√M: the current
    parameters readjust), and the whitened innovations; the score statistic of any subset
    J of them is ε'C_J(C_J'C_J)⁻¹C_J'ε (the forms of :func:`~.formula.score_formula`)."""
    with one_blas_thread():
        used, ok, scale, eps, K, d = _whitened(samples, model, base)
        C = model.filter_columns(base.values, used, make(used))[0][ok, 1:] * scale[:, None]
        if K is not None:
            C -= K @ (d[:, None] * (K.T @ C))
    return C, eps


def _regressors(bigger: Model, term: str, vals: dict[str, float], ctx: object
                ) -> list[np.ndarray]:
    """The regressor columns of ``term``'s coefficients in ``bigger``."""
    lin = [n for n in bigger.names_of_kind("linear") if n.startswith(term + ".")]
    owner = bigger.term_of(lin[0])
    got = owner.regressors(vals, ctx)  # type: ignore[arg-type]
    return [got[n] for n in lin]


def _shape_sup(samples: Samples, model: Model, point: _Point, term: str,
               eps: np.ndarray) -> float:
    """sup over the shape grid of Z(θ)² at ``point`` (:func:`~.shapes.shape_grid`)."""
    axes, unit = shape_grid(samples, model, point, term)
    blocks = ([[(v,) for v in axes[0]]] if len(axes) == 1 else
              [[(u, w) for u in axes[0]] for w in axes[1]])
    return max(float(np.max((unit(zs).T @ eps) ** 2, initial=0.0)) for zs in blocks)


def _one(samples: Samples, model: Model, base: FitResult, term: str,
         preps: list[tuple[FitResult | _Point, tuple]]) -> Score:
    t0 = time.perf_counter()
    (_, (used, ok, scale, eps, K, d)), *more = preps
    bigger = model.add(term)
    if shape_params(bigger, term) or lag_params(bigger, term):
        best = [0.0]

        def seen(U: np.ndarray) -> None:
            best[0] = max(best[0], float(np.max((U.T @ eps) ** 2, initial=0.0)))

        lkc = shape_curvatures(samples, model, base, term, seen)
        stat = best[0]
        with one_blas_thread():
            for point, prep in more:
                stat = max(stat, _shape_sup(samples, model, point, term,  # type: ignore[arg-type]
                                            prep[3]))
        return Score(term, stat, 1, float(sup_chi2_sf(stat, 1, lkc)), lkc,
                     time.perf_counter() - t0)
    with one_blas_thread():
        stat, k = 0.0, 1
        for point, prep in preps:
            one, k = _linear_score(prep[0], model, point, term, *prep[1:])
            stat = max(stat, one)
    return Score(term, stat, k, float(chi2_sf(stat, k)), (), time.perf_counter() - t0)


def score_tests(samples: Samples, model: Model, base: FitResult, terms: list[str],
                also: Mapping[str, float] | None = None) -> dict[str, Score]:
    """The score test of each of ``terms`` (each :func:`score_testable`) at the fit ``base``
    of ``model`` — and, given ``also`` (a random part, the saturated reference's), at
    the current model with that random part (:func:`_second_point`), the larger LM kept:
    one filter pass of the current model per point, then one pass per candidate's
    regressor columns (its shape grid's, for a shaped term), on a thread per CPU in the
    main thread (the compiled filter releases the GIL)."""
    if not terms:
        return {}
    with one_blas_thread():
        points: list[FitResult | _Point] = [base]
        if also:
            points.append(_second_point(samples, model, base, also))
        preps = [(pt, _whitened(samples, model, pt)) for pt in points]
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    main = threading.current_thread() is threading.main_thread()
    workers = min(len(terms), cpus or 1, MAX_THREADS) if main else 1
    if workers <= 1:
        return {t: _one(samples, model, base, t, preps) for t in terms}
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="score") as pool:
        futures = {t: pool.submit(_one, samples, model, base, t, preps) for t in terms}
        return {t: futures[t].result() for t in terms}


def screened_candidate(s: Score, base: FitResult) -> Candidate:
    """The table's row of a candidate the screen ruled out: its LM statistic in place of
    the LR (ΔAIC/ΔBIC from it, their asymptotic equivalent), not refitted, not ranked."""
    n = base.n_observed
    return Candidate(
        term=s.term, lr_stat=s.stat, df=s.df, p_value=s.p_value,
        delta_aic=-s.stat + 2 * s.df, delta_bic=-s.stat + s.df * float(np.log(n)),
        rms_after=base.residual_rms, loglik_after=float(base.loglik or 0.0), effect={},
        seconds=s.seconds, note=f"screened (score test): LM {s.stat:.2f}, p {s.p_value:.2g} "
        f">= {SCREEN_P:g}; not refitted", test=TEST_SCORE if not s.shape_lkc else TEST_SUP,
        shape_lkc=s.shape_lkc, n_params=s.df, score_stat=s.stat, score_p=s.p_value,
        screened=True)


def to_refit(scores: dict[str, Score], p_screen: float = SCREEN_P,
             top: int = SCREEN_TOP) -> set[str]:
    """The screened terms the screen cannot rule out: score p < ``p_screen``, and the
    ``top`` best by score p (then by LM)."""
    best = sorted(scores.values(), key=lambda s: (s.p_value, -s.stat))[:top]
    return {s.term for s in scores.values() if s.p_value < p_screen} | {s.term for s in best}
