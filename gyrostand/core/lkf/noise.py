"""The converging LKF's held noise levels (:class:`~gyrostand.core.lkf.relin.RelinLKF`):
re-estimated at the current point, and their share of the estimate's covariance.

:func:`reestimate`: the held noise levels the caller did not fix are searched at the
current point by a 1-D likelihood search: with both σ and σ_v free the common scale is
concentrated out (``s² = Σ e²/f̃ / n``) and the ratio σ_v/σ searched (bounded Brent in
ln ratio); other processes (``random_walk``, ``markov2``) keep their ratio to σ.
:func:`inflation`: the estimate's covariance grows by the delta method with the searched
level's variance.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import minimize_scalar

from ..aot import kernel
from ..kalman import NO_WEIGHTS, kf_run
from ..terms.base import Context
from .kernel import gm_profile

if TYPE_CHECKING:
    from .relin import RelinLKF

#: bounds of the searched noise ratio σ_v/σ
RATIO_BOUNDS = (1e-3, 1e2)
#: step in the log noise parameter for its curvature and the estimate's sensitivity
NOISE_STEP = 0.1
#: a noise level searched to a bound of its range: at least this far (log) into it for the
#: estimate's sensitivity (kept for callers; the reach is the profile's, see PROFILE_DROP)
BOUND_STEP = 4.0
#: a level at a bound: its plausible range ends where −ln L has risen by this much, half
#: the 99.73 % point of χ²(1) (the ±3σ band's level), found on steps of PROFILE_GRID
PROFILE_DROP = 0.5 * 8.807468
PROFILE_GRID = 0.25
#: above this std of ẑ the profile's interval ends replace its curvature
PROFILE_STD = 0.25
#: z poorly determined: the band is the union of the filter's bands over z's interval
#: (False: the larger one-std shift of the two ends plus E P(z), kept for comparison)
UNION = True


def _profile_reach(nll, z: float, inward: float, lo: float, hi: float,
                   floor: float = BOUND_STEP, drop: float = PROFILE_DROP
                   ) -> tuple[float, bool]:
    """How far (> 0, log units) from ``z``, towards ``inward``, the profile ``nll``
    stays within ``drop`` of its value at ``z``: the first grid step past the drop,
    interpolated linearly to the drop, at least ``floor``; and whether the drop was
    reached (False: the profile stays flat to the end of [lo, hi], whose distance is
    returned)."""
    base = nll(z)
    prev_d, prev_rise = 0.0, 0.0
    span = (hi - z) if inward > 0 else (z - lo)
    d = PROFILE_GRID
    while d <= span:
        rise = nll(z + inward * d) - base
        if not math.isfinite(rise):
            break
        if rise >= drop:
            frac = (drop - prev_rise) / (rise - prev_rise) if rise > prev_rise else 1.0
            return max(prev_d + frac * (d - prev_d), floor), True
        prev_d, prev_rise = d, rise
        d += PROFILE_GRID
    return max(min(prev_d, span), floor), False


def inflation(f: RelinLKF, n: int, U: np.ndarray) -> None:
    """The held noise levels are estimates: add their share to the covariance of the
    estimate. Each step ``(h, k)`` of the search's record is one more pass with the
    searched log level z moved to z + h (then the state is restored); its shift of the
    estimate times ``k`` is a one-std vector ``w`` in the direction of +z:

    * regular (z well determined): one step of one std, ``k = std ẑ / h``, so
      ``C += (∂θ̂/∂z)(∂θ̂/∂z)' var ẑ``: the delta method;
    * z poorly determined (std ẑ > PROFILE_STD): the two ends of its profile-likelihood
      interval at the ±3σ level, ``k = ±1/3``; the band is the union of the filter's
      ±3σ bands over the interval: per coefficient its half-width is the largest of
      3√P(ẑ) and |θ̂(z_end) − θ̂| + 3√P(z_end) over the ends (P's correlations kept). A
      side where the profile stays flat to the range's end adds the delta method's
      one-std shift. Measured on C3 σ_v = σ/2 at 400 s (200 runs): coverage 0.99 for β
      and γ, against 0.955–0.96 with the larger one-std shift of the two ends plus
      E P(z) to second order, and ML's own band 0.84. Applied only here: with z well
      determined the union over a ±3σ interval is far wider than the spread (C3 at
      1500 s with the threshold at 0.1: every |error| < 1.7 std);
    * at a bound: one step to the profile's reach, ``k = 1/3``: the union of the bands
      at the bound and at the reach (the level is not estimated)."""
    f._infl = np.zeros((len(f.names),) * 2)
    if f._noise is None:
        return
    apply, z, _var_z, steps, at_bound = f._noise

    saved = (f.x.copy(), f.P.copy(), f._st.copy(), f._E[:n].copy(),
             f._F[:n].copy(), dict(f.held), f._qd)
    v0 = f.values.copy()
    k = len(f.names)
    w: np.ndarray | None = None
    extra = np.zeros((k, k))
    curv = np.zeros((k, k))
    P0 = saved[1][1: 1 + k, 1: 1 + k]
    # per coefficient, the widest ±3σ reach of the filter's band at an end of the level's
    # ±3σ profile interval: |θ̂(z_end) − θ̂| + 3 √P(z_end)  (the union of the bands)
    reach = np.zeros(k)
    flat = np.zeros(k)
    for h, scale in steps:
        apply(z + h)
        f._configure()
        f._start()
        f._pass(0, n, U)
        wi = (f.values - v0) * scale
        ex = f.P[1: 1 + k, 1: 1 + k] - P0
        if UNION and abs(abs(scale) - 1.0 / 3.0) < 1e-12:
            reach = np.maximum(reach, np.abs(f.values - v0)
                               + 3.0 * np.sqrt(np.maximum(np.diag(f.P)[1: 1 + k], 0.0)))
        elif UNION:
            flat = np.maximum(flat, wi * wi)
        if np.trace(ex) > np.trace(extra):
            extra = ex
        curv += 0.5 * scale * scale * ex
        f.x, f.P, f._st = saved[0].copy(), saved[1].copy(), saved[2].copy()
        f._E[:n], f._F[:n] = saved[3], saved[4]
        f.held, f._qd = dict(saved[5]), saved[6]
        if not np.all(np.isfinite(wi)):
            w = None
            break
        w = wi if w is None else np.where(np.abs(wi) > np.abs(w), wi, w)
    f._configure()
    if w is not None and UNION and np.any(reach > 0):
        # z poorly determined, its interval closed on a side: the band holds the union of
        # the filter's ±3σ bands over the interval (checked at its ends): a coverage of at
        # least 1 − 2·0.27 % whatever θ̂(z) and P(z) do in between, if they are monotone;
        # P's correlations kept, each variance raised to its union's (3σ half-width / 3)²
        d0 = np.sqrt(np.maximum(np.diag(P0), 1e-300))
        want = np.sqrt(np.maximum(d0 * d0, (reach / 3.0) ** 2) + flat)
        D = want / d0
        f._infl = P0 * np.outer(D, D) - P0
        return
    if w is not None:
        f._infl = np.outer(w, w)
        if at_bound and np.all(np.diag(extra) > 0):
            # ... and at a bound (the level not estimated), the wider band of the
            # level moved into its range (inside it, that term averages out)
            f._infl += extra
        elif len(steps) > 1 and np.all(np.diag(curv) > 0):
            # ... and with a step each way, the filter's own band averaged over the
            # level's uncertainty to second order: E P(z) ≈ P(ẑ) + ½ P''(ẑ) var ẑ, the
            # second difference of P over the two steps (each scaled to one std)
            f._infl += curv


def reestimate(f: RelinLKF, ctx: Context) -> None:
    """The held noise levels not fixed by the caller, at the current point."""
    f._noise = None
    free = [k for k in ("markov.sigma", "white.sigma") if k not in f.fixed]
    if not free or f.n < 10:
        return
    p = {**f.held, **f._model_point()}
    X = f.model.regressors(p, ctx)
    lin = f.model.names_of_kind("linear")
    theta = np.array([p[k] for k in lin])
    d = f._y[: f.n] - (X @ theta if theta.size else 0.0)
    D = np.ascontiguousarray(d[:, None])
    sig0 = f.held["markov.sigma"]
    others = {k: v / sig0 for k, v in f.held.items()
              if f.model.kind(k) == "std" and k not in ("markov.sigma", "white.sigma")}

    single = f.model.n_states == 1
    memo: dict[tuple[float, bool], tuple[float, float]] = {}

    def nll(z: float, scale_free: bool) -> tuple[float, float]:
        """−ln L at ln ratio z (σ = 1 when the scale is concentrated), and s²."""
        if (z, scale_free) in memo:
            return memo[z, scale_free]
        q = dict(p)
        if scale_free:
            q["markov.sigma"], q["white.sigma"] = 1.0, math.exp(z)
            for k, v in others.items():
                q[k] = v
        elif "markov.sigma" in free:
            q["markov.sigma"] = math.exp(z)
        else:
            q["white.sigma"] = math.exp(z)
        ss = f.model.state_space(q, f.dt)
        if single:  # markov + white: the scalar filter
            profile = kernel("gm_profile", gm_profile)  # at install, else numba's
            g, slogf, nobs = profile(d, ss.phi[0], ss.q[0], ss.r, ss.p0[0])
        else:
            G, slogf, nobs = kf_run(ss.phi, ss.q, ss.p0, ss.r, NO_WEIGHTS, D, False)[2:]
            g = float(G[0, 0])
        out = (math.inf, 1.0)
        if np.isfinite(slogf) and nobs > 0:
            if scale_free:
                out = 0.5 * (nobs * math.log(g / nobs) + slogf), g / nobs
            else:
                out = 0.5 * (g + slogf), 1.0
        memo[z, scale_free] = out
        return out

    def brent(a: float, b: float, scale_free: bool) -> float:
        res = minimize_scalar(lambda z: nll(z, scale_free)[0], bounds=(a, b),
                              method="bounded", options={"xatol": 0.02})
        return float(res.x)

    def search(z0: float, lo: float, hi: float, scale_free: bool) -> float:
        """Bounded Brent in a bracket of ±1.5 around ``z0``; when the minimum sits at
        the edge of the bracket or near a bound of [lo, hi] (the profile can have a
        second minimum where one noise level vanishes), a coarse grid over [lo, hi]
        picks the bracket again."""
        z = brent(max(lo, z0 - 1.5), min(hi, z0 + 1.5), scale_free)
        near = min(z - lo, hi - z) < 0.5 or abs(z - z0) > 1.45
        if near:
            grid = np.linspace(lo, hi, 9)
            best = float(grid[int(np.argmin([nll(float(g), scale_free)[0]
                                             for g in grid]))])
            if nll(best, scale_free)[0] < nll(z, scale_free)[0]:
                z = brent(max(lo, best - 1.5), min(hi, best + 1.5), scale_free)
        return z if nll(z, scale_free)[0] <= nll(z0, scale_free)[0] else z0

    b0 = float(f.point[0])
    if len(free) == 2:
        lo, hi = math.log(RATIO_BOUNDS[0]), math.log(RATIO_BOUNDS[1])
        z0 = math.log(min(max(f.held["white.sigma"] / sig0, RATIO_BOUNDS[0]),
                          RATIO_BOUNDS[1]))
        z = search(z0, lo, hi, True)
        scale_free = True

        def apply(z: float) -> None:
            s = math.sqrt(nll(z, True)[1])
            f.held["markov.sigma"] = s
            f.held["white.sigma"] = s * math.exp(z)
            for k, v in others.items():
                f.held[k] = s * v
            f._qd = s * s * -math.expm1(-2.0 * b0 * f.dt)
    else:
        ref = f.held[free[0]] if f.held[free[0]] > 0 else sig0
        z0 = math.log(max(ref, 1e-12))
        lo, hi = z0 - 8.0, z0 + 8.0
        z = search(z0, lo, hi, False)
        scale_free = False

        def apply(z: float) -> None:
            f.held[free[0]] = math.exp(z)
            if free[0] == "markov.sigma":
                f._qd = math.exp(2 * z) * -math.expm1(-2.0 * b0 * f.dt)
    apply(z)
    # var ẑ from the curvature of −ln L (a flat profile: the full search range)
    c = (nll(z + NOISE_STEP, scale_free)[0] - 2 * nll(z, scale_free)[0]
         + nll(z - NOISE_STEP, scale_free)[0]) / NOISE_STEP ** 2
    span = (hi - lo) / 2
    var_z = min(1.0 / c, span * span) if c > 0 else span * span
    # the sensitivity pass moves the drift's noise up by one std of ẑ (σ larger:
    # z = ln σ_v/σ down, or ln σ up): a finite difference over the plausible range
    up = -1.0 if scale_free or free[0] == "white.sigma" else 1.0
    h = up * min(max(math.sqrt(var_z), NOISE_STEP), BOUND_STEP)
    at_bound = hi - z < 0.05 if scale_free else (z - lo < 0.05 or hi - z < 0.05)
    if scale_free and z - lo < 0.05:
        # σ_v/σ at its lower bound: σ_v ≈ 0, the data are smooth; the ratio's direction
        # does not move the estimate and σ (the scale) is concentrated
        f._noise = None
        return
    prof = lambda zz: nll(zz, scale_free)[0]  # noqa: E731
    if at_bound:
        # at a bound of its search the level is not estimated and the curvature means
        # nothing: the plausible levels reach from the bound to where the profile
        # likelihood has fallen by PROFILE_DROP (its ±3σ-equivalent limit). The
        # sensitivity pass goes there, and the band is widened so that its ±3 std hold
        # the estimate at that level, plus the filter's wider band there.
        inward = 1.0 if z - lo < 0.05 else -1.0
        h = inward * _profile_reach(prof, z, inward, lo, hi)[0]
        f._noise = (apply, z, (h / 3.0) ** 2, ((h, 1.0 / 3.0),), True)
        return
    if math.sqrt(var_z) > PROFILE_STD:
        # poorly determined (a short record): the curvature at ẑ misjudges a skewed
        # profile; its interval's two ends at the ±3σ level instead
        up_end, up_closed = _profile_reach(prof, z, 1.0, lo, hi, floor=0.0)
        down_end, down_closed = _profile_reach(prof, z, -1.0, lo, hi, floor=0.0)
        # each side where the profile closes inside the range: its end at the ±3σ
        # level; a side where it stays flat to an end of the range: the delta
        # method's one-std step that way
        sd = math.sqrt(var_z)
        steps = tuple((d, sgn / 3.0) if closed else (sgn * sd, sgn)
                      for d, sgn, closed in ((up_end, 1.0, up_closed),
                                             (-down_end, -1.0, down_closed))
                      if d != 0 and lo <= z + (d if closed else sgn * sd) <= hi)
        if steps:
            f._noise = (apply, z, var_z, steps, False)
            return
    if not lo <= z + h <= hi:
        h = -h
    f._noise = (apply, z, var_z, ((h, math.sqrt(var_z) / h),), False)
