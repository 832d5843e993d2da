"""How far a wrong model stays from the truth on a record: Λ(truth→fit), the whitened
squared distance of the means after the wrong model's best refit plus the noises' Whittle
divergence (the expected log-likelihood ratio; :mod:`~gyrostand.core.design.separation`
describes it), for one record or several switch-ons, and the pieces the power-cycle protocol
(:mod:`~gyrostand.core.design.switch_ons`) shares: the records, the refitted parameters,
their log bounds, the Nelder–Mead of Λ and a verify's tally."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from ..data import Samples
from ..model import Model, context

__all__ = ["VERIFY_FIT", "design_samples", "mean_response", "mean_parameters", "divergence",
           "divergence_runs", "whittle_loglik", "whittle_grids", "refitted_params",
           "log_bounds", "nelder_mead", "tally_wins"]

#: verify's ML fits: only ln L is used (no standard errors); the best start (the model's
#: own parameters among them) refined
VERIFY_FIT = {"n_local": 1, "std_errors": False}


def design_samples(t: np.ndarray, y: np.ndarray, temp: np.ndarray, dt: float) -> Samples:
    return Samples(np.asarray(t, dtype=float), np.asarray(y, dtype=float),
                   np.asarray(temp, dtype=float), float(dt), source="design --separate")


def mean_response(model: Model, params: Mapping[str, float], s: Samples) -> np.ndarray:
    """μ = X θ: the model's deterministic response on the record ``s``."""
    X = model.regressors(params, context(s, model))
    theta = np.array([params[n] for n in model.names_of_kind("linear")])
    return X @ theta if theta.size else np.zeros(len(s))


def _distance(fit: Model, params: Mapping[str, float], s: Samples) -> float:
    """min_β ‖W (y − X β)‖² with the model's whitening W at ``params``."""
    return _joint_distance(fit, [params], [s])


def _joint_distance(fit: Model, params: Sequence[Mapping[str, float]],
                    records: Sequence[Samples]) -> float:
    """The same over several runs (run k at ``params[k]``): one least squares over the
    stacked whitened runs, a shared linear coefficient one column, a per-run one
    (:func:`~.multirun.per_run_names`: the bias, a warm-up's amplitude) a column per run."""
    from ..ml.joint_problem import per_run_names

    lin = fit.names_of_kind("linear")
    per = set(per_run_names(fit))
    cols = [(j, k) for j, n in enumerate(lin)
            for k in (range(len(records)) if n in per and len(records) > 1 else [None])]
    ys, blocks = [], []
    for k, (q, s) in enumerate(zip(params, records, strict=True)):
        X = fit.regressors(q, context(s, fit))
        E, f = fit.filter_columns(q, s, X)
        ok = np.isfinite(E[:, 0]) & (f > 0)
        W = E[ok] / np.sqrt(f[ok])[:, None]
        ys.append(W[:, 0])
        block = np.zeros((W.shape[0], len(cols)))
        for c, (j, owner) in enumerate(cols):
            if owner is None or owner == k:
                block[:, c] = W[:, 1 + j]
        blocks.append(block)
    y = np.concatenate(ys)
    if not cols:
        return float(y @ y)
    A = np.concatenate(blocks)
    beta, *_ = np.linalg.lstsq(A, y, rcond=None)
    r = y - A @ beta
    return float(r @ r)


def mean_parameters(fit: Model, params: Mapping[str, float], s: Samples) -> list[str]:
    """The nonlinear parameters (``rate``, ``time``) the model's mean response depends on
    (markov.beta through an input term, a time constant): what a refit moves to mimic."""
    ctx = context(s, fit)
    X0 = fit.regressors(params, ctx)
    out = []
    for n in fit.param_names:
        if fit.kind(n) in ("rate", "time"):
            q = dict(params)
            q[n] *= 1.01
            if not np.allclose(fit.regressors(q, ctx), X0, rtol=0, atol=0):
                out.append(n)
    return out


def whittle_loglik(S0: np.ndarray, fit: Model, params: Mapping[str, float], w: np.ndarray,
                   dt: float, n: int) -> float:
    """N · mean_j [ρ_j − 1 − ln ρ_j], ρ = S_truth/S_fit: 2 KL of the noises (Whittle)."""
    rho = S0 / _spectrum(fit, params, dt, w)
    return float(n * np.mean(rho - 1.0 - np.log(rho)))


def divergence(truth: Model, truth_params: Mapping[str, float], fit: Model,
               fit_params: Mapping[str, float], t: np.ndarray, temp: np.ndarray, dt: float,
               *, refit_noise: bool = True, found: dict[str, float] | None = None) -> float:
    """Λ(truth→fit) on the record (``t``, ``temp``): min over ``fit``'s linear
    coefficients (least squares), its mean parameters (:func:`mean_parameters`) and, with
    ``refit_noise``, its noise levels (``std``), of the whitened squared distance plus the
    noises' Whittle divergence (module docstring). ``found``: filled with the re-fitted
    nonlinear parameters (a warm start for the next, similar record)."""
    return divergence_runs(truth, truth_params, fit, fit_params, [(t, temp)], dt,
                           refit_noise=refit_noise, found=found)


def divergence_runs(truth: Model, truth_params: Mapping[str, float], fit: Model,
                    fit_params: Mapping[str, float],
                    records: Sequence[tuple[np.ndarray, np.ndarray]], dt: float, *,
                    refit_noise: bool = True, found: dict[str, float] | None = None
                    ) -> float:
    """Λ(truth→fit) summed over several runs (switch-ons) of one gyro, each record
    (``t``, ``temp``) its own run: the truth runs each from its own switch-on with the
    same parameters; ``fit`` is refitted jointly as :mod:`~.multirun` fits several runs
    (its shared parameters once, its per-run ones — bias, a warm-up's A and τ — once per
    run). One record: :func:`divergence`."""

    from ..ml.joint_problem import per_run_names

    recs = []
    for t, temp in records:
        s = design_samples(t, np.zeros_like(t), temp, dt)
        recs.append(s.replace(drift=mean_response(truth, truth_params, s)))
    K = len(recs)
    grids = whittle_grids(truth, truth_params, recs, dt)
    names = refitted_params(fit, fit_params, recs[0], refit_noise)
    per = set(per_run_names(fit)) if K > 1 else set()
    # the searched point: a per-run parameter once per run (owner k), a shared one once
    slots = [(k, owner) for k in names for owner in (range(K) if k in per else [None])]
    bounds = log_bounds(fit, names, max(float(t[-1] - t[0]) for t, _ in records), dt)

    def point(z: np.ndarray) -> list[dict[str, float]]:
        qs = [dict(fit_params) for _ in range(K)]
        for (k, owner), v in zip(slots, z, strict=True):
            lo, hi = bounds[k]
            x = math.exp(min(max(float(v), lo), hi))
            for r in (range(K) if owner is None else [owner]):
                qs[r][k] = x
        return qs

    def total(z: np.ndarray) -> float:
        qs = point(z)
        return _joint_distance(fit, qs, recs) + sum(
            whittle_loglik(S0, fit, q, w, dt, n) for q, (w, S0, n) in zip(qs, grids, strict=True))

    start = np.array([math.log(fit_params[k]) for k, _ in slots])
    best = total(start)
    if not slots:
        return max(best, 0.0)
    fun, x = nelder_mead(total, start, best, refit_noise)
    if found is not None and fun < best:
        # the shared values (a per-run one: its first run's) warm-start the next record
        found.update({k: v for k, v in point(x)[0].items() if k in names})
    return float(max(min(fun, best), 0.0))


def whittle_grids(truth: Model, truth_params: Mapping[str, float], recs: Sequence[Samples],
                  dt: float) -> list[tuple[np.ndarray, np.ndarray, int]]:
    """Each record's Fourier frequencies ω_j = 2πj/N, the truth's noise spectrum at them,
    and N (the Whittle term of :func:`whittle_loglik`)."""
    grids = []
    for s in recs:
        n = len(s)
        w = 2.0 * np.pi * np.arange(1, n // 2 + 1) / n
        grids.append((w, _spectrum(truth, truth_params, dt, w), n))
    return grids


def refitted_params(fit: Model, fit_params: Mapping[str, float], s: Samples, refit_noise: bool
                    ) -> list[str]:
    """The wrong model's parameters searched in Λ's minimization: those its mean depends on
    (:func:`mean_parameters`) and, with ``refit_noise``, the noise levels and the rates of
    processes no input goes through."""
    names = mean_parameters(fit, fit_params, s)
    if refit_noise:
        names += [k for k in fit.param_names if fit.kind(k) in ("std", "rate")
                  and k not in names and fit_params[k] > 0]
    return names


def log_bounds(fit: Model, names: Sequence[str], duration: float, dt: float
               ) -> dict[str, tuple[float, float]]:
    """The searched parameters' bounds in log: a time constant 2Δt .. 20 × the record, a
    rate 1e-3 / the record .. 1/Δt, a noise level unbounded."""
    return {k: ((math.log(2.0 * dt), math.log(20.0 * max(duration, dt)))
                if fit.kind(k) == "time" else
                (math.log(1e-3 / max(duration, dt)), math.log(1.0 / dt))
                if fit.kind(k) == "rate" else (-math.inf, math.inf)) for k in names}


def nelder_mead(total: Callable[[np.ndarray], float], start: np.ndarray, best: float,
                refit_noise: bool) -> tuple[float, np.ndarray]:
    """Nelder–Mead of Λ's ``total`` from ``start`` (where it is ``best``): (min, argmin).
    The search's Λ (noise held) to 1 %, the report's to 0.1 %."""
    from scipy.optimize import minimize

    tol = 1e-3 if refit_noise else 1e-2
    res = minimize(total, start, method="Nelder-Mead",
                   options={"xatol": tol, "fatol": tol * max(best, 1e-3),
                            "maxfev": (200 if refit_noise else 25) * len(start)})
    return float(res.fun), res.x


def _spectrum(model: Model, params: Mapping[str, float], dt: float, w: np.ndarray
              ) -> np.ndarray:
    ss = model.state_space(params, dt)
    z = np.exp(-1j * w)
    S = np.full(w.shape, ss.r)
    for phi, q in zip(ss.phi, ss.q, strict=True):
        S = S + q / np.abs(1.0 - phi * z) ** 2
    return S


def tally_wins(other: str, lrs: Sequence[float], failed: int, penalty: float) -> dict[str, Any]:
    """A verify's tally of one direction: how often the right model wins, by LR (> 0) and
    by BIC (> ``penalty``), the mean LR of the sets whose fits did not fail, and each set's
    LR (for the realised gain's interval, :mod:`.realised`)."""
    arr = np.asarray(lrs)
    return {"fitted_by": other, "failed": failed,
            "right_wins_lr": float(np.mean(arr > 0)) if arr.size else None,
            "right_wins_bic": float(np.mean(arr > penalty)) if arr.size else None,
            "mean_lr": float(np.mean(arr)) if arr.size else None,
            "lrs": [float(x) for x in arr]}
