"""Standard errors of an ML fit: the observed information (numerical Hessian of ln L in
the natural parameters), kept symmetric positive definite."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..data import Samples
from ..model import Model
from ..terms.base import POSITIVE_KINDS

if TYPE_CHECKING:
    from .fit import Problem
    from .joint_problem import JointProblem


def hessian(fun, x: np.ndarray, h: np.ndarray, evaluate=None) -> np.ndarray:
    """Central-difference Hessian of ``fun`` at ``x`` with steps ``h``.

    ``evaluate(fun, points)`` → values, in order (default: one after the other; the ML fit
    passes a thread pool's map — the same values whichever way they are computed):

        H_ii = (f(x + h_i) − 2 f(x) + f(x − h_i)) / h_i²
        H_ij = (f(x + h_i + h_j) − f(x + h_i − h_j) − f(x − h_i + h_j) + f(x − h_i − h_j))
               / (4 h_i h_j)
    """
    n = x.size
    H = np.empty((n, n))
    pts = [x]
    for i in range(n):
        e = np.zeros(n)
        e[i] = h[i]
        pts += [x + e, x - e]
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    for i, j in pairs:
        ei = np.zeros(n)
        ej = np.zeros(n)
        ei[i], ej[j] = h[i], h[j]
        pts += [x + ei + ej, x + ei - ej, x - ei + ej, x - ei - ej]
    vals = evaluate(fun, pts) if evaluate is not None else [fun(q) for q in pts]
    f0 = vals[0]
    for i in range(n):
        fp, fm = vals[1 + 2 * i], vals[2 + 2 * i]
        H[i, i] = (fp - 2 * f0 + fm) / h[i] ** 2
    for k, (i, j) in enumerate(pairs):
        a, b, c, d = vals[1 + 2 * n + 4 * k: 5 + 2 * n + 4 * k]
        v = (a - b - c + d)
        H[i, j] = H[j, i] = v / (4 * h[i] * h[j])
    return H


#: an eigenvalue of an information matrix normalised to a unit diagonal at or below this
#: fraction of the largest (at least 1): a direction along which the likelihood is flat
FLAT = 1e-10
#: how the warning of a flat direction begins (the candidates' table reads it)
FLAT_WARNING = "the likelihood is flat along a combination of "


def _flat(lam: np.ndarray, V: np.ndarray, names: list[str]
          ) -> tuple[float, list[str] | None]:
    """The floor of the eigenvalues ``lam`` (eigenvectors ``V``) of a unit-diagonal
    information, and the parameters its flat directions involve (None: none is flat)."""
    floor = max(float(lam.max()), 1.0) * FLAT
    if lam.min() > floor:
        return floor, None
    bad = V[:, lam <= floor]
    return floor, sorted({names[i] for i in np.flatnonzero(np.abs(bad).max(axis=1) > 0.3)})


def covariance_from_hessian(H: np.ndarray, names: list[str]) -> tuple[np.ndarray, list[str]]:
    """Inverse of the observed information −H, kept symmetric positive definite.

    Directions where the likelihood is flat or curved the wrong way are clipped to a tiny
    curvature (a huge variance) and reported.
    """
    J = -0.5 * (H + H.T)
    scale = np.sqrt(np.abs(np.diag(J)))
    scale[scale == 0] = 1.0
    Jn = J / np.outer(scale, scale)
    lam, V = np.linalg.eigh(Jn)
    warnings = []
    floor, involved = _flat(lam, V, names)
    if involved is not None:
        warnings.append(f"{FLAT_WARNING}{', '.join(involved)}: not identifiable from these "
                        "data (their stds are huge)")
        lam = np.maximum(lam, floor)
    cov = (V / lam) @ V.T / np.outer(scale, scale)
    return 0.5 * (cov + cov.T), warnings


def observed_covariance(model: Model, samples: Samples, p: dict[str, float], free: list[str],
                         gls_info: np.ndarray, prob: Problem | JointProblem,
                         at_bound: list[str],
                         passes: int = 2, evaluate=None,
                         known: tuple[list[str], np.ndarray] | None = None):
    """Covariance from the numerical Hessian of ln L in the natural parameters (2 passes).

    A parameter at a search bound (typically a noise level ≈ 0) is not at an interior
    maximum: the others' covariance is then taken with it held at its estimate, and its
    own std is the inverse curvature along it alone. ``evaluate`` as :func:`hessian`.

    ``known``: (names, covariance) of a smaller model's fit (a diagnosis's current fit,
    whose candidate this is). Where the parameters the model adds are a random process's
    at a bound, its level at 0 (the fit is the smaller one: :func:`_added_at_zero`), one
    pass gives the others' covariance with those held, the smaller fit's own, so only the
    added parameters' curvatures are computed — the numbers the whole Hessian's diagonal
    gives them.
    """
    x0 = np.array([p[n] for n in free])
    noise_scale = max(p[n] for n in model.names_of_kind("std"))
    lin_std = {}
    if gls_info.size:
        ginv = np.linalg.pinv(gls_info)
        lin_std = {n: float(np.sqrt(max(ginv[i, i], 0.0))) for i, n in enumerate(prob.lin_free)}
    h = np.empty(x0.size)
    for i, n in enumerate(free):
        kind = prob.kind(n)
        if kind == "linear":
            h[i] = 0.1 * lin_std.get(n, 0.0) or 1e-4 * max(abs(x0[i]), 1.0)
        elif kind == "std":
            h[i] = 1e-2 * max(abs(x0[i]), 0.1 * noise_scale)
        else:
            h[i] = 1e-3 * abs(x0[i])

    def ll(x: np.ndarray) -> float:
        q = dict(p)
        for n, v in zip(free, x, strict=True):
            q[n] = float(v)
        for n in free:
            if prob.kind(n) in POSITIVE_KINDS and q[n] <= 0:
                return -np.inf
        return prob.full_loglik(q)

    warnings: list[str] = []
    # a noise level whose removal costs no likelihood is at its boundary (≈ 0) too
    ll0 = ll(x0)
    at_bound = list(at_bound)
    for i, n in enumerate(free):
        if prob.kind(n) == "std" and n not in at_bound:
            x = x0.copy()
            x[i] = 0.0
            if ll0 - ll(x) < 1e-3:
                at_bound.append(n)
    if known is not None and passes <= 1:
        added = _added_at_zero(model, free, known[0], at_bound, ll, ll0, x0)
        if added:
            return _added_only(free, known, added, ll, x0, h, noise_scale, evaluate), []
    B: np.ndarray | None = None  # principal axes of a previous pass (x = x0 + B u)
    hu = h
    prev: np.ndarray | None = None  # the last covariance without a clipped direction
    for _ in range(max(1, passes) + 1):
        if _ == max(1, passes) and B is None:
            break  # the extra pass is only for a retry along the axes
        if B is None:
            H = hessian(ll, x0, h, evaluate)
        else:
            # along the previous covariance's principal axes, 0.1 std each (a step in
            # whitened coordinates): on a narrow curved ridge (β–γ, correlation 0.9997)
            # coordinate steps of 0.1 std each cross the ridge's curvature and the
            # Hessian came out indefinite — a 'flat' warning where ML's own profile
            # deviance rises by 12-14 within the band (chamber hour, seed 5061)
            Hu = hessian(lambda u, B=B: ll(x0 + B @ u), np.zeros(x0.size), hu, evaluate)
            Binv = np.linalg.inv(B)
            H = Binv.T @ Hu @ Binv
        if not np.all(np.isfinite(H)):
            H = np.nan_to_num(H, nan=0.0, posinf=0.0, neginf=0.0)
        inner = [i for i, n in enumerate(free) if n not in at_bound]
        cov = np.zeros((len(free), len(free)))
        sub, warnings = covariance_from_hessian(H[np.ix_(inner, inner)], [free[i] for i in inner])
        cov[np.ix_(inner, inner)] = sub
        for i, n in enumerate(free):
            if n in at_bound:
                cov[i, i] = _alone_variance(H[i, i], noise_scale)
        sd = np.sqrt(np.diag(cov))
        new_h = 0.1 * sd
        for i, n in enumerate(free):
            if prob.kind(n) in POSITIVE_KINDS:
                new_h[i] = min(new_h[i], 0.05 * abs(x0[i]))
            elif prob.kind(n) == "std":
                new_h[i] = min(new_h[i], 0.1 * max(abs(x0[i]), 0.1 * noise_scale))
            new_h[i] = max(new_h[i], 1e-9 * max(abs(x0[i]), 1e-12))
        h = new_h
        if warnings and B is None and prev is not None:
            # clipped after coordinate steps: once more along the principal axes of the
            # last covariance that had none (a narrow curved ridge, not a flat direction)
            B, hu = _axes(prev, inner, h, x0, [prob.kind(n) in POSITIVE_KINDS for n in free])
            if B is not None:
                continue
        if not warnings:
            prev = cov
    if not any(w.startswith(FLAT_WARNING) for w in warnings):
        warnings += collinear(gls_info, list(prob.lin_free))
    return cov, warnings


def collinear(info: np.ndarray, names: list[str]) -> list[str]:
    """The 'flat' warning for coefficients whose regressors are collinear (a constant
    temperature's response beside the bias) — read from their GLS information exactly,
    where the numerical Hessian of a flat direction is rounding noise either way (a std
    of 180 or of 0.05 for β at optima 1e-8 apart); the same test as
    :func:`covariance_from_hessian`'s (:data:`FLAT`)."""
    if info.shape[0] < 2:
        return []
    d = np.sqrt(np.abs(np.diag(info)))
    if not np.all(d > 0) or not np.all(np.isfinite(info)):
        return []
    _, involved = _flat(*np.linalg.eigh(info / np.outer(d, d)), names)
    if involved is None:
        return []
    return [f"{FLAT_WARNING}{', '.join(involved)}: their regressors are collinear in these "
            "data (not identifiable; their stds mean nothing)"]


def _alone_variance(hii: float, noise_scale: float) -> float:
    """The variance of a parameter at a bound from the curvature ``hii`` of ln L along it
    alone (a tenth of the noise scale, squared, where ln L does not curve down)."""
    return 1.0 / max(-hii, 1e-300) if -hii > 0 else (0.1 * noise_scale) ** 2


def _added_at_zero(model: Model, free: list[str], names: list[str], at_bound: list[str],
                   ll, ll0: float, x0: np.ndarray) -> list[int] | None:
    """The positions in ``free`` of the parameters ``model`` adds to the smaller fit's
    ``names`` where the fit is that smaller one: each added term a random process whose
    noise levels are 0 (setting them to 0 costs no ln L) and every added parameter at a
    bound (a second process's rate with its level); None otherwise (a lag at the end of
    its range is a model of its own)."""
    added = [i for i, n in enumerate(free) if n not in names]
    if not added or any(n not in names for i, n in enumerate(free) if i not in added) \
            or any(free[i] not in at_bound for i in added):
        return None
    for i in added:
        term = model.term_of(free[i])
        if term.n_states == 0:
            return None
        for q in term.params:
            if q.kind != "std":
                continue
            key = term.key(q.name)
            if key not in free or free.index(key) not in added:
                return None
            x = x0.copy()
            x[free.index(key)] = 0.0
            if not ll0 - ll(x) < 1e-3:
                return None
    return added


def _added_only(free: list[str], known: tuple[list[str], np.ndarray], added: list[int],
                ll, x0: np.ndarray, h: np.ndarray, noise_scale: float,
                evaluate=None) -> np.ndarray:
    """:func:`observed_covariance` where the fit is the smaller one of ``known``: its
    covariance for the shared parameters, each added one's inverse curvature along it alone
    (the central difference :func:`hessian` takes on the diagonal, with the same steps)."""
    names, kcov = known
    old = [i for i in range(len(free)) if i not in added]
    k = [names.index(free[i]) for i in old]
    cov = np.zeros((len(free), len(free)))
    cov[np.ix_(old, old)] = kcov[np.ix_(k, k)]
    pts = [x0]
    for i in added:
        e = np.zeros(x0.size)
        e[i] = h[i]
        pts += [x0 + e, x0 - e]
    vals = evaluate(ll, pts) if evaluate is not None else [ll(q) for q in pts]
    f0 = vals[0]
    for j, i in enumerate(added):
        fp, fm = vals[1 + 2 * j], vals[2 + 2 * j]
        hii = float(np.nan_to_num((fp - 2 * f0 + fm) / h[i] ** 2, nan=0.0, posinf=0.0,
                                  neginf=0.0))
        cov[i, i] = _alone_variance(hii, noise_scale)
    return cov


def _axes(cov: np.ndarray, inner: list[int], h: np.ndarray, x0: np.ndarray,
          positive: list[bool]) -> tuple[np.ndarray | None, np.ndarray]:
    """(B, hu): the next pass's step directions and sizes, x = x0 + B u. The interior
    parameters along their covariance's principal axes (B's block U√S, u-steps of 0.1, made
    smaller where a positive parameter would come within half its value of 0); a parameter
    at a bound along its own coordinate (step ``h``). None where the covariance has a
    clipped (flat) direction: the coordinate steps ``h`` then, as before."""
    n = x0.size
    sub = cov[np.ix_(inner, inner)]
    if not inner or not np.all(np.isfinite(sub)):
        return None, h
    lam, U = np.linalg.eigh(0.5 * (sub + sub.T))
    if lam.min() <= 0 or lam.max() / lam.min() > 1e14:
        return None, h
    B = np.diag(np.where(np.isin(np.arange(n), inner), 0.0, 1.0))
    B[np.ix_(inner, inner)] = U * np.sqrt(lam)
    hu = np.where(np.isin(np.arange(n), inner), 0.1, h)
    # a positive parameter must stay positive at every point of the stencil (two axes)
    reach = 2.0 * np.abs(B) @ np.where(np.isin(np.arange(n), inner), 0.1, 0.0)
    for i in inner:
        if positive[i] and reach[i] > 0.5 * abs(x0[i]):
            hu[inner] *= 0.5 * abs(x0[i]) / reach[i]
            reach *= 0.5 * abs(x0[i]) / reach[i]
    return B, hu
