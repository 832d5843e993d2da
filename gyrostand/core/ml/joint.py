"""Several runs of one gyro, identified at once: the joint exact likelihood.

Runs r = 1..R of the same gyro (switched on R times, days apart) share its physics — the
rates β, the noise levels σ, the temperature coefficients γ and every effect's coefficient —
while each switch-on has its own turn-on bias, its own initial state and, where the model
has one, its own warm-up (the terms with :attr:`~gyrostand.core.terms.base.Term.per_run`).
The runs are independent given the parameters, so the log-likelihood is the sum of each
run's exact Kalman likelihood (:mod:`~gyrostand.core.ml.fit`):

    ln L(θ_shared, θ_1 .. θ_R) = Σ_r ln L_r(θ_shared, θ_r)

Each run is filtered on its own from its own initial state; the linear parameters (shared
and per-run) are concentrated out by one GLS over the summed Gram matrices, the common noise
scale by ``s² = Σ_r S_r / Σ_r n_r``; what remains is searched exactly as for one run (the
same start grid, optimiser and observed-information covariance). One run is the case R = 1
and gives the single-run fit's numbers.

The turn-on-to-turn-on *bias repeatability* is the spread τ of the per-run biases b_r
beyond their own estimation error (a random-effects model, DerSimonian & Laird 1986):

    b = μ 1 + u + e,   u ~ N(0, τ² I),   e ~ N(0, C)     (C: the joint fit's covariance of b)

τ is estimated by restricted maximum likelihood, and its interval is the Q-profile interval
(Viechtbauer 2007): with ``V(τ²) = τ² I + C`` and μ̂ its GLS mean,

    Q(τ²) = (b − μ̂ 1)' V⁻¹ (b − μ̂ 1)  ~  χ²_{R−1}

exactly at the true τ², and Q falls as τ² grows; the interval is the τ² where Q lies between
the χ²_{R−1} quantiles (0 where even τ² = 0 leaves Q below them).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from ...errors import DataError, IdentificationError
from ..data import Samples
from ..model import Model
from ..results import Estimate, FitResult, jsonable
from ..threads import one_blas_thread
from ..validate import prepare, require_samples
from .cov import observed_covariance
from .fit import lsq_beta, start_grid, starts_from
from .joint_problem import BIAS, JointProblem, base_name, run_key
from .search import optimise

log = logging.getLogger(__name__)

__all__ = ["JointFit", "Repeatability", "joint_ml", "repeatability", "REPEATABILITY_PARAM"]

#: the parameter whose spread over the runs is the turn-on-to-turn-on repeatability
REPEATABILITY_PARAM = "bias.b"
#: confidence level of the repeatability's interval
LEVEL = 0.95


@dataclass(frozen=True)
class Repeatability:
    """The spread of one parameter over the runs beyond each run's estimation error.

    ``spread`` τ̂ (REML) with its ``interval`` at ``level`` (Q-profile); ``mean`` μ̂ and
    its ``mean_std``; the per-run ``values`` and their ``stds``; ``q`` = Q(0) and ``p``
    its χ²_{R−1} tail (small: the runs differ by more than their errors)."""

    parameter: str
    unit: str
    values: tuple[float, ...]
    stds: tuple[float, ...]
    mean: float
    mean_std: float
    spread: float
    interval: tuple[float, float]
    level: float
    q: float
    p: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "parameter": self.parameter, "runs": len(self.values),
            "spread": self.spread, "interval": list(self.interval), "level": self.level,
            "mean": self.mean, "mean_std": self.mean_std,
            "per_run": [{"value": v, "std": s} for v, s in zip(self.values, self.stds,
                                                               strict=True)],
            "q": self.q, "p_equal": self.p,
            "method": "REML spread; Q-profile interval (Viechtbauer 2007)",
        }


def repeatability(values: Sequence[float], cov: np.ndarray, *, parameter: str = "bias.b",
                  unit: str = "y", level: float = LEVEL) -> Repeatability:
    """Random-effects spread τ of ``values`` whose estimation errors have covariance
    ``cov`` (see the module's equations): REML τ̂ and the Q-profile interval at ``level``."""
    from scipy.optimize import brentq, minimize_scalar
    from scipy.stats import chi2

    b = np.asarray(values, dtype=float)
    C = np.asarray(cov, dtype=float).reshape(b.size, b.size)
    R = b.size
    if R < 2:
        raise DataError(f"the repeatability of {parameter} needs at least 2 runs, got {R}")
    one = np.ones(R)

    def gls(t2: float) -> tuple[float, float, float, float]:
        """μ̂, its variance, Q and the restricted log-likelihood at τ² = t2."""
        V = C + t2 * np.eye(R)
        Vi = np.linalg.inv(V)
        w = float(one @ Vi @ one)
        mu = float(one @ Vi @ b) / w
        d = b - mu
        q = float(d @ Vi @ d)
        _, logdet = np.linalg.slogdet(V)
        return mu, 1.0 / w, q, -0.5 * (logdet + np.log(w) + q)

    scale = float(np.std(b, ddof=1)) + float(np.sqrt(max(float(np.mean(np.diag(C))), 0.0))) + 1e-300
    top = (10.0 * scale) ** 2
    res = minimize_scalar(lambda s: -gls(s * s)[3], bounds=(0.0, np.sqrt(top)),
                          method="bounded", options={"xatol": 1e-6 * scale})
    tau = float(res.x)
    if -gls(0.0)[3] <= res.fun:
        tau = 0.0
    mu, mu_var, _, _ = gls(tau * tau)
    q0 = gls(0.0)[2]
    alpha = 1.0 - level

    def bound(quantile: float) -> float:
        target = float(chi2.ppf(quantile, R - 1))
        if q0 <= target:
            return 0.0
        hi = top
        while gls(hi)[2] > target:
            hi *= 4.0
        return float(np.sqrt(brentq(lambda t2: gls(t2)[2] - target, 0.0, hi,
                                    xtol=1e-12 * scale * scale)))

    lo_tau, hi_tau = bound(1.0 - alpha / 2), bound(alpha / 2)
    return Repeatability(
        parameter=parameter, unit=unit, values=tuple(float(v) for v in b),
        stds=tuple(float(np.sqrt(max(C[i, i], 0.0))) for i in range(R)),
        mean=mu, mean_std=float(np.sqrt(mu_var)), spread=tau, interval=(lo_tau, hi_tau),
        level=level, q=q0, p=float(chi2.sf(q0, R - 1)),
    )


@dataclass(frozen=True)
class JointFit:
    """A joint ML fit of several runs of one gyro.

    ``parameters`` by joint name (shared ones by their model name, each run's own as
    :func:`run_key`); ``runs`` each run's :class:`FitResult` at the joint estimate (its
    shared and own parameters under the model's names, its residuals and ln L);
    ``repeatability`` the spread of the turn-on bias (None: one run, or no free bias)."""

    model: Model
    parameters: Mapping[str, Estimate]
    loglik: float
    runs: tuple[FitResult, ...]
    covariance: np.ndarray | None
    cov_names: tuple[str, ...]
    warnings: tuple[str, ...]
    info: Mapping[str, Any] = field(default_factory=dict)
    repeatability: Repeatability | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "parameters", MappingProxyType(dict(self.parameters)))
        object.__setattr__(self, "info", MappingProxyType(dict(self.info)))

    @property
    def method(self) -> str:
        return "ml"

    @property
    def n_observed(self) -> int:
        return sum(r.n_observed for r in self.runs)

    @property
    def values(self) -> dict[str, float]:
        return {k: e.value for k, e in self.parameters.items()}

    @property
    def residual_rms(self) -> float:
        """RMS of every run's innovations together."""
        r = np.concatenate([np.asarray(x.residuals) for x in self.runs])
        r = r[np.isfinite(r)]
        return float(np.sqrt(np.mean(r * r))) if r.size else 0.0

    @property
    def shared(self) -> dict[str, Estimate]:
        """The gyro's parameters (those every run shares)."""
        return {n: e for n, e in self.parameters.items() if "@" not in n}

    def value(self, name: str) -> float:
        return self.parameters[name].value

    def std(self, name: str) -> float:
        return self.parameters[name].std

    def to_dict(self) -> dict[str, Any]:
        """The single-run JSON keys (parameters: the shared ones), plus ``runs`` (each
        run's own block) and ``repeatability``."""
        d: dict[str, Any] = {
            "method": "ml", "model": list(self.model.names),
            "parameters": {k: e.to_dict() for k, e in self.shared.items()},
            "loglik": float(self.loglik),
            "residual": {"rms": self.residual_rms},
            "n_samples": sum(r.n_samples for r in self.runs),
            "n_observed": self.n_observed,
            "dt": self.runs[0].dt,
            "source": "; ".join(r.source for r in self.runs),
            "warnings": list(self.warnings),
            "info": {k: v for k, v in self.info.items() if jsonable(v)},
            "runs": [r.to_dict() for r in self.runs],
            "repeatability": (self.repeatability.to_dict() if self.repeatability is not None
                              else None),
        }
        return d


def residual_check(e: np.ndarray, f: np.ndarray) -> dict[str, Any]:
    """One run's residual check: Ljung–Box on its standardised innovations z = e/√f (lags
    as :func:`~gyrostand.core.diagnose.diagnostics.diagnose_fit`), and their mean square (NIS, 1
    when the variances are right)."""
    from ..chisq import ljung_box

    z = np.asarray(e, dtype=float) / np.sqrt(np.asarray(f, dtype=float))
    n = int(np.count_nonzero(np.isfinite(z)))
    lags = int(min(max(10, np.log(max(n, 2))), max(1, n // 5)))
    q, pval = ljung_box(z, lags)
    return {"ljung_box_q": float(q), "ljung_box_p": float(pval), "lags": lags,
            "nis_mean": float(np.nanmean(z * z)), "n": n}


def joint_ml(runs: Sequence[Samples], model: Model, **options: Any) -> JointFit:
    """Joint exact ML of ``model`` over ``runs`` (options as :func:`joint_ml_fit`); BLAS on
    one thread as for :func:`~gyrostand.core.ml.fit.ml`."""
    with one_blas_thread():
        return joint_ml_fit(runs, model, **options)


def joint_ml_fit(runs: Sequence[Samples], model: Model, *, sigma: float | None = None,
                 fixed: Mapping[str, float] | None = None, n_local: int | None = None,
                 start: Mapping[str, float] | None = None, std_errors: bool = True,
                 hessian_passes: int = 2, bias_spread: float | None = None,
                 shared: Sequence[str] = (), absolute_time: bool = False) -> JointFit:
    """Joint exact ML over several runs: options as :func:`~gyrostand.core.ml.fit.ml_fit`
    (``start`` by joint name: a per-run parameter as :func:`run_key`, or by its model name
    for every run).

    The power-cycle protocol's options (the defaults leave the fit as above, bit for bit):

    * ``bias_spread`` σ_b: the turn-on bias is a random effect, b_r = μ + u_r with
      u_r ~ N(0, σ_b²) independent of everything else, around one shared mean μ
      (``bias.b``), σ_b known (the repeatability of earlier runs). Run r's likelihood
      integrates u_r out exactly: its covariance is V_r = Σ_r + σ_b² 11' (Σ_r the
      Kalman model's), by Woodbury on the filtered Gram matrix,
      ln L_r = −½[n_r ln 2π + ln det Σ_r + ln(1 + σ_b² 1'Σ_r⁻¹1) + e'V_r⁻¹e].
      σ_b → ∞ gives the free per-run bias (up to −½ ln(σ_b² 1'Σ_r⁻¹1) per run), σ_b = 0
      one bias for every run. Each run's reported bias is μ + û_r (the BLUP).
    * ``absolute_time``: the runs' times are on one clock (each record's t[0] its
      switch-on); the trend c·(t − t₀) counts from the first switch-on, so it keeps its
      rate across the off periods (ageing), while a warm-up still restarts at each
      switch-on.
    * ``shared``: per-run terms shared by the switch-ons instead (``["warmup"]``: the
      same A and τ at every switch-on of one protocol)."""
    if not runs:
        raise DataError("a joint fit needs at least one run")
    fixed = dict(fixed or {})
    if sigma is not None:
        fixed["markov.sigma"] = float(sigma)
    runs = [prepare(s, "ml") for s in runs]
    prob = JointProblem(model, runs, fixed, bias_spread=bias_spread, shared=shared,
                         absolute_time=absolute_time)
    n_free = len(prob.znames) + len(prob.lin_free) + (1 if prob.concentrate else 0)
    for s in runs:
        require_samples(s, s.n_observed, len(prob.per_run) + 2, "ml")
    if prob.n_obs < n_free + 2:
        raise DataError(f"the runs have {prob.n_obs} observed samples together; a joint "
                        f"fit of {n_free} parameters needs at least {n_free + 2}")
    warnings = [f"run {r + 1}: {w}" if len(runs) > 1 else w
                for r, s in enumerate(runs) for w in s.warnings]
    # the start grid of the longest run, each per-run parameter alike in every run
    ref = max(range(len(runs)), key=lambda r: prob.parts[r].duration)
    grid = start_grid(prob.parts[ref], {"markov.beta": lsq_beta(runs[ref], model)})
    starts = [prob.joint_z(zb) for zb in grid]
    if start:
        spread = dict(start)
        for n in prob.per_run:
            for r in range(len(runs)):
                if n in start and run_key(n, r) not in spread:
                    spread[run_key(n, r)] = start[n]
        starts += starts_from(prob, starts, spread)
    z, info, more = optimise(prob, starts, n_local)
    warnings += more
    at_bound = list(info.get("at_bound", []))
    p, gls_info, _ = prob.natural(z)
    if prob.bias_col is None:
        lls = [model.loglik(prob.run_params(p, r), s) for r, s in enumerate(runs)]
    else:
        lls = prob.random_loglik(p)
        own_bias = prob.random_effects(p)
    if not all(np.isfinite(lls)):
        raise IdentificationError("ml found no finite joint likelihood of "
                                  + "; ".join(s.source for s in runs))
    free: list[str] = []
    for n in model.param_names:
        if n in fixed:
            continue
        free += [run_key(n, r) for r in range(len(runs))] if n in prob.per_run else [n]
    cov = None
    std = dict.fromkeys(free, 0.0)
    if std_errors and free:
        cov, cw = observed_covariance(model, runs[0], p, free, gls_info, prob, at_bound,
                                      hessian_passes)
        warnings += cw
        std = {n: float(np.sqrt(cov[i, i])) for i, n in enumerate(free)}
    params: dict[str, Estimate] = {}
    for n in model.param_names:
        if n in fixed:
            params[n] = Estimate(float(fixed[n]), 0.0, model.unit(n), fixed=True)
            continue
        for k in ([run_key(n, r) for r in range(len(runs))] if n in prob.per_run else [n]):
            params[k] = Estimate(float(p[k]), std[k], model.unit(n))
    info.update({"evaluations": prob.nevals, "concentrated_scale": prob.concentrate,
                 "start_points": len(starts), "runs": len(runs)})
    if prob.bias_col is not None:
        info.update({"bias_spread": prob.spread, "absolute_time": absolute_time,
                     "shared": list(shared),
                     "switch_on_offsets_s": [float(x) for x in prob.offsets]})
    results = []
    for r, s in enumerate(runs):
        own = {n: params[run_key(n, r)] if run_key(n, r) in params else params[n]
               for n in model.param_names}
        names_r = [base_name(k) for k in free
                   if "@" not in k or k.endswith(f"@{r + 1}")]
        rows = [i for i, k in enumerate(free) if "@" not in k or k.endswith(f"@{r + 1}")]
        cov_r = cov[np.ix_(rows, rows)] if cov is not None else None
        q = prob.run_params(p, r)
        if prob.bias_col is not None:  # this run's own turn-on bias (trend at its origin)
            q[BIAS] = own_bias[r]
            own[BIAS] = Estimate(own_bias[r], 0.0, model.unit(BIAS))
        e, f = model.innovations(q, s)
        check = residual_check(e, f)
        if check["ljung_box_p"] < 0.01:
            warnings.append(f"run {r + 1} ({s.source}): innovations not white (Ljung–Box p = "
                            f"{check['ljung_box_p']:.2g} over {check['lags']} lags)")
        results.append(FitResult(
            method="ml", model=model, parameters=own, loglik=float(lls[r]), residuals=e,
            residual_var=f, warnings=tuple(dict.fromkeys(s.warnings)), source=s.source,
            n_samples=len(s), n_observed=s.n_observed, dt=s.dt, covariance=cov_r,
            cov_names=tuple(names_r) if cov_r is not None else (),
            info={"run": r + 1, "of_runs": len(runs), "joint": True,
                  "residual_check": check},
        ))
    rep = None
    key = REPEATABILITY_PARAM
    if len(runs) >= 2 and key in prob.per_run and key not in fixed and cov is not None:
        keys = [run_key(key, r) for r in range(len(runs))]
        idx = [free.index(k) for k in keys]
        try:
            rep = repeatability([p[k] for k in keys], cov[np.ix_(idx, idx)], parameter=key,
                                unit=model.unit(key))
        except (np.linalg.LinAlgError, ValueError) as exc:
            warnings.append(f"repeatability of {key} not computed: {exc}")
    log.info("joint ml of %d runs: ln L = %.3f", len(runs), float(sum(lls)))
    return JointFit(model=model, parameters=params, loglik=float(sum(lls)),
                    runs=tuple(results), covariance=cov,
                    cov_names=tuple(free) if cov is not None else (),
                    warnings=tuple(dict.fromkeys(warnings)), info=info, repeatability=rep)
