"""Compiled Kalman-filter kernels (numba), textbook symbols.

Two kernels:

* :func:`kf_innovations` — the exact-likelihood filter of the stochastic part of a model:
  independent scalar Gauss-Markov / random-walk states ``x_i`` with
  ``x_{i,k} = phi_i x_{i,k-1} + w_{i,k}``, ``w ~ N(0, q_i)``, ``x_{i,0} ~ N(0, p0_i)``,
  observed as ``y_k = sum_i x_{i,k} + v_k``, ``v_k ~ N(0, r·w_k)``. The weight ``w_k``
  (``rw``) scales the measurement noise of sample k: a bin mean of n_k frames has
  ``w_k = n̄/n_k`` (an empty ``rw`` means every ``w_k = 1``). It filters several data
  columns at once with the same gains (the gains do not depend on the data), which is how
  the linear parameters are concentrated out of the likelihood by GLS (de Jong 1991).
* :func:`kf_step` — one predict + update of a general small filter (the LKF).

Both use the Joseph-form covariance update, which keeps ``P`` symmetric positive
semi-definite in floating point.
"""

from __future__ import annotations

import numpy as np

from .aot import kernel
from .jit import listen, njit, ready
from .rts import forward_work, joseph_covariance, repeats, rts_forward, sum_variance, writable
from .rts import kf_smooth as kf_smooth

listen()  # a compilation is shown as progress (jit.watch)


@njit(cache=True, nogil=True, inline="always")
def innovation(x, P, H, z, r, PH):  # pragma: no cover - compiled
    """The innovation of a scalar measurement ``z`` and its variance; fills ``PH``.

    PH = P H' ;  e = z − H x ;  f = H P H' + r
    """
    n = x.shape[0]
    hx = 0.0
    f = r
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += P[i, j] * H[j]
        PH[i] = s
        hx += H[i] * x[i]
    for i in range(n):
        f += H[i] * PH[i]
    return z - hx, f


@njit(cache=True, nogil=True, inline="always")
def joseph_update(x, P, H, e, f, r, PH, K, B, BH):  # pragma: no cover - compiled
    """The measurement update after :func:`innovation`, in place (Joseph form).

    K = P H' / f ;  x = x + K e ;  P = (I − K H) P (I − K H)' + K r K'

    ``K`` (n,), ``B`` (n, n) and ``BH`` (n,) are work arrays (``BH`` may be ``PH``: it is
    written once ``PH`` is used up): B = (I − K H) P = P − K (H P), H P = PH' since P is
    symmetric, and BH = B H'.
    """
    n = x.shape[0]
    for i in range(n):
        K[i] = PH[i] / f
        x[i] += K[i] * e
    joseph_covariance(P, H, K, PH, r, B, BH)


def kf_run(phi, q, p0, r, rw, Y, store):
    """Filter every column of ``Y`` (shape (N, m)) with the same gains: see
    :func:`_kf_run`, to which this passes writable arrays (one compiled version) and its
    outputs and work arrays, allocated here (:func:`kf_work`)."""
    Y = writable(Y)
    phi = writable(phi)
    run = kernel("kf_run", _kf_run, made_here=True)  # compiled at install, else numba's
    return run(phi, writable(q), writable(p0), float(r), writable(rw), Y, bool(store),
               *kf_work(phi.shape[0], Y.shape[0], Y.shape[1], bool(store)))


def kf_work(n: int, N: int, m: int, store: bool) -> tuple[np.ndarray, ...]:
    """:func:`_kf_run`'s outputs and work arrays for ``n`` states and ``Y`` (N, m),
    allocated here: numba compiles each ``np.zeros``/``np.empty``/``np.ones`` of a kernel
    for its own rank, a first run's cost. ``X, P, E, f, G, e_row, PH, K, A, AH, ones,
    P_last, Bk, T``: zeros where the kernel reads them first; ``E`` and ``f`` (N, m), (N,)
    only when ``store``; ``Bk`` a block of rows and ``T`` its Gram product only for a wide
    ``Y``."""
    NE = N if store else 0
    return (np.zeros((n, m)), np.zeros((n, n)), np.empty((NE, m)), np.empty(NE),
            np.zeros((m, m)), np.empty(m), np.empty(n), np.empty(n), np.empty((n, n)),
            np.empty(n), np.ones(n), np.empty((n, n)),
            np.empty((BLOCK if m >= WIDE else 0, m)), np.empty((m, m) if m >= WIDE else (0, 0)))


#: rows of whitened innovations gathered before one product into the Gram matrix, for
#: a ``Y`` of at least :data:`WIDE` columns (the saturated reference's ~25: its filter
#: pass 30 -> 14 ms on a 6-h run); narrower ones (a model's own 3-10) keep the sample-by-
#: sample sum, where a block product costs more than it saves (and their fits stay the
#: same numbers to the last bit)
BLOCK = 256
WIDE = 16


@njit(cache=True, nogil=True)
def _kf_run(phi, q, p0, r, rw, Y, store,  # pragma: no cover - compiled
            X, P, E, f_out, G, e_row, PH, K, A, AH, ones, P_last, Bk, T):
    """Filter every column of ``Y`` (shape (N, m)) with the same gains; its outputs, state
    and work arrays (``X`` ... ``T``) as :func:`kf_work` allocates them.

    ``rw`` (N,) or empty: weight of each sample's measurement noise, R_k = r·rw_k.

    Column 0 is the measurement ``y`` and columns 1.. the regressors; a NaN in column 0
    marks a missing sample (predict only). Returns ``(E, f, G, slogf, nobs)``:

    * ``E`` (N, m): innovations ``e_k = Y_k - H x_{k|k-1}`` (NaN where missing), and
      ``f`` (N,): their variance ``f_k = H P_{k|k-1} H' + r`` — only when ``store``,
      else empty arrays (the likelihood needs no (N, m) array);
    * ``G = sum_k e_k e_k' / f_k`` (m, m) — only when not ``store`` (else zeros: who
      keeps E makes what it needs of it), ``slogf = sum_k ln f_k`` and ``nobs`` over
      the observed samples (``slogf = -inf`` if some ``f_k <= 0``).

    Steady state, exactly: the covariance recursion P_{k+1|k} = F (I − K_k H) P_{k|k−1} ...
    is a fixed function of P_{k|k−1} and R_k. Once two consecutive observed samples with
    the same R start from bit-identical P_{k|k−1}, every following one (until a missing
    sample or another R) does too, so its f, ln f and K are the previous ones: they are
    reused instead of recomputed (the same floating-point numbers; on a 6-h run the
    Riccati recursion reaches its fixed point within a few hundred samples).
    """
    n = phi.shape[0]
    N, m = Y.shape
    for i in range(n):
        P[i, i] = p0[i]
    slogf = 0.0
    nobs = 0
    # P_last: P_{k|k-1} of the last observed sample, r_last its R (NaN: the last sample
    # was not observed); ones: H = [1 … 1], the states are observed through their sum
    r_last = np.nan
    steady = False
    f = 0.0
    logf = 0.0
    weighted = rw.shape[0] == N
    wide = m >= WIDE
    nb = 0
    sf = 0.0
    for k in range(N):
        missing = np.isnan(Y[k, 0])
        if missing:
            steady = False
            r_last = np.nan
            if store:
                for c in range(m):
                    E[k, c] = np.nan
                f_out[k] = np.nan
        else:
            rk = r * rw[k] if weighted else r
            if steady and rk != r_last:
                steady = False
            if not steady:
                f_last = f
                # f = H P H' + R_k, with H = [1, ..., 1]
                f = sum_variance(P, PH, rk)
                if f <= 0.0:
                    return E, f_out, G, -np.inf, nobs
                logf = np.log(f)
                sf = 1.0 / np.sqrt(f)
                # K = P H' / f
                for i in range(n):
                    K[i] = PH[i] / f
                steady = repeats(P, P_last, rk == r_last and f == f_last)
                r_last = rk
            slogf += logf
            nobs += 1
            # e = y - H x ;  x = x + K e
            for c in range(m):
                hx = 0.0
                for i in range(n):
                    hx += X[i, c]
                e = Y[k, c] - hx
                e_row[c] = e
                for i in range(n):  # update, then predict: x = F (x + K e)
                    X[i, c] = (X[i, c] + K[i] * e) * phi[i]
            if store:
                f_out[k] = f
                for c in range(m):
                    E[k, c] = e_row[c]
            if store:
                pass  # the caller reads E and f: no Gram matrix (m² a sample)
            elif wide:
                # G += e e' / f by blocks: the rows e / sqrt(f) gathered, then one
                # matrix product a block (BLAS), not m(m+1)/2 divisions a sample
                for c in range(m):
                    Bk[nb, c] = e_row[c] * sf
                nb += 1
                if nb == BLOCK:
                    _gram_block(G, Bk, T)
                    nb = 0
            else:
                for a in range(m):
                    for c in range(a, m):
                        G[a, c] += e_row[a] * e_row[c] / f
            if not steady:
                # Joseph form: P = (I - K H) P (I - K H)' + K R K'
                joseph_covariance(P, ones, K, PH, rk, A, AH)
        # predict: x = F x (an observed sample's x was predicted with its update) ;
        # P = F P F' + Q  (F, Q diagonal; P unchanged in steady state)
        if missing:
            for i in range(n):
                for c in range(m):
                    X[i, c] *= phi[i]
        if not steady:
            for i in range(n):
                for j in range(n):
                    P[i, j] *= phi[i] * phi[j]
                P[i, i] += q[i]
    if nb > 0:
        _gram_block(G, Bk[:nb], T)
    for a in range(m):  # exactly symmetric, as the solves downstream expect
        for c in range(a):
            G[a, c] = G[c, a]
    return E, f_out, G, slogf, nobs


@njit(cache=True, nogil=True)
def _gram_block(G, B, T):  # pragma: no cover - compiled
    """G += B' B (one BLAS product; the last, partial block is passed as its filled rows:
    a row count passed beside the block made numba compile this twice, once for the
    literal 0 it saw while typing, 0.18 s of a first run). A function of its own, not
    written in :func:`_kf_run`'s loop: there, the product's call made the narrow columns'
    sample loop about 12 % slower (the same numbers either way)."""
    np.dot(B.T, B, T)  # into T (m, m): no array allocated here
    m = G.shape[0]
    for a in range(m):
        for c in range(m):
            G[a, c] += T[a, c]


NO_WEIGHTS = np.zeros(0)


def kf_innovations(phi, q, p0, r, Y, rw=None):
    """Innovations ``E`` (N, m) of every column of ``Y`` and their variances ``f`` (N,)."""
    E, f, _, _, _ = kf_run(phi, q, p0, r, NO_WEIGHTS if rw is None else rw,
                           np.ascontiguousarray(Y, dtype=float), True)
    return E, f


def kf_filtered_states(phi, q, p0, r, rw, y):
    """Filtered states ``x_{k|k}`` (N, n) of the diagonal model of :func:`kf_run`.

    NaN ``y`` = missing (the state is then the prediction ``x_{k|k-1}``). The h-step
    prediction of the signal from time k is ``sum_i phi_i^h x_{i,k|k}``. The smoother's
    forward pass computes them (one compiled kernel for both: a first run compiles one
    less).
    """
    ready("rts")  # a first run: compiled beside this process (.prewarm)
    phi, y = writable(phi), writable(y)
    forward = kernel("rts_forward", rts_forward, made_here=True)
    return forward(phi, writable(q), writable(p0), float(r), writable(rw), y,
                   *forward_work(phi.shape[0], y.shape[0], covariances=False))[2]


def first_order_response(u, phi, a0, a1, x0):
    """x_0 = x0; x_k = phi x_{k-1} + a0 u_{k-1} + a1 u_k: :func:`_first_order_response`
    on a writable ``u``."""
    u = writable(u)
    response = kernel("first_order_response", _first_order_response, made_here=True)
    return response(u, float(phi), float(a0), float(a1), float(x0), np.empty(u.shape[0]))


@njit(cache=True, nogil=True)
def _first_order_response(u, phi, a0, a1, x0, x):  # pragma: no cover - compiled
    """x_0 = x0; x_k = phi x_{k-1} + a0 u_{k-1} + a1 u_k  (exact discretisation, FOH input),
    written into ``x`` (as long as ``u``; allocated by the caller, no allocation compiled
    here) and returned."""
    N = u.shape[0]
    x[0] = x0
    for k in range(1, N):
        x[k] = phi * x[k - 1] + a0 * u[k - 1] + a1 * u[k]
    return x


@njit(cache=True, nogil=True)
def kf_step(x, P, A, Qd, H, r, z):  # pragma: no cover - compiled
    """One Kalman predict (if ``A`` given) + update, in place. Returns ``(e, f)``.

    predict:  x = A x ;  P = A P A' + diag(Qd)
    update:   e = z - H x ; f = H P H' + r ; K = P H' / f ; x = x + K e
              P = (I - K H) P (I - K H)' + K r K'      (Joseph form)
    A NaN ``z`` skips the update and returns ``(nan, nan)``.
    """
    n = x.shape[0]
    if A.shape[0] == n:
        xn = np.zeros(n)
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += A[i, j] * x[j]
            xn[i] = s
        AP = np.zeros((n, n))
        for i in range(n):
            for j in range(n):
                s = 0.0
                for k in range(n):
                    s += A[i, k] * P[k, j]
                AP[i, j] = s
        for i in range(n):
            x[i] = xn[i]
            for j in range(n):
                s = 0.0
                for k in range(n):
                    s += AP[i, k] * A[j, k]
                P[i, j] = s
            P[i, i] += Qd[i]
    if np.isnan(z):
        return np.nan, np.nan
    PH = np.zeros(n)
    e, f = innovation(x, P, H, z, r, PH)
    joseph_update(x, P, H, e, f, r, PH, np.empty(n), np.empty((n, n)), np.zeros(n))
    return e, f


def foh_weights(beta: float, dt: float) -> tuple[float, float, float]:
    """Exact discretisation of dx/dt = -beta x + u(t) with u linear between samples.

    Returns ``(phi, a0, a1)`` with ``phi = exp(-beta dt)``,
    ``a0 = int_0^dt e^{-beta s} (s/dt) ds`` (weight of u_{k-1}) and
    ``a1 = int_0^dt e^{-beta s} (1 - s/dt) ds`` (weight of u_k), so that
    ``x_k = phi x_{k-1} + a0 u_{k-1} + a1 u_k``; ``a0 + a1 = (1 - phi)/beta``.
    """
    x = beta * dt
    phi = float(np.exp(-x))
    total = dt * (-np.expm1(-x) / x) if x != 0.0 else dt
    if abs(x) < 1e-3:
        # 1 - e^{-x}(1 + x) = x^2/2 - x^3/3 + x^4/8 - x^5/30 + ...
        a0 = dt * (0.5 - x / 3.0 + x * x / 8.0 - x**3 / 30.0)
    else:
        a0 = (1.0 - phi * (1.0 + x)) / (beta * x)
    return phi, float(a0), float(total - a0)
