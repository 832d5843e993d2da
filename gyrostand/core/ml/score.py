"""The analytic gradient (score) of the concentrated log-likelihood: one tangent-linear
pass of the Kalman filter instead of 2·d filter passes of central differences.

At a point ``z`` of the search (log rates, log noise ratios) the concentrated ln L is
ln L at the GLS coefficients θ̂(z) (and the scale ŝ²(z)), which maximise it: by the
envelope theorem its gradient is the partial derivative of ln L at fixed θ̂, ŝ²,

    ∂ ln L / ∂z_j = −½ Σ_k [ ∂f_k/f_k + (2 e_k ∂e_k − e_k² ∂f_k / f_k) / (ŝ² f_k) ],

with e_k, f_k the innovations of the residual series u = [y, X] c (c = [1, −θ̂]) through
the model's filter. Their derivatives come from the filter's tangent-linear recursion
(the filter of :func:`~gyrostand.core.kalman.kf_run`: independent scalar states, H = 1'):

    ∂f = 1'∂P 1 + ∂r_k ;  ∂K = (∂P 1 − K ∂f) / f ;  ∂e = ∂u_k − 1'∂x
    ∂x⁺ = ∂x + ∂K e + K ∂e ;  ∂P⁺ = ∂P − (∂(P1)(P1)' + (P1)∂(P1)')/f + (P1)(P1)' ∂f/f²
    ∂x = ∂φ∘x⁺ + φ∘∂x⁺ ;  ∂P_ab = (∂φ_a φ_b + φ_a ∂φ_b) P⁺_ab + φ_a φ_b ∂P⁺_ab + δ_ab ∂q_a

The system's derivatives ∂φ, ∂q, ∂p0, ∂r (small arrays) and the data's ∂u = (∂X/∂z_j) θ̂
(a rate or shape moves the regressors: a thermal response through the drift's process, a
lag) are central differences of the model's own state space and regressors, which are
smooth closed forms, so the gradient is exact to ~1e-9 relative where the filter's own
central differences (step 1e-5) were good to ~1e-6. Measured on the 6-h run of
``benchmarks/diagnose_speed.py``: the gradient of a candidate refit 2·d = 8-12 passes →
one pass of ~2.5 passes' cost.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..aot import kernel
from ..jit import listen, njit, ready
from ..rts import sum_variance, writable

if TYPE_CHECKING:
    from .fit import Problem

listen()

#: step of the central differences of the state space and regressors in log parameters
STEP = 1e-6
#: ∂P has settled (with P repeated bit for bit) when no entry moved by more than this
#: fraction of its parameter's largest entry since the previous sample: its recursion,
#: a contraction once P is fixed, ends in a cycle of values a few units in the last place
#: apart (sample-to-sample cancellations of ∂P − 2K∂P + K²∂P), which bit-for-bit
#: equality never accepted: the kernel then recomputed ∂P at every sample
#: (3.4 ms a pass where the filter takes 1.0, 6-h run). A step of 1e-13 of a contraction
#: by ρ leaves ∂P within 1e-13/(1 − ρ) of its fixed point.
DP_SETTLED = 1e-13


def score(prob: Problem, z: np.ndarray, theta: np.ndarray, s2: float) -> np.ndarray:
    """∂ ln L / ∂z of ``prob`` (a :class:`~.fit.Problem`) at ``z``, its GLS coefficients
    ``theta`` (free linear parameters) and scale ``s2`` (1 when not concentrated)."""
    return score_pass(prob, z, theta, s2)[0]


def score_pass(prob: Problem, z: np.ndarray, theta: np.ndarray, s2: float
               ) -> tuple[np.ndarray, int]:
    """:func:`score`, and the number of observed samples at which the pass recomputed
    the covariance and its derivatives (before its steady state, after a gap)."""
    p = prob.unpack(z)
    d = z.size
    model, dt = prob.model, prob.samples.dt
    Y = prob.filter_input(p)
    c = prob.c0.copy()
    c[prob.free_cols] = -theta
    u = Y @ c
    ss = model.state_space(p, dt)
    n = ss.phi.size
    dphi, dq, dp0 = np.zeros((d, n)), np.zeros((d, n)), np.zeros((d, n))
    dr = np.zeros(d)
    du = np.zeros((d, u.size))
    coef = {key: c[1 + i] for i, key in enumerate(prob.linear)}  # u's weight of each column
    ctx = prob.ctx.bound(model.modifiers)
    for j, name in enumerate(prob.znames):
        up, dn = dict(p), dict(p)
        up[name] = float(np.exp(z[j] + STEP))
        dn[name] = float(np.exp(z[j] - STEP))
        a, b = model.state_space(up, dt), model.state_space(dn, dt)
        dphi[j] = (a.phi - b.phi) / (2 * STEP)
        dq[j] = (a.q - b.q) / (2 * STEP)
        dp0[j] = (a.p0 - b.p0) / (2 * STEP)
        dr[j] = (a.r - b.r) / (2 * STEP)
        if name in prob.x_names and Y.shape[1] > 1:
            # a term's own slopes where it gives them (Term.regressor_slopes), else
            # central differences of its regressors
            differenced = []
            for t in _moved_by(prob, name, p):
                slopes = t.regressor_slopes(p, ctx, name)
                if slopes is None:
                    differenced.append(t)
                    continue
                for key, sl in slopes.items():
                    if key in coef:
                        du[j] += sl * coef[key]
            if differenced:
                ca = model.columns(up, prob.ctx, differenced)
                cb = model.columns(dn, prob.ctx, differenced)
                moved = np.zeros(u.size)
                for key, xa in ca.items():
                    if key in coef:
                        moved += (xa - cb[key]) * coef[key]
                du[j] += moved / (2 * STEP)
    # u's NaN (a missing sample) is du's too: the kernel tests u
    ready("score_run")  # a first run: compiled beside this process (..prewarm)
    work = score_work(n, d)
    run = kernel("score_run", _score_run, made_here=True)  # compiled at install, else numba's
    g_logf, g_s = run(writable(ss.phi), writable(ss.q), writable(ss.p0), float(ss.r),
                      writable(prob.weights), writable(u), dphi, dq, dp0, dr, du, *work)
    return -0.5 * (g_logf + g_s / s2), int(work[-1][0])


def score_work(n: int, d: int) -> tuple[np.ndarray, ...]:
    """:func:`_score_run`'s state and work arrays for ``n`` states and ``d`` parameters,
    allocated here: numba compiles each ``np.zeros``/``np.empty`` of a kernel for its own
    rank, and its 13 allocations were 0.6 of the kernel's 2.1 s of compilation on a first
    run (measured in a fresh process). ``x, P, dx, dP, PH, dPH, K, dK, df, g_logf, g_s,
    P_last, dP_last, unsettled``: the kernel's start values (zeros) where it reads them
    first (``unsettled``, one entry: the count of samples that recomputed P and ∂P)."""
    return (np.zeros(n), np.zeros((n, n)), np.zeros((d, n)), np.zeros((d, n, n)),
            np.empty(n), np.empty((d, n)), np.empty(n), np.empty((d, n)), np.empty(d),
            np.zeros(d), np.zeros(d), np.empty((n, n)), np.empty((d, n, n)), np.zeros(1))


def _moved_by(prob: Problem, name: str, p) -> tuple:
    """The terms whose regressors move with ``name`` (its own; those whose input goes
    through the drift's process for β; those a modifier's parameter changes the
    temperature of): found once per problem by moving ``name`` by half, so a derivative
    recomputes those terms' columns alone (a tanh of a width, a lag's response: the
    others are the same numbers)."""
    deps = prob.x_deps.get(name)
    if deps is None:
        ctx = prob.ctx.bound(prob.model.modifiers)
        moved = {**p, name: 1.5 * p[name]}
        found = []
        for t in prob.model.terms:
            if not t.linear:
                continue
            a, b = t.regressors(p, ctx), t.regressors(moved, ctx)
            if any(not np.array_equal(a[k], b[k]) for k in a):
                found.append(t)
        deps = prob.x_deps[name] = tuple(found)
    return deps


@njit(cache=True, nogil=True)
def _score_run(phi, q, p0, r, rw, u, dphi, dq, dp0, dr, du,  # pragma: no cover - compiled
               x, P, dx, dP, PH, dPH, K, dK, df, g_logf, g_s, P_last, dP_last,
               unsettled):
    """(Σ ∂f/f, Σ ∂(e²/f)) per parameter: the tangent-linear filter of ``u``; its state
    and work arrays (``x`` ... ``unsettled``) as :func:`score_work` allocates them; returns
    ``g_logf`` and ``g_s``, filled in place.

    Steady state as :func:`~gyrostand.core.kalman._kf_run`'s: once two consecutive
    observed samples with the same R start from bit-identical P, and ∂P has settled
    (:data:`DP_SETTLED`), the gains, f and their derivatives are held, and only the states
    and their derivatives are updated.

    P and ∂P are symmetric (diagonal at the start, every update symmetric in a, b): the
    upper triangle is computed and mirrored, the same floating-point numbers as the whole
    square (each entry's products and sums commute exactly); with 2 states 5.4 -> 4.2 ms
    on a 6-h run."""
    n = phi.shape[0]
    d = dphi.shape[0]
    N = u.shape[0]
    for i in range(n):
        P[i, i] = p0[i]
        for j in range(d):
            dP[j, i, i] = dp0[j, i]
    r_last = np.nan
    f = 0.0
    invf = 0.0
    steady = False
    weighted = rw.shape[0] == N
    for k in range(N):
        if np.isnan(u[k]):
            steady = False
            r_last = np.nan
        else:
            rk = r * rw[k] if weighted else r
            if steady and rk != r_last:
                steady = False
            if not steady:
                unsettled[0] += 1.0
                f_last = f
                f = sum_variance(P, PH, rk)  # f = 1'P1 + R_k, PH = P1
                if f <= 0.0:
                    for j in range(d):
                        g_logf[j] = np.nan
                        g_s[j] = np.nan
                    return g_logf, g_s
                invf = 1.0 / f
                for i in range(n):
                    K[i] = PH[i] / f
                for j in range(d):
                    fj = dr[j] * (rw[k] if weighted else 1.0)
                    for i in range(n):
                        s = 0.0
                        for a in range(n):
                            s += dP[j, i, a]
                        dPH[j, i] = s
                        fj += s
                    df[j] = fj
                    for i in range(n):
                        dK[j, i] = (dPH[j, i] - K[i] * fj) / f
                same = rk == r_last and f == f_last
                for a in range(n):
                    for b in range(a, n):
                        if same and P[a, b] != P_last[a, b]:
                            same = False
                        P_last[a, b] = P[a, b]
                # ∂P (P repeated): settled to DP_SETTLED of its size since the last sample
                for j in range(d):
                    big = 0.0
                    moved = 0.0
                    for a in range(n):
                        for b in range(a, n):
                            v = dP[j, a, b]
                            big = max(big, abs(v))
                            moved = max(moved, abs(v - dP_last[j, a, b]))
                            dP_last[j, a, b] = v
                    if moved > DP_SETTLED * big:
                        same = False
                r_last = rk
                steady = same
            hx = 0.0
            for i in range(n):
                hx += x[i]
            e = u[k] - hx
            for j in range(d):
                dhx = 0.0
                for i in range(n):
                    dhx += dx[j, i]
                dej = du[j, k] - dhx
                cj = df[j] * invf
                g_logf[j] += cj
                g_s[j] += (2.0 * e * dej - e * e * cj) * invf
                for i in range(n):
                    dx[j, i] += dK[j, i] * e + K[i] * dej
            for i in range(n):
                x[i] += K[i] * e
            if not steady:
                # P⁺ = P − (P1)(P1)'/f and its derivative (from P, before it changes)
                for j in range(d):
                    for a in range(n):
                        for b in range(a, n):
                            v = dP[j, a, b] + (-(dPH[j, a] * PH[b] + PH[a] * dPH[j, b])
                                               + PH[a] * PH[b] * df[j] / f) / f
                            dP[j, a, b] = v
                            dP[j, b, a] = v
                for a in range(n):
                    for b in range(a, n):
                        v = P[a, b] - PH[a] * PH[b] / f
                        P[a, b] = v
                        P[b, a] = v
        # predict (diagonal F); ∂ from the updated P, x
        for j in range(d):
            for a in range(n):
                dx[j, a] = dphi[j, a] * x[a] + phi[a] * dx[j, a]
        for a in range(n):
            x[a] *= phi[a]
        if not steady:
            for j in range(d):
                for a in range(n):
                    for b in range(a, n):
                        v = ((dphi[j, a] * phi[b] + phi[a] * dphi[j, b]) * P[a, b]
                             + phi[a] * phi[b] * dP[j, a, b])
                        dP[j, a, b] = v
                        dP[j, b, a] = v
                    dP[j, a, a] += dq[j, a]
            for a in range(n):
                for b in range(a, n):
                    v = P[a, b] * (phi[a] * phi[b])
                    P[a, b] = v
                    P[b, a] = v
                P[a, a] += q[a]
    return g_logf, g_s


#: this module's compiled kernels (:mod:`..prewarm` asks numba's cache for them)
KERNELS = (_score_run,)


def warm() -> None:
    """Compile :func:`_score_run` for the argument types :func:`score` passes (a first
    run's second process, :mod:`..prewarm`)."""
    n, d, N = 2, 2, 8
    one = np.ones(n)
    _score_run(0.9 * one, 0.1 * one, one, 0.1, np.zeros(0), np.ones(N), np.zeros((d, n)),
               np.zeros((d, n)), np.zeros((d, n)), np.zeros(d), np.zeros((d, N)),
               *score_work(n, d))
