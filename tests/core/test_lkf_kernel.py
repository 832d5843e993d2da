"""The compiled LKF pass against a dense numpy transcription of its documented equations."""

import numpy as np
import pytest

from gyrostand.core.kalman import foh_weights
from gyrostand.core.lkf.kernel import lkf_pass


def dense_pass(y, U, X, th_in, th_out, phi0, a0, a1, q0, r, phix, qx, feedback, x, P, eps0):
    """x, P, ε₀ after the bins of y (bin 0 the start), with A, Q, H built in full."""
    n_in, n_out, n_x = U.shape[1], X.shape[1], phix.size
    n = 2 + n_in + n_out + n_x
    o_out, o_x = 2 + n_in, 2 + n_in + n_out
    E = np.full(y.size, np.nan)
    for k in range(y.size):
        if k > 0:
            u = a0 * U[k - 1] + a1 * U[k]
            e_prev, eps0 = eps0, phi0 * eps0 + th_in @ u
            ea, eb = e_prev, eps0
            if feedback:
                ea = e_prev + x[0] + X[k - 1] @ x[o_out:o_x]
                eb = eps0 + phi0 * x[0] + X[k] @ x[o_out:o_x]
            A = np.eye(n)
            A[0, 0], A[0, 1], A[0, 2:o_out] = phi0, -(a0 * ea + a1 * eb), u
            A[o_x:, o_x:] = np.diag(phix)
            Q = np.zeros(n)
            Q[0], Q[o_x:] = q0, qx
            x, P = A @ x, A @ P @ A.T + np.diag(Q)
        if np.isnan(y[k]):
            continue
        H = np.zeros(n)
        H[0], H[o_out:o_x], H[o_x:] = 1.0, X[k], 1.0
        z = y[k] - eps0 - th_out @ X[k]
        f = H @ P @ H + r
        K = P @ H / f
        E[k] = z - H @ x
        x = x + K * E[k]
        IKH = np.eye(n) - np.outer(K, H)
        P = IKH @ P @ IKH.T + r * np.outer(K, K)
    return x, P, eps0, E


@pytest.mark.parametrize("feedback", [False, True])
def test_kernel_matches_dense_equations(feedback):
    rng = np.random.default_rng(5)
    N, n_in, n_out, n_x = 60, 2, 2, 2
    y = rng.normal(size=N)
    y[[7, 30, 31]] = np.nan  # gaps: predict only
    U = rng.normal(size=(N, n_in)) + 20
    X = rng.normal(size=(N, n_out))
    th_in, th_out = np.array([0.01, -0.002]), np.array([0.3, 1.5])
    phi0, a0, a1 = foh_weights(0.05, 1.0)
    phix, qx = np.array([1.0, 0.99]), np.array([1e-4, 2e-3])
    n = 2 + n_in + n_out + n_x
    M = rng.normal(size=(n, n))
    P0 = M @ M.T / n + np.eye(n) * 0.1
    ref = dense_pass(y, U, X, th_in, th_out, phi0, a0, a1, 0.01, 0.04, phix, qx, feedback,
                     np.zeros(n), P0.copy(), 0.7)
    x, P, st = np.zeros(n), P0.copy(), np.array([0.7])
    E, F = np.empty(N), np.empty(N)
    lkf_pass(y, U, X, th_in, th_out, phi0, a0, a1, 0.01, 0.04, phix, qx, feedback, x, P, st,
             0, 20, E, F)
    lkf_pass(y, U, X, th_in, th_out, phi0, a0, a1, 0.01, 0.04, phix, qx, feedback, x, P, st,
             20, N, E, F)  # in two pieces: the online use
    np.testing.assert_allclose(x, ref[0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(P, ref[1], rtol=1e-9, atol=1e-12)
    assert st[0] == pytest.approx(ref[2], rel=1e-12)
    np.testing.assert_allclose(E, ref[3], rtol=1e-9, atol=1e-12)
    assert np.isnan(E[7]) and np.isnan(F[30])
