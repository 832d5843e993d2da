"""The search of ML: L-BFGS-B over the log rates and log noise ratios of a problem (a
:class:`~.fit.Problem`, or the joint problem of several runs), from the best of its start
points, with the analytic score of the concentrated likelihood (:mod:`.score`: one
tangent-linear filter pass) where the problem has one, else central differences."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from scipy.optimize import minimize

#: step of the central-difference gradient in the log parameters (a problem without the
#: analytic score: the power-cycle protocol's joint problem)
GRAD_STEP = 1e-5
#: L-BFGS-B's tolerance on the projected gradient of −ln L / n (per log-parameter): at the
#: curvature of a typical fit this leaves the optimum within ~1e-5 of its std
GTOL = 1e-8
#: ... and on the relative reduction of −ln L / n: 1e-10 leaves ln L within ~1e-5 of its
#: maximum on a 6-hour run (a likelihood-ratio test needs ~1e-2), and stops the crawl
#: along the flat ridges of over-parametrised candidate models
FTOL = 1e-10


def bound_warning(name: str, side: str) -> str:
    """How the search's warning of a parameter at its ``side`` ("lower"/"upper") search
    bound begins (the plain shapes and the candidates' table read it)."""
    return f"ml: {name} is at its {side} search bound"


def _newton_gain(res, n: int) -> float:
    """ln L still to gain by a quasi-Newton step from L-BFGS-B's end point (½ g'H⁻¹g · n).

    L-BFGS-B stops 'abnormally' when its line search cannot improve a value that is already
    optimal to rounding; a negligible remaining gain means the optimum is reached.
    """
    g = np.asarray(res.jac, dtype=float)
    try:
        step = res.hess_inv.matvec(g) if hasattr(res.hess_inv, "matvec") else res.hess_inv @ g
    except Exception:  # noqa: BLE001 - no curvature model: be conservative
        return np.inf
    return float(0.5 * abs(g @ step) * n)


def _sequential(fun: Callable[[np.ndarray], float],
                points: Sequence[np.ndarray]) -> list[float]:
    return [fun(z) for z in points]


def optimise(prob, starts: list[np.ndarray], n_local: int | None,
              evaluate: Callable[[Callable[[np.ndarray], float], Sequence[np.ndarray]],
                                 list[float]] = _sequential
              ) -> tuple[np.ndarray, dict[str, Any], list[str]]:
    """Maximise the concentrated ln L of ``prob`` (a :class:`Problem`, or the joint
    problem of several runs, :mod:`~gyrostand.core.ml.joint`) by L-BFGS-B from the best of
    ``starts``: the searched point ``z``, the search's info and its warnings. ``evaluate``
    gives the objective at several points (the start grid, a gradient's points): an
    :class:`_Evaluator`'s thread pool, or one after the other."""
    warnings: list[str] = []

    analytic = prob.score if prob.analytic_score else None
    last: list = [None, None]  # the last point the search asked for, and its GLS part

    def obj(z: np.ndarray) -> float:
        ll, extra = prob.profile(z)
        last[:] = [z.copy(), extra]
        return -ll / prob.n_obs if np.isfinite(ll) else 1e10

    at_bound: list[str] = []
    lo = np.array([b[0] for b in prob.bounds])
    hi = np.array([b[1] for b in prob.bounds])

    def grad(z: np.ndarray) -> np.ndarray:
        if analytic is not None:  # at the point obj just evaluated (L-BFGS-B asks so)
            if last[0] is None or not np.array_equal(last[0], z):
                obj(z)
            if last[1] is None:
                return np.zeros(z.size)
            _, theta, s2, _ = last[1]
            return -analytic(z, theta, s2) / prob.n_obs
        # central differences in the log parameters (one-sided at a bound)
        g = np.empty(z.size)
        pts = []
        for i in range(z.size):
            up, dn = z.copy(), z.copy()
            up[i] = min(z[i] + GRAD_STEP, hi[i])
            dn[i] = max(z[i] - GRAD_STEP, lo[i])
            pts += [up, dn]
        vals = evaluate(obj, pts)
        for i in range(z.size):
            g[i] = (vals[2 * i] - vals[2 * i + 1]) / (pts[2 * i][i] - pts[2 * i + 1][i])
        return g

    if prob.znames:
        vals = evaluate(obj, starts)
        order = np.argsort(vals)
        if n_local is None:
            n_local = 2 if len(prob.rates) <= 1 else 5
        # best first, then the best of those whose rates differ by a factor > 5 from every
        # start already chosen: different basins (with measurement noise the likelihood
        # of β has a spurious maximum near 1/Δt besides the true one)
        chosen: list[int] = []
        nr = len(prob.rates)
        for i in order:
            if all(np.max(np.abs(starts[i][:nr] - starts[j][:nr]), initial=0.0) > np.log(5)
                   for j in chosen):
                chosen.append(i)
            if len(chosen) >= max(1, n_local):
                break
        best = None
        for i in chosen:
            res = minimize(obj, starts[i], jac=grad, method="L-BFGS-B", bounds=prob.bounds,
                           options={"maxiter": 300, "ftol": FTOL, "gtol": GTOL})
            if best is None or res.fun < best.fun - 1e-12:
                best = res
        assert best is not None
        z = best.x
        converged = bool(best.success) or _newton_gain(best, prob.n_obs) < 1e-4
        if not converged:
            warnings.append(f"ml: optimiser did not converge ({best.message})")
        for name, v, (z_lo, z_hi) in zip(prob.znames, z, prob.bounds, strict=True):
            if v <= z_lo + 1e-3 or v >= z_hi - 1e-3:
                at_bound.append(name)
                side = "lower" if v <= z_lo + 1e-3 else "upper"
                what = ("≈ 0: no measurable contribution" if side == "lower" and
                        prob.kind(name) == "std" else "at the edge of its plausible range")
                warnings.append(f"{bound_warning(name, side)} ({what})")
        info = {"iterations": int(best.nit), "converged": converged,
                "at_bound": list(at_bound)}
    else:
        z = np.zeros(0)
        info = {"iterations": 0, "converged": True}
    return z, info, warnings
