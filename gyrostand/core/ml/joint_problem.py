"""The joint likelihood's problem: several runs of one gyro, their shared and per-run
parameters by name (:func:`run_key`, :func:`base_name`) and the filtered Gram matrices that
concentrate the linear parameters out by one GLS over the runs (:class:`JointProblem`).
The fit built on it is :mod:`~gyrostand.core.ml.joint`; the model is described there."""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence

import numpy as np

from ...errors import DataError, IdentificationError
from ..data import Samples
from ..model import LOG_2PI, Model
from .fit import Problem
from .gls import concentrated_loglik, fill_natural

log = logging.getLogger(__name__)

__all__ = ["BIAS", "TREND", "JointProblem", "run_key", "base_name", "shared_params", "per_run_names"]


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


class JointProblem:
    """The concentrated joint likelihood of one model on several runs: the interface of
    :class:`~gyrostand.core.ml.fit.Problem` (what the search and the covariance use), with
    every per-run parameter once per run under :func:`run_key`."""

    def __init__(self, model: Model, runs: Sequence[Samples], fixed: Mapping[str, float],
                 *, bias_spread: float | None = None, shared: Sequence[str] = (),
                 absolute_time: bool = False):
        self.model = model
        self.parts = [Problem(model, s, fixed) for s in runs]
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

    @property
    def analytic_score(self) -> bool:
        """Whether :meth:`score` applies: not with the power-cycle protocol's random-effect
        bias or absolute time (their scale is searched; central differences there)."""
        return self.spread is None and self.trend_col is None

    def score(self, z: np.ndarray, theta: np.ndarray, s2: float) -> np.ndarray:
        """∂ ln L / ∂z of the concentrated joint ln L: each run's score at its part of
        ``z`` and of the joint GLS ``theta`` (the common ``s2``), a shared parameter's
        summed over the runs (:meth:`.fit.Problem.score`)."""
        g = np.zeros(z.size)
        for r, part in enumerate(self.parts):
            gr = part.score(self.part_z(z, r), theta[self.lin_index[r]], s2)
            k = 0
            for j, (_, owner) in enumerate(self.zmap):
                if owner is None or owner == r:
                    g[j] += gr[k]
                    k += 1
        return g

    def _accumulate(self, G: np.ndarray, r: int, A: np.ndarray, b: np.ndarray) -> float:
        """Add run ``r``'s filtered Gram matrix ``G`` to the joint GLS: its free linear
        columns into ``A`` and ``b`` (in place), its residual sum of squares with the
        fixed coefficients' columns taken off returned."""
        part = self.parts[r]
        c0 = part.c0
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
        p: dict[str, float] = {}
        for r, pr in enumerate(ps):
            for name, v in pr.items():
                if name in self.per_run and name not in self.fixed:
                    p[run_key(name, r)] = v
                else:
                    p[name] = v
        return (fill_natural(self.model, self.concentrate, self.lin_free, p, theta, s2),
                A / s2, ll)
