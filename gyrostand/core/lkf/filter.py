"""The paper's linearised Kalman filter with a moving linearisation point (Algorithm 2),
over a record: the paper's single pass (optionally iterated) and the converging variant.

The filter itself, and how each model term enters it, is :mod:`.lkf_online`
(:class:`OnlineLKF`, :func:`lkf_terms`; re-exported here); the converging filter is
:mod:`.lkf_relin`.

Noise levels (σ, σ_v, and those of the other processes) are *held*, as in the paper where
σ is known: given by the caller, or estimated beforehand (least squares' moments when the
model is a single process, otherwise maximum likelihood) — the result says which.
:func:`lkf` runs the filter over a batch, optionally iterated (re-linearised at the
previous estimate until it settles).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping

import numpy as np

from ...errors import GyrostandError, ModelError
from ..data import Samples
from ..model import Model, context
from ..names import LKF_VARIANTS
from ..results import Estimate, FitResult
from ..validate import prepare, require_samples
from .online import (
    ONLINE_RATE_WINDOW,
    PAPER_POINT,
    LkfTerms,
    OnlineLKF,
    causal_rate,
    default_prior_std,
    estimated_names,
    held_names,
    lkf_layout,
    lkf_terms,
)
from .squarem import fixed_point

__all__ = ["lkf", "OnlineLKF", "LkfTerms", "lkf_terms", "lkf_layout", "held_names",
           "held_values", "estimated_names", "default_prior_std", "causal_rate",
           "relin_fit", "PAPER_POINT", "ONLINE_RATE_WINDOW", "VARIANTS", "BETA_MAX_DT"]

log = logging.getLogger(__name__)

#: the iteration's β stays below BETA_MAX_DT / Δt: a correlation time shorter than the
#: sampling step is white noise, not a Gauss-Markov drift
BETA_MAX_DT = 1.0


def held_values(samples: Samples, model: Model, given: Mapping[str, float]) -> tuple[dict, str]:
    """Values of the held noise parameters: ``given`` first, else (a shape parameter)
    its default, else an estimate."""
    given = {**model.defaults, **given}
    need = [n for n in held_names(model) if n not in given]
    if not need:
        return {n: float(given[n]) for n in held_names(model)}, "given"
    r = None
    if model.is_single_process:
        from ..lsq.fit import lsq

        try:
            r, src = lsq(samples, model), "lsq"
        except GyrostandError as exc:
            log.info("lkf: no lsq noise estimate (%s); using ml", exc)
    if r is None:
        from ..ml.fit import ml

        r = ml(samples, model, fixed={k: v for k, v in given.items() if k in model.param_names},
               std_errors=False)
        src = "ml"
    out = {n: float(given[n]) if n in given else abs(r.value(n)) for n in held_names(model)}
    if out.get("markov.sigma", 1.0) <= 0:
        out["markov.sigma"] = float(np.nanstd(np.diff(samples.drift)))
    return out, src


#: the LKF's variants: the converging filter and the paper's single pass
VARIANTS = LKF_VARIANTS
#: relin batch: re-linearisations (each a noise re-estimate and passes to a fixed point)
#: until the point moves less than this many stds and the noise levels by < 1e-4 relative
BATCH_SETTLE_SIGMA = 1e-2


def lkf(samples: Samples, model: Model, *, variant: str = "relin",
        beta0: float | None = None, gamma0: float | None = None, b0: float | None = None,
        sigma: float | None = None, held: Mapping[str, float] | None = None,
        iterate: bool = False, max_iter: int = 60, tol: float = 1e-4,
        prior_std: Mapping[str, float] | None = None, soaked: bool = True) -> FitResult:
    """Run the LKF over the samples.

    ``variant="relin"`` (default): the converging filter of :mod:`.lkf_relin` run over
    the record to its fixed point (feedback, re-linearised with the held noise levels not
    given re-estimated, until neither moves); the start point is ``beta0``/``gamma0``/``b0``
    or, left out, the least-squares (else ML) fit the noise levels come from.
    ``variant="paper"``: the paper's single pass (or iterated with ``iterate=True``).

    Args:
        beta0: linearisation point of ``markov.beta`` (paper variant default: the
            paper's 1e-4).
        gamma0: linearisation point of ``temp.gamma`` (paper variant default: 1e-4).
        b0: linearisation point of ``bias.b``.
        sigma: the known σ (``markov.sigma``), as in the paper; with ``held``, values
            given are fixed (never re-estimated).
        held: other held values (``white.sigma``, ``random_walk.q``, ...).
        iterate: (paper) re-linearise at the previous estimate until the relative change
            of every estimate is below ``tol`` (at most ``max_iter`` passes).
        soaked: (relin) start the moving point in equilibrium with the first temperature.
    """
    if variant not in VARIANTS:
        raise ModelError(f"unknown lkf variant {variant!r}; choose one of "
                         f"{', '.join(VARIANTS)}")
    if variant == "relin":
        return _lkf_relin(samples, model, beta0, gamma0, b0, sigma, held, max_iter,
                          prior_std, soaked)
    beta0 = PAPER_POINT if beta0 is None else beta0
    gamma0 = PAPER_POINT if gamma0 is None else gamma0
    b0 = 0.0 if b0 is None else b0
    layout = lkf_layout(model)
    given = dict(held or {})
    if sigma is not None:
        given["markov.sigma"] = float(sigma)
    samples = prepare(samples, "lkf")
    require_samples(samples, samples.n_observed, len(layout) + 2, "lkf")
    warnings = list(samples.warnings)
    hv, src = held_values(samples, model, given)
    if src != "given":
        warnings.append(f"lkf: noise levels held at the {src} estimate "
                        f"({', '.join(f'{k}={v:.3g}' for k, v in hv.items())})")
    y = samples.drift
    first = int(np.flatnonzero(np.isfinite(y))[0])
    ps = dict(prior_std) if prior_std else OnlineLKF.default_prior_std(
        model, samples.dt, float(y[first]), float(samples.temp[0]),
        float(np.nanstd(y)) + hv["markov.sigma"], float(np.std(samples.temp)))
    keys = list(lkf_terms(model).estimated)
    state = {"passes": 0}

    # the output terms' regressors as ML sees them (centred dT/dt, time from the start)
    ctx = context(samples, model)
    regs = {k: term.regressors(hv, ctx)[k] for k, term in lkf_terms(model).outputs}

    def one_pass(pt: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
        """g(point): the estimate (and its std) of one LKF pass linearised at ``pt``."""
        point = dict(zip(keys, pt, strict=True))
        f = OnlineLKF(model, samples.dt, beta0=point["markov.beta"],
                      gamma0=point.get("temp.gamma", 0.0), b0=point.get("bias.b", 0.0),
                      held=hv, prior_std=ps, point=point)
        run = _run(f, samples, regs)
        state["passes"] += 1
        return (np.array([run["final"][k][0] for k in keys]),
                np.array([run["final"][k][1] for k in keys]), run)

    start = {"markov.beta": beta0, "temp.gamma": gamma0, "bias.b": b0}
    x0 = np.array([start.get(k, 0.0) for k in keys])
    first_point = dict(zip(keys, map(float, x0), strict=True))
    x1, sd, run = one_pass(x0)
    settled = not iterate
    clipped = [0]  # passes whose beta came out <= 0 and was re-linearised at beta0/3
    if iterate:
        x0, x1, sd, run, settled = fixed_point(one_pass, lambda: state["passes"], x0, x1,
                                                sd, run, max_iter, tol, clipped,
                                                BETA_MAX_DT / samples.dt)
        if not settled:
            warnings.append(f"lkf: iteration did not settle within {max_iter} passes")
        b_end = float(x0[0])
        dur = max(float(samples.t[-1] - samples.t[0]), samples.dt)
        if b_end >= 0.99 * BETA_MAX_DT / samples.dt or b_end < 0.1 / dur:
            warnings.append(
                f"lkf: the iteration ended at beta = {b_end:.3g} 1/s, outside the plausible "
                f"range [{0.1 / dur:.2g}, {BETA_MAX_DT / samples.dt:.2g}]: a spurious fixed "
                "point along the γ/β ridge (measured: 20 % of C2 fits); linearise at an "
                "lsq or ml estimate instead")
    point = dict(zip(keys, map(float, x0), strict=True))
    est = run["final"]
    loud = []
    if est["markov.beta"][0] <= 0:
        loud.append(f"lkf (paper variant): beta = {est['markov.beta'][0]:.3g} <= 0 (not "
                    "mean-reverting): one pass from its linearisation point is badly biased "
                    "(its std is not a confidence band); use variant relin")
    at = [k for k in ("markov.beta", "temp.gamma") if k in est and
          abs(est[k][0] - point[k]) <= 1e-3 * max(abs(point[k]), 1e-12)]
    if at and not iterate:  # (an iteration ends at its point by construction)
        loud.append(f"lkf (paper variant): {', '.join(at)} ended at the linearisation "
                    "point: the pass did not move it (its std is not a confidence band); "
                    "use variant relin")
    for w in loud:
        log.warning("%s", w)
    warnings += loud
    params = {}
    for n in model.param_names:
        if n in est:
            params[n] = Estimate(est[n][0], est[n][1], model.unit(n))
        else:
            params[n] = Estimate(hv[n], 0.0, model.unit(n), fixed=True)
    names = [n for n in layout if n in keys]
    idx = [layout.index(n) for n in names]
    return FitResult(
        method="lkf", model=model, parameters=params, loglik=None, residuals=run["e"],
        residual_var=run["f"], warnings=tuple(dict.fromkeys(warnings)),
        source=samples.source, n_samples=len(samples), n_observed=samples.n_observed,
        dt=samples.dt, covariance=run["P"][np.ix_(idx, idx)], cov_names=tuple(names),
        info={"variant": "paper", "linearization": point, "passes": state["passes"],
              "iterated": iterate,
              "settled": settled, "held_from": src, "first_point": first_point,
              "beta_clipped_passes": clipped[0]},
        history=run["history"],
    )


def _run(f: OnlineLKF, samples: Samples, regs: Mapping[str, np.ndarray]) -> dict:
    N = len(samples)
    e = np.empty(N)
    fv = np.empty(N)
    est_names = [n for n in f.layout if n in f.estimated]
    hist = {n: np.empty(N) for n in est_names}
    hist.update({n + ":std": np.empty(N) for n in est_names})
    hist["drift"] = np.empty(N)
    y, T = samples.drift, samples.temp
    for k in range(N):
        e[k], fv[k] = f.update(float(y[k]), float(T[k]),
                               {n: float(r[k]) for n, r in regs.items()})
        for n, (v, s) in f.estimates.items():
            hist[n][k] = v
            hist[n + ":std"][k] = s
        hist["drift"][k] = f.drift
    return {"e": e, "f": fv, "history": hist, "final": f.estimates, "P": f.covariance}


def _lkf_relin(samples: Samples, model: Model, beta0, gamma0, b0, sigma, held, max_iter,
               prior_std, soaked) -> FitResult:
    """The relin variant over a record (see :func:`lkf`)."""
    from .relin import RelinLKF

    lkf_layout(model)
    given = dict(held or {})
    if sigma is not None:
        given["markov.sigma"] = float(sigma)
    samples = prepare(samples, "lkf")
    require_samples(samples, samples.n_observed, len(lkf_layout(model)) + 2, "lkf")
    warnings = list(samples.warnings)
    hv, src = held_values(samples, model, given)
    point = {"markov.beta": beta0, "temp.gamma": gamma0, "bias.b": b0}
    start_from = "given"
    if beta0 is None or not beta0 > 0:
        fit = _start_fit(samples, model, given)
        point = {k: (fit.value(k) if v is None and k in model.param_names else v)
                 for k, v in point.items()}
        point = {**{k: fit.value(k) for k in model.names_of_kind("linear")},
                 **{k: v for k, v in point.items() if v is not None}}
        if not point["markov.beta"] > 0:
            point["markov.beta"] = 1.0 / max(float(samples.t[-1] - samples.t[0]), samples.dt)
        start_from = fit.method
    point = {k: float(v) for k, v in point.items() if v is not None}
    f = RelinLKF(model, samples.dt, point=point, held=hv, fixed=tuple(given),
                 relinearize_every=0, soaked=soaked, prior_std=prior_std)
    regs = _relin_regressors(samples, model, hv, f)
    y, T = samples.drift, samples.temp
    first = int(np.flatnonzero(np.isfinite(y))[0])
    for k in range(first, len(samples)):
        f.update(float(y[k]), float(T[k]), regs[k] if regs is not None else None)
    settled = False
    for _ in range(max(1, max_iter // 6)):
        noise = dict(f.held)
        last = f.relinearize()
        still = [k for k, v in f.held.items() if abs(v - noise[k]) > 1e-4 * max(abs(v), 1e-12)]
        if last.settled and last.step_sigma <= BATCH_SETTLE_SIGMA and not still:
            settled = True
            break
    if not settled:
        warnings.append("lkf: the re-linearisation did not settle (point or noise levels "
                        f"still moving after {f.relinearizations} re-linearisations)")
    if src != "given":
        warnings.append("lkf: noise levels not given re-estimated at the fixed point "
                        f"({', '.join(f'{k}={v:.3g}' for k, v in f.held.items())})")
    return relin_fit(f, samples, warnings, {"start": start_from, "held_from": src,
                                            "settled": settled}, first)


def _start_fit(samples: Samples, model: Model, given: Mapping[str, float]) -> FitResult:
    """Start point of the relin batch: least squares, or ML where LSQ cannot represent the
    model or finds no mean reversion."""
    if model.is_single_process:
        from ..lsq.fit import lsq

        try:
            r = lsq(samples, model)
            if r.value("markov.beta") > 0:
                return r
        except GyrostandError as exc:
            log.info("lkf: no lsq start (%s); using ml", exc)
    from ..ml.fit import ml

    return ml(samples, model, fixed={k: v for k, v in given.items() if k in model.param_names},
              std_errors=False)


def _relin_regressors(samples: Samples, model: Model, hv: Mapping[str, float], f):
    """The output terms' regressors as ML sees them (centred dT/dt), rows of the samples."""
    if not f.outputs:
        return None
    ctx = context(samples, model)
    cols = {}
    for k, term in f.output_terms:
        if k not in cols:
            cols.update(term.regressors(hv, ctx))
    return np.column_stack([cols[k] for k in f.outputs])


def relin_fit(f, samples: Samples, warnings: list[str], info: Mapping, first: int = 0,
              method: str = "lkf", stds: Mapping[str, float] | None = None) -> FitResult:
    """A :class:`FitResult` of a :class:`~gyrostand.core.lkf.relin.RelinLKF`'s current
    state; its bins are those of ``samples`` from ``first`` on (innovations aligned).
    ``stds`` replaces the filter's stds (the online band widened to its profile
    interval: :func:`~gyrostand.core.lkf.band.calibrated_estimates`), the covariance
    scaled to them with its correlations kept."""
    est = f.estimates
    cov = f.covariance
    if stds:
        scale = np.array([stds[n] / est[n][1] if est[n][1] > 0 else 1.0 for n in f.params])
        cov = cov * np.outer(scale, scale)
        est = {n: (v, stds.get(n, s)) for n, (v, s) in est.items()}
    if est["markov.beta"][0] <= 0:
        warnings.append(f"lkf: beta = {est['markov.beta'][0]:.3g} <= 0 (not mean-reverting)")
    params = {}
    for n in f.model.param_names:
        if n in est:
            params[n] = Estimate(est[n][0], est[n][1], f.model.unit(n))
        else:
            params[n] = Estimate(f.held[n], 0.0, f.model.unit(n), fixed=True)
    N = len(samples)
    e = np.full(N, np.nan)
    v = np.full(N, np.nan)
    ee, vv = f.innovations
    m = min(ee.size, N - first)
    e[first: first + m] = ee[:m]
    v[first: first + m] = vv[:m]
    last = f.last
    return FitResult(
        method=method, model=f.model, parameters=params, loglik=None, residuals=e,
        residual_var=v, warnings=tuple(dict.fromkeys(warnings)), source=samples.source,
        n_samples=N, n_observed=samples.n_observed, dt=samples.dt,
        covariance=cov, cov_names=tuple(f.params),
        info={"variant": "relin", "linearization": dict(zip(
                  f.params, map(float, f.to_model(f.point)[0]), strict=True)),
              "relinearizations": f.relinearizations, "passes": f.total_passes,
              "last_step_sigma": float(last.step_sigma) if last else None,
              "soaked": f.soaked, **dict(info)})
