"""Several runs of one gyro, identified at once: the joint exact likelihood.

Runs r = 1..R of the same gyro (switched on R times, days apart) share its physics — the
rates β, the noise levels σ, the temperature coefficients γ and every effect's coefficient —
while each switch-on has its own turn-on bias, its own initial state and, where the model
has one, its own warm-up (the terms with :attr:`~gyrostand.core.term_base.Term.per_run`).
The runs are independent given the parameters, so the log-likelihood is the sum of each
run's exact Kalman likelihood (:mod:`~gyrostand.core.ml`):

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
from threadpoolctl import threadpool_limits

from ..errors import DataError, IdentificationError
from .data import Samples
from .ml import _lsq_beta, _optimise, _Problem, _start_grid, _starts_from, concentrated_loglik
from .ml_cov import observed_covariance
from .model import LOG_2PI, Model
from .results import Estimate, FitResult, _jsonable
from .validate import prepare, require_samples

log = logging.getLogger(__name__)

__all__ = ["JointFit", "JointDiagnosis", "Repeatability", "joint_ml", "joint_diagnose",
           "repeatability", "run_key", "per_run_names", "shared_params",
           "REPEATABILITY_PARAM"]

#: the parameter whose spread over the runs is the turn-on-to-turn-on repeatability
REPEATABILITY_PARAM = "bias.b"
#: confidence level of the repeatability's interval
LEVEL = 0.95


def run_key(name: str, run: int) -> str:
    """The joint name of run ``run``'s (0-based) own copy of parameter ``name``:
    ``bias.b@1`` for the first run."""
    return f"{name}@{run + 1}"


def base_name(key: str) -> str:
    """The model's parameter name of a joint name (``bias.b@2`` → ``bias.b``)."""
    return key.split("@", 1)[0]


#: the turn-on bias and the trend's rate (the power-cycle protocol's parameters)
BIAS, TREND = "bias.b", "trend.c"


def shared_params(model: Model, terms: Sequence[str]) -> tuple[str, ...]:
    """The parameters of the per-run ``terms`` (e.g. ``warmup``) that a protocol shares
    over its switch-ons instead (the same gyro's self-heating at every switch-on)."""
    unknown = [t for t in terms if t not in model.names]
    if unknown:
        raise DataError(f"shared terms {', '.join(unknown)} are not in the model {model}")
    return tuple(n for n in model.param_names if n.split(".", 1)[0] in terms)


def per_run_names(model: Model) -> tuple[str, ...]:
    """The model's parameters each run has its own of (its per-run terms' parameters)."""
    return tuple(n for n in model.param_names if getattr(model.term_of(n), "per_run", False))


class _JointProblem:
    """The concentrated joint likelihood of one model on several runs: the interface of
    :class:`~gyrostand.core.ml._Problem` (what the search and the covariance use), with
    every per-run parameter once per run under :func:`run_key`."""

    def __init__(self, model: Model, runs: Sequence[Samples], fixed: Mapping[str, float],
                 *, bias_spread: float | None = None, shared: Sequence[str] = (),
                 absolute_time: bool = False):
        self.model = model
        self.parts = [_Problem(model, s, fixed) for s in runs]
        first = self.parts[0]
        self.fixed = first.fixed
        self.n_runs = len(self.parts)
        self.per_run = set(per_run_names(model)) - set(shared_params(model, shared))
        #: the power-cycle protocol's options (:func:`joint_ml_fit`): the turn-on bias a
        #: random effect of spread σ_b around a shared mean, the trend in absolute time
        self.spread = None if bias_spread is None else float(bias_spread)
        self.offsets = np.zeros(self.n_runs)
        self.bias_col = self.trend_col = None
        if self.spread is not None or absolute_time:
            if BIAS not in first.lin_free:
                raise DataError("a random-effect turn-on bias and absolute time need the "
                                "model's free bias term")
            self.bias_col = 1 + first.linear.index(BIAS)
        if self.spread is not None:
            if not self.spread >= 0:
                raise DataError(f"the turn-on bias spread must be >= 0, got {self.spread}")
            self.per_run.discard(BIAS)
        if absolute_time and TREND in first.lin_free:
            self.trend_col = 1 + first.linear.index(TREND)
            t0 = min(float(s.t[0]) for s in runs)
            self.offsets = np.array([float(s.t[0]) - t0 for s in runs])
        # noise scale and reference are decided by the model and the fixed values alone
        self.concentrate, self.ref, self.ref_scale = first.concentrate, first.ref, first.ref_scale
        self.stds = list(first.stds)
        # searched parameters, in the single run's order; a per-run one once per run
        self.rates: list[str] = []
        self.zmap: list[tuple[str, int | None]] = []
        for n in first.rates:
            owners: list[int | None] = (list(range(self.n_runs)) if n in self.per_run
                                        else [None])
            for r in owners:
                self.rates.append(n if r is None else run_key(n, r))
                self.zmap.append((n, r))
        self.zmap += [(n, None) for n in self.stds]
        self.znames = self.rates + self.stds
        self.bounds = []
        for n, r in self.zmap:
            i = first.znames.index(n)
            if r is not None:
                self.bounds.append(self.parts[r].bounds[i])
            else:  # shared: the widest of the runs' plausible ranges
                self.bounds.append((min(pt.bounds[i][0] for pt in self.parts),
                                    max(pt.bounds[i][1] for pt in self.parts)))
        # concentrated linear parameters: a per-run one once per run, in the model's order
        self.linear = first.linear
        self.lin_free: list[str] = []
        for n in first.lin_free:
            if n in self.per_run:
                self.lin_free += [run_key(n, r) for r in range(self.n_runs)]
            else:
                self.lin_free.append(n)
        index = {n: i for i, n in enumerate(self.lin_free)}
        #: for each run, the joint index of each of its free linear columns
        self.lin_index = [np.array([index[run_key(n, r) if n in self.per_run else n]
                                    for n in first.lin_free], dtype=int)
                          for r in range(self.n_runs)]
        self.n_obs = sum(pt.n_obs for pt in self.parts)
        self.duration = max(pt.duration for pt in self.parts)
        self.nevals = 0

    def kind(self, name: str) -> str:
        return self.model.kind(base_name(name))

    def part_z(self, z: np.ndarray, r: int) -> np.ndarray:
        """Run ``r``'s searched point (single-run order) from the joint one."""
        out = np.empty(len(self.parts[r].znames))
        k = 0
        for j, (_, owner) in enumerate(self.zmap):
            if owner is None or owner == r:
                out[k] = z[j]
                k += 1
        return out

    def joint_z(self, zb: np.ndarray) -> np.ndarray:
        """A single-run searched point spread over the runs (each run's copy alike)."""
        names = self.parts[0].znames
        z = np.array([zb[names.index(n)] for n, _ in self.zmap])
        lo = np.array([b[0] for b in self.bounds]) + 1e-9
        hi = np.array([b[1] for b in self.bounds]) - 1e-9
        return np.clip(z, lo, hi) if z.size else z

    def run_params(self, p: Mapping[str, float], r: int) -> dict[str, float]:
        """Run ``r``'s natural parameters (model names) from the joint ones."""
        out = {n: v for n, v in p.items() if "@" not in n}
        for n in self.per_run:
            k = run_key(n, r)
            if k in p:
                out[n] = p[k]
        return out

    def profile(self, z: np.ndarray):
        """Concentrated joint ln L at ``z``; also the runs' parameters, θ̂, s², GLS info."""
        self.nevals += 1
        L = len(self.lin_free)
        A = np.zeros((L, L))
        b = np.zeros(L)
        S = 0.0
        slogf = 0.0
        n = 0
        ps = []
        grams = []
        for r, part in enumerate(self.parts):
            p = part.unpack(self.part_z(z, r))
            G, slogf_r, n_r = part.gram(p)
            if not np.isfinite(slogf_r):
                return -np.inf, None
            ps.append(p)
            if self.spread is not None or self.trend_col is not None:
                grams.append(self.shifted(G, r))
                slogf += slogf_r
                n += n_r
                continue
            S += self._accumulate(G, r, A, b)
            slogf += slogf_r
            n += n_r
        if grams:
            return self._profile_random(grams, slogf, n, ps)
        if L:
            theta, *_ = np.linalg.lstsq(A, b, rcond=1e-13)
            S -= float(b @ theta)
        else:
            theta = np.zeros(0)
        ll, s2 = concentrated_loglik(S, n, slogf, self.concentrate)
        return ll, (ps, theta, s2, A)

    def _accumulate(self, G: np.ndarray, r: int, A: np.ndarray, b: np.ndarray) -> float:
        """Add run ``r``'s filtered Gram matrix ``G`` to the joint GLS: its free linear
        columns into ``A`` and ``b`` (in place), its residual sum of squares with the
        fixed coefficients' columns taken off returned."""
        part = self.parts[r]
        c0 = np.zeros(G.shape[0])
        c0[0] = 1.0
        for j, name in enumerate(part.linear):
            if name in part.fixed:
                c0[1 + j] = -part.fixed[name]
        free = part.free_cols
        if free:
            idx = self.lin_index[r]
            A[np.ix_(idx, idx)] += G[np.ix_(free, free)]
            b[idx] += G[free] @ c0
        return float(c0 @ G @ c0)

    # -- the power-cycle protocol: absolute time, random-effect turn-on bias ----------

    def shifted(self, G: np.ndarray, r: int) -> np.ndarray:
        """Run ``r``'s Gram matrix with the trend's column counted from the first
        switch-on: x_c + δ_r·1 (the filter is linear: G → M'GM)."""
        if self.trend_col is None or self.offsets[r] == 0.0:
            return G
        M = np.eye(G.shape[0])
        M[self.bias_col, self.trend_col] = self.offsets[r]
        return M.T @ G @ M

    def _gls(self, grams: Sequence[np.ndarray], rho: float
             ) -> tuple[float, float, np.ndarray, np.ndarray]:
        """At ρ = σ_b²/s²: (S, Σ_r ln(1 + ρ h_r), θ̂, A) of the GLS with each run's
        V_r ∝ Σ̃_r + ρ 11' (Woodbury on its Gram matrix; ρ = inf: a free bias per run)."""
        L = len(self.lin_free)
        A = np.zeros((L, L))
        bv = np.zeros(L)
        S = 0.0
        logdet = 0.0
        c = self.bias_col
        assert c is not None
        for r, G in enumerate(grams):
            h = float(G[c, c])
            if self.spread is not None and h > 0:
                if np.isinf(rho):
                    G = G - np.outer(G[:, c], G[c]) / h
                else:
                    G = G - rho * np.outer(G[:, c], G[c]) / (1.0 + rho * h)
                    logdet += float(np.log1p(rho * h))
            S += self._accumulate(G, r, A, bv)
        if L:  # equilibrated: a trend counted from the first switch-on has a large column
            d = np.diag(A)
            d = 1.0 / np.sqrt(np.where(d > 0, d, 1.0))
            x, *_ = np.linalg.lstsq(A * np.outer(d, d), bv * d, rcond=1e-13)
            theta = x * d
            S -= float(bv @ theta)
        else:
            theta = np.zeros(0)
        return max(S, 1e-300), logdet, theta, A

    def _profile_random(self, grams, slogf: float, n: int, ps):
        """The concentrated joint ln L with the random-effect bias: V_r = s²(Σ̃_r + ρ11'),
        ρ = σ_b²/s², σ_b known; with the common scale concentrated, ln L is maximized over
        s² (one dimension: ρ moves with s²)."""
        from scipy.optimize import minimize_scalar

        sb2 = (self.spread or 0.0) ** 2

        def ll_at(s2: float) -> tuple[float, tuple]:
            S, logdet, theta, A = self._gls(grams, sb2 / s2)
            ll = -0.5 * (n * LOG_2PI + n * np.log(s2) + slogf + logdet + S / s2)
            return float(ll), (ps, theta, s2, A)

        if not self.concentrate:
            return ll_at(1.0)
        hi = self._gls(grams, 0.0)[0] / n
        lo = self._gls(grams, np.inf)[0] / n if sb2 > 0 else hi
        if not hi > lo * (1 + 1e-12):
            return ll_at(hi)
        res = minimize_scalar(lambda x: -ll_at(float(np.exp(x)))[0],
                              bounds=(np.log(lo) - 0.01, np.log(hi) + 0.01), method="bounded",
                              options={"xatol": 1e-10})
        return ll_at(float(np.exp(res.x)))

    def _run_gram(self, q: Mapping[str, float], r: int
                  ) -> tuple[np.ndarray, np.ndarray, float, float, int]:
        """Run ``r``'s filtered Gram matrix at its natural parameters ``q`` (the trend's
        column on the first switch-on's clock), the coefficient vector c = (1, −q) whose
        quadratic form c'Gc is its residual sum of squares, h = 1'Σ_r⁻¹1 (the bias
        column's own entry), ln det of the filter and the run's sample count."""
        part = self.parts[r]
        G, slogf, n = part.gram(q)
        G = self.shifted(G, r)
        c = self.bias_col
        assert c is not None
        cvec = np.zeros(G.shape[0])
        cvec[0] = 1.0
        for j, name in enumerate(part.linear):
            cvec[1 + j] = -q[name]
        return G, cvec, float(G[c, c]), slogf, n

    def random_effects(self, p: Mapping[str, float]) -> list[float]:
        """Each run's turn-on bias at natural joint parameters ``p``: μ + δ_r c + û_r,
        û_r = E[u_r | run r] (the BLUP, 0 without a random effect), for the run's own
        parameters (its residuals, its ln L at the joint estimate)."""
        out = []
        for r in range(self.n_runs):
            q = self.run_params(p, r)
            base = q[BIAS] + (self.offsets[r] * q[TREND] if self.trend_col is not None
                              else 0.0)
            u = 0.0
            if self.spread is not None and self.spread > 0:
                G, cvec, h, _, _ = self._run_gram(q, r)
                sb2 = self.spread ** 2
                u = sb2 * float(G[self.bias_col] @ cvec) / (1.0 + sb2 * h)
            out.append(base + u)
        return out

    def random_loglik(self, p: Mapping[str, float]) -> list[float]:
        """Each run's exact ln L at natural joint parameters ``p`` (nothing concentrated),
        its turn-on bias integrated out: −½[n ln 2π + ln det Σ_r + ln(1 + σ_b² h_r) + r'V⁻¹r]."""
        out = []
        sb2 = (self.spread or 0.0) ** 2
        for r in range(self.n_runs):
            G, cvec, h, slogf, n = self._run_gram(self.run_params(p, r), r)
            if not np.isfinite(slogf):
                out.append(-np.inf)
                continue
            quad = float(cvec @ G @ cvec)
            logdet = 0.0
            if sb2 > 0:
                gc = float(G[self.bias_col] @ cvec)
                quad -= sb2 * gc * gc / (1.0 + sb2 * h)
                logdet = float(np.log1p(sb2 * h))
            out.append(float(-0.5 * (n * LOG_2PI + slogf + logdet + quad)))
        return out

    def full_loglik(self, p: Mapping[str, float]) -> float:
        """Exact joint ln L at natural joint parameters ``p`` (nothing concentrated)."""
        if self.bias_col is not None:
            return float(sum(self.random_loglik(p)))
        total = 0.0
        for r, part in enumerate(self.parts):
            total += part.full_loglik(self.run_params(p, r))
        return total

    def natural(self, z: np.ndarray) -> tuple[dict[str, float], np.ndarray, float]:
        """Joint natural parameters at ``z`` (scale and θ̂ filled in), GLS info, ln L."""
        ll, extra = self.profile(z)
        if extra is None:
            raise IdentificationError("joint likelihood is not finite at the optimum")
        ps, theta, s2, A = extra
        s = float(np.sqrt(s2))
        p: dict[str, float] = {}
        for r, pr in enumerate(ps):
            for name, v in pr.items():
                if name in self.per_run and name not in self.fixed:
                    p[run_key(name, r)] = v
                else:
                    p[name] = v
        if self.concentrate:
            for n in self.model.names_of_kind("std"):
                p[n] = p[n] * s
        for n, v in zip(self.lin_free, theta, strict=True):
            p[n] = float(v)
        return p, A / s2, ll


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
            "info": {k: v for k, v in self.info.items() if _jsonable(v)},
            "runs": [r.to_dict() for r in self.runs],
            "repeatability": (self.repeatability.to_dict() if self.repeatability is not None
                              else None),
        }
        return d


def residual_check(e: np.ndarray, f: np.ndarray) -> dict[str, Any]:
    """One run's residual check: Ljung–Box on its standardised innovations z = e/√f (lags
    as :func:`~gyrostand.core.diagnostics.diagnose_fit`), and their mean square (NIS, 1
    when the variances are right)."""
    from .diagnostics import ljung_box

    z = np.asarray(e, dtype=float) / np.sqrt(np.asarray(f, dtype=float))
    n = int(np.count_nonzero(np.isfinite(z)))
    lags = int(min(max(10, np.log(max(n, 2))), max(1, n // 5)))
    q, pval = ljung_box(z, lags)
    return {"ljung_box_q": float(q), "ljung_box_p": float(pval), "lags": lags,
            "nis_mean": float(np.nanmean(z * z)), "n": n}


def joint_ml(runs: Sequence[Samples], model: Model, **options: Any) -> JointFit:
    """Joint exact ML of ``model`` over ``runs`` (options as :func:`joint_ml_fit`); BLAS on
    one thread as for :func:`~gyrostand.core.ml.ml`."""
    with threadpool_limits(limits=1, user_api="blas"):
        return joint_ml_fit(runs, model, **options)


def joint_ml_fit(runs: Sequence[Samples], model: Model, *, sigma: float | None = None,
                 fixed: Mapping[str, float] | None = None, n_local: int | None = None,
                 start: Mapping[str, float] | None = None, std_errors: bool = True,
                 hessian_passes: int = 2, bias_spread: float | None = None,
                 shared: Sequence[str] = (), absolute_time: bool = False) -> JointFit:
    """Joint exact ML over several runs: options as :func:`~gyrostand.core.ml.ml_fit`
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
    prob = _JointProblem(model, runs, fixed, bias_spread=bias_spread, shared=shared,
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
    grid = _start_grid(prob.parts[ref], {"markov.beta": _lsq_beta(runs[ref], model)})
    starts = [prob.joint_z(zb) for zb in grid]
    if start:
        spread = dict(start)
        for n in prob.per_run:
            for r in range(len(runs)):
                if n in start and run_key(n, r) not in spread:
                    spread[run_key(n, r)] = start[n]
        starts += _starts_from(prob, starts, spread)
    z, info, more = _optimise(prob, starts, n_local)
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



@dataclass(frozen=True)
class JointDiagnosis:
    """``diagnose`` of several runs: the joint fit, each run's residual check, and the
    missing effects ranked on the joint model (each candidate refitted jointly: its LR is
    the joint LR, a per-run effect's parameters counted once per run)."""

    fit: JointFit
    candidates: tuple[Any, ...]  # candidates.Candidate, best first
    alpha: float
    adequate: bool
    reasons: tuple[str, ...]
    unit: str = "y"

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": list(self.fit.model.names), "adequate": self.adequate,
            "reasons": list(self.reasons), "alpha": self.alpha,
            "fit": self.fit.to_dict(),
            "repeatability": (self.fit.repeatability.to_dict()
                              if self.fit.repeatability is not None else None),
            "runs": [{"source": r.source, **dict(r.info.get("residual_check", {}))}
                     for r in self.fit.runs],
            "candidates": [c.to_dict(self.unit) for c in self.candidates],
        }


#: each run's whiteness test at this level (Bonferroni over the runs)
WHITE_ALPHA = 0.01


def joint_diagnose(runs: Sequence[Samples], model: Model, *, alpha: float = 0.05,
                   terms: list[str] | None = None, unit: str = "y") -> JointDiagnosis:
    """Fit ``model`` to every run jointly, check each run's innovations, rank the missing
    effects by their joint likelihood ratio (:func:`~.candidates.rank_candidates` on the
    runs together)."""
    from .candidates import rank_candidates

    fit = joint_ml(runs, model)
    cands = rank_candidates(tuple(runs), model, fit, terms)  # type: ignore[arg-type]
    alpha_each = alpha / max(len(cands), 1)
    reasons = []
    for r in fit.runs:
        chk = r.info.get("residual_check", {})
        if chk and chk["ljung_box_p"] < WHITE_ALPHA / len(runs):
            reasons.append(f"run {r.info['run']} ({r.source}): innovations are not white "
                           f"(Ljung–Box p = {chk['ljung_box_p']:.2g} over {chk['lags']} lags)")
    sig = [c for c in cands if c.ranked and c.p_value < alpha_each]
    if sig:
        reasons.append(f"{', '.join(c.term for c in sig)} significant at {alpha:g} on the "
                       f"{len(runs)} runs together (Bonferroni over {len(cands)} candidates: "
                       f"p < {alpha_each:.2g})")
    return JointDiagnosis(fit=fit, candidates=tuple(cands), alpha=alpha,
                          adequate=not reasons, reasons=tuple(reasons), unit=unit)
