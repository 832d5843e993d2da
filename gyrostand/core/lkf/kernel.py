"""Compiled pass of the linearised Kalman filter (numba), textbook symbols.

One kernel, :func:`lkf_pass`, runs the LKF of :mod:`gyrostand.core.lkf.filter` over the bins
``k0 .. k1-1`` of a stored record, in place on the filter's state, so the same code serves
one new bin (online) and a re-filter of the whole history after a re-linearisation.

State ``x = [δε, δβ, δθ_in (n_in), δθ_out (n_out), extra processes (n_x)]``, point
``(β₀, θ_in, θ_out)``; the moving point ε₀ is carried in ``st[0]``. Per bin k ≥ 1
(FOH weights ``(φ₀, a0, a1)`` of β₀, MODEL.md Algorithm 2):

    ε₀_k  = φ₀ ε₀_{k−1} + Σ_j θ_in_j (a0 u_j,k−1 + a1 u_j,k)
    δε_k  = φ₀ δε_{k−1} − (a0 e_{k−1} + a1 e_k) δβ + Σ_j (a0 u_j,k−1 + a1 u_j,k) δθ_in_j + w
            e = ε₀ (the paper's column)  or, with ``feedback``, the filtered drift
            e = ε₀ + δε̂ + Σ_j X_j δθ̂_out_j (its level with the output terms at the point)
    x_i,k = φ_i x_i,k−1 + w_i          (extra processes: random walk φ = 1, markov2)
    z_k   = y_k − ε₀_k − Σ_j θ_out_j X_j,k = [1, 0, 0…, X_k, 1…] x_k + v_k

with ``var w = q0``, ``var w_i = qx_i``, ``var v = r``; Joseph-form update.
"""

from __future__ import annotations

import numpy as np

from ..jit import njit
from ..kalman import innovation, joseph_update


@njit(cache=True, nogil=True)
def lkf_pass(y, U, X, th_in, th_out, phi0, a0, a1, q0, r, phix, qx, feedback,
             x, P, st, k0, k1, E, F):  # pragma: no cover - compiled
    """Filter bins ``k0 .. k1-1`` in place on ``x`` (n,), ``P`` (n, n), ``st = [ε₀]``.

    ``y`` (N,) drift (NaN = gap: predict only), ``U`` (N, n_in) the inputs u_j(T_k),
    ``X`` (N, n_out) the output regressors. Bin 0 is the start (no predict; ``x``, ``P``,
    ``st`` hold the prior). Writes the innovation ``E[k]`` and its variance ``F[k]`` (NaN for
    a gap). Returns ``(Σ e²/f, Σ ln f, n)`` over the observed bins of the range.
    """
    n = x.shape[0]
    n_in = U.shape[1]
    n_out = X.shape[1]
    n_x = phix.shape[0]
    o_out = 2 + n_in
    o_x = o_out + n_out
    A = np.zeros((n, n))
    AP = np.empty((n, n))
    PH = np.empty(n)
    K = np.empty(n)
    H = np.zeros(n)
    H[0] = 1.0
    for i in range(n_x):
        H[o_x + i] = 1.0
    s_nis = 0.0
    s_logf = 0.0
    nobs = 0
    eps0 = st[0]
    for k in range(k0, k1):
        if k > 0:
            # moving point and the δε row of F (FOH: the inputs linear between bins)
            drive = 0.0
            for j in range(n_in):
                u = a0 * U[k - 1, j] + a1 * U[k, j]
                drive += th_in[j] * u
                A[0, 2 + j] = u
            eps_prev = eps0
            eps0 = phi0 * eps_prev + drive
            if feedback:
                # the filtered level less the output terms *at the point*: δε and the
                # output corrections are confounded in the level, their sum is not
                ea = eps_prev + x[0]
                eb = eps0 + phi0 * x[0]
                for j in range(n_out):
                    ea += X[k - 1, j] * x[o_out + j]
                    eb += X[k, j] * x[o_out + j]
            else:
                ea = eps_prev
                eb = eps0
            A[0, 0] = phi0
            A[0, 1] = -(a0 * ea + a1 * eb)
            for i in range(1, n):
                A[i, i] = 1.0
            for i in range(n_x):
                A[o_x + i, o_x + i] = phix[i]
            # x = A x: only δε (row 0) and the extra processes change
            s = 0.0
            for j in range(n):
                s += A[0, j] * x[j]
            x[0] = s
            for i in range(n_x):
                x[o_x + i] *= phix[i]
            # P = A P A' + Q, O(n²): A is the identity but for row 0 and the extra
            # processes' diagonal d_i, so with v = A[0,:] P:
            # P00 = v A[0,:]', P0j = v_j d_j, Pij = d_i d_j Pij (i, j > 0)
            for j in range(n):
                s = 0.0
                for m in range(n):
                    s += A[0, m] * P[m, j]
                PH[j] = s
            s = 0.0
            for j in range(n):
                s += PH[j] * A[0, j]
            for i in range(n_x):
                di = phix[i]
                for j in range(1, n):
                    P[o_x + i, j] *= di
                    P[j, o_x + i] *= di
            for j in range(1, n):
                dj = phix[j - o_x] if j >= o_x else 1.0
                P[0, j] = PH[j] * dj
                P[j, 0] = P[0, j]
            P[0, 0] = s + q0
            for i in range(n_x):
                P[o_x + i, o_x + i] += qx[i]
        if np.isnan(y[k]):
            E[k] = np.nan
            F[k] = np.nan
            continue
        # z = y − ε₀ − Σ θ_out X ;  H = [1, 0, 0.., X_k, 1..]
        z = y[k] - eps0
        for j in range(n_out):
            z -= th_out[j] * X[k, j]
            H[o_out + j] = X[k, j]
        e, f = innovation(x, P, H, z, r, PH)
        E[k] = e
        F[k] = f
        if not f > 0.0:
            st[0] = eps0
            return s_nis, -np.inf, nobs
        s_nis += e * e / f
        s_logf += np.log(f)
        nobs += 1
        joseph_update(x, P, H, e, f, r, PH, K, AP, PH)  # (AP, PH: work arrays)
    st[0] = eps0
    return s_nis, s_logf, nobs


@njit(cache=True, nogil=True)
def gm_profile(d, phi, q1, ratio2, p01):  # pragma: no cover - compiled
    """Scale-concentrated likelihood pieces of ``d_k = ε_k + v_k`` (NaN = gap), ε a
    Gauss–Markov process with unit stationary variance ``p01`` at the start, ``q1`` its
    step variance, ``var v = ratio2``. Returns ``(Σ e²/f, Σ ln f, n)``."""
    xm = 0.0
    Pm = p01
    s_nis = 0.0
    s_logf = 0.0
    n = 0
    for k in range(d.shape[0]):
        if k > 0:
            xm = phi * xm
            Pm = phi * phi * Pm + q1
        if np.isnan(d[k]):
            continue
        f = Pm + ratio2
        e = d[k] - xm
        s_nis += e * e / f
        s_logf += np.log(f)
        n += 1
        K = Pm / f
        xm += K * e
        Pm = (1.0 - K) * Pm * (1.0 - K) + K * ratio2 * K
    return s_nis, s_logf, n
