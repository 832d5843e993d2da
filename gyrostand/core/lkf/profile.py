"""β's profile likelihood from the converging LKF's own record
(:class:`~gyrostand.core.lkf.relin.RelinLKF`): is its symmetric band calibrated?

Given β the drift model is linear in every other estimated coefficient (γ, c = βb, the
output terms'): one pass of the filter over the stored record with β *held* (δβ's prior
variance zero, the soaked start conditioned on δβ = 0) is an exact Kalman filter, and its
innovations give the log-likelihood of the record at that β with the other coefficients
integrated out (their priors the filter's), the common noise scale concentrated out:

    ℓ(β) = −½ [ n ln(Σ e²/f / n) + Σ ln f ]        (n observed bins)

The deviance D(β) = 2 [ℓ(β̂) − ℓ(β)] is (β − β̂)²/σ_β² where the likelihood is Gaussian in
β. In a short record it is skewed (β̂ is biased high), and the joint region of β and a
coefficient that depends on it curves (b = c/β most): the symmetric band from the
filter's covariance then lies. :func:`profile_interval` gives each parameter's ±3σ
profile-likelihood interval from a grid of β-held passes (given β the others are
Gaussian), and says whether β's likelihood stays within 9 of its maximum to an end of the
grid (flat or strongly skewed: no interval). Each grid point is one pass (O(n)); the
filter's state is restored afterwards. Measured by ``benchmarks/lkf_accuracy.py``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .relin import RelinLKF

__all__ = ["GRID", "beta_profile", "profile_check", "profile_interval"]


def beta_profile(f: RelinLKF, betas: Sequence[float]
                 ) -> list[tuple[float, np.ndarray | None, np.ndarray | None]]:
    """ℓ(β) (module docstring) of ``f``'s stored record at each of ``betas`` (1/s, > 0),
    the estimate of every model parameter (``f.params``) given that β and its std (β's
    zero; the held noise levels' share outside β kept); ``(NaN, None, None)`` for a
    β ≤ 0. The other coefficients' point is the current estimate. ``f``'s
    state (estimate, covariance, innovations, held levels) is left as it was."""
    n = f.n
    if n == 0:
        return [(math.nan, None, None)] * len(betas)
    saved = (f.point.copy(), f.x.copy(), f.P.copy(), f._st.copy(), f._E[:n].copy(),
             f._F[:n].copy(), dict(f.held), f._qd, f.prior_sd.copy())
    est = f.values.copy()
    off = f.names.index(f.offset_key) if f.offset_key is not None else -1
    U = f._U()
    out: list[tuple[float, np.ndarray | None, np.ndarray | None]] = []
    try:
        for beta in betas:
            if not beta > 0 or not math.isfinite(beta):
                out.append((math.nan, None, None))
                continue
            pt = est.copy()
            pt[0] = beta
            if off >= 0:  # c = βb: the same b at this β
                pt[off] = est[off] * beta / est[0] if est[0] > 0 else est[off]
            f.point = pt
            f.held, f._qd = dict(saved[6]), saved[7]
            f._configure()
            f._start()
            # condition the prior on δβ = 0: P − P[:, 1] P[1, :] / P[1, 1]
            P = f.P
            if P[1, 1] > 0:
                P = P - np.outer(P[:, 1], P[1, :]) / P[1, 1]
            P[1, :] = 0.0
            P[:, 1] = 0.0
            f.P = P
            s, lf, m = f._pass(0, n, U)
            ll = -0.5 * (m * math.log(s / m) + lf) if m > 0 and s > 0 else math.nan
            # the estimate given β, its covariance with the held levels' share outside β
            infl = f._infl.copy()
            infl[0, :] = 0.0
            infl[:, 0] = 0.0
            k = len(f.names)
            v, C = f.to_model(f.values, f.P[1: 1 + k, 1: 1 + k] + infl)
            out.append((ll, v.copy(), np.sqrt(np.maximum(np.diag(C), 0.0))))
    finally:
        f.point = saved[0]
        f.x, f.P, f._st = saved[1], saved[2], saved[3]
        f._E[:n], f._F[:n] = saved[4], saved[5]
        f.held, f._qd = dict(saved[6]), saved[7]
        f._configure()
        f.prior_sd = saved[8]
    return out


#: β's grid for :func:`profile_interval`, in its stds from β̂
GRID = (-6.0, -4.5, -3.0, -1.5, 0.0, 1.5, 3.0, 4.5, 6.0)


def profile_interval(f: RelinLKF, k: float = 3.0, grid: Sequence[float] = GRID
                     ) -> tuple[np.ndarray, np.ndarray, bool]:
    """The ±k-level profile-likelihood interval of every model parameter (``f.params``),
    from one β-held pass per point of β̂ + ``grid``·σ_β: given β the others are Gaussian
    (estimate θ̂(β), std s(β)), so the interval of θ_j is the union over β of
    θ̂_j(β) ± s_j(β)·√(k² − D(β)) where D(β) < k² (β's own: the β with D < k²). In the
    linear-Gaussian case this is the ±kσ band exactly. Returns ``(lo, hi, open)``,
    ``open`` when D stays below k² at an end of the grid (the interval runs past it: a
    flat or strongly skewed likelihood)."""
    lo, hi, open_, _ = profile_check(f, k, grid)
    return lo, hi, open_


def profile_check(f: RelinLKF, k: float = 3.0, grid: Sequence[float] = GRID
                  ) -> tuple[np.ndarray, np.ndarray, bool, float]:
    """:func:`profile_interval`'s ``(lo, hi, open)`` and D(β̂): the deviance of the
    estimate itself from the highest point of its grid, 0 where β̂ is the maximum of the
    record's likelihood in β (NaN where the grid's β̂ pass failed). Well above k² the
    filter's point is not that maximum: the re-linearisation sits off it (a 6-h chamber
    run at 4200 s: β̂ 0.51 1/s, its own profile highest at 0.40 with D(β̂) = 38.5, ML on
    the same 4200 s 0.0063 ± 0.0031)."""
    b, sb = float(f.values[0]), float(f.stds[0])
    betas = [b + u * sb for u in grid]
    pr, d_hat_ll = [], math.nan
    for u, (ll, v, sd) in zip(grid, beta_profile(f, betas), strict=True):
        if v is not None and sd is not None and math.isfinite(ll):
            pr.append((ll, v, sd))
            if u == 0.0:
                d_hat_ll = ll
    npar = len(f.params)
    if not pr:
        return np.full(npar, -np.inf), np.full(npar, np.inf), True, math.nan
    lmax = max(p[0] for p in pr)
    k2 = k * k
    d = np.array([2.0 * (lmax - p[0]) for p in pr])
    bs = np.array([float(v[0]) for _, v, _ in pr])
    lo, hi = np.full(npar, np.inf), np.full(npar, -np.inf)
    for (_, v, sd), dj in zip(pr, d, strict=True):
        if dj < k2:
            w = np.sqrt(k2 - dj) * sd
            lo, hi = np.minimum(lo, v - w), np.maximum(hi, v + w)
    # β's own ends: where D crosses k² between grid points (linear in D)
    inside = np.flatnonzero(d < k2)
    i0, i1 = int(inside[0]), int(inside[-1])
    lo[0] = bs[i0] if i0 == 0 else bs[i0 - 1] + (bs[i0] - bs[i0 - 1]) * (
        d[i0 - 1] - k2) / (d[i0 - 1] - d[i0])
    hi[0] = bs[i1] if i1 == len(d) - 1 else bs[i1] + (bs[i1 + 1] - bs[i1]) * (
        k2 - d[i1]) / (d[i1 + 1] - d[i1])
    open_ = i0 == 0 or i1 == len(d) - 1
    return lo, hi, bool(open_), 2.0 * (lmax - d_hat_ll)
