"""The fixed-interval (Rauch-Tung-Striebel) smoother of the stochastic part of a model,
as two compiled loops of scalars and one batched numpy pseudo-inverse between them.

It is the kernel of :mod:`gyrostand.core.kalman`'s diagonal model (independent scalar
Gauss-Markov / random-walk states observed through their sum), imported from there as
``kf_smooth``. Its compiled parts use loops only: numba's own ``pinv``, ``outer`` and
``sum(axis)`` cost the one-kernel form 11-14 s of compilation on a first run (issue 25),
these loops about a second.
"""

from __future__ import annotations

import numpy as np

from .aot import kernel
from .jit import listen, njit, ready

listen()  # a compilation is shown as progress (jit.watch)


@njit(cache=True, nogil=True, inline="always")
def joseph_finish(P, B, BH, K, r):  # pragma: no cover - compiled
    """P = B (I − K H)' + K r K' with B = (I − K H) P and BH = B H', kept symmetric."""
    n = P.shape[0]
    for i in range(n):
        for j in range(n):
            P[i, j] = B[i, j] - BH[i] * K[j] + K[i] * r * K[j]
    for i in range(n):
        for j in range(i + 1, n):
            s = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = s
            P[j, i] = s


@njit(cache=True, nogil=True, inline="always")
def sum_variance(P, PH, rk):  # pragma: no cover - compiled
    """f = H P H' + R_k for states observed through their sum (H = [1 … 1]), with PH = P H'
    (the row sums of P) written into ``PH``."""
    n = P.shape[0]
    f = rk
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += P[i, j]
        PH[i] = s
        f += s
    return f


@njit(cache=True, nogil=True, inline="always")
def repeats(P, P_last, same):  # pragma: no cover - compiled
    """Whether ``P`` repeats ``P_last`` bit for bit, given ``same`` (the cheaper tests, R
    and f repeated, passed first: P is compared only then); ``P`` copied into ``P_last``.
    The filters' steady state: once it repeats, so does every following P."""
    n = P.shape[0]
    for i in range(n):
        for j in range(n):
            if same and P[i, j] != P_last[i, j]:
                same = False
            P_last[i, j] = P[i, j]
    return same


@njit(cache=True, nogil=True, inline="always")
def joseph_covariance(P, H, K, PH, r, B, BH):  # pragma: no cover - compiled
    """P = (I − K H) P (I − K H)' + K r K' in place, given the gain ``K`` and PH = P H'.

    (I − K H) P = P − K (H P), H P = PH' since P is symmetric; then right-multiplied by
    (I − K H)' (:func:`joseph_finish`). ``B`` (n, n), ``BH`` (n,) work arrays.
    """
    n = P.shape[0]
    for i in range(n):
        for j in range(n):
            B[i, j] = P[i, j] - K[i] * PH[j]
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += B[i, j] * H[j]
        BH[i] = s
    joseph_finish(P, B, BH, K, r)


def writable(a):
    """``a`` as a writable C-contiguous float array: numba compiles a kernel once per
    argument type, and a read-only array (a frozen :class:`~gyrostand.core.data.Samples`'
    column) is another type; one copy of a read-only input costs far less than a second
    compilation (0.9-1.8 s for :func:`~gyrostand.core.kalman.kf_run`)."""
    a = np.ascontiguousarray(a, dtype=float)
    return a if a.flags.writeable else a.copy()


def kf_smooth(phi, q, p0, r, rw, y):
    """Fixed-interval (Rauch-Tung-Striebel) smoother of the diagonal model of
    :func:`~gyrostand.core.kalman.kf_run`.

    Returns ``(s, v)``: the smoothed signal ``s_k = H x_{k|N}`` (sum of the stochastic
    states) and its variance ``v_k = H P_{k|N} H'``, shape (N,). NaN ``y`` = missing.

        forward:  x_{k|k-1}, P_{k|k-1}, x_{k|k}, P_{k|k}   (Joseph form)
        backward: J_k = P_{k|k} F' P_{k+1|k}^+
                  x_{k|N} = x_{k|k} + J_k (x_{k+1|N} - x_{k+1|k})
                  P_{k|N} = P_{k|k} + J_k (P_{k+1|N} - P_{k+1|k}) J_k'

    The two passes are compiled loops of scalars; the gains ``J_k`` are one batched numpy
    pseudo-inverse of the stacked ``P_{k+1|k}`` between them (numba's own ``pinv``,
    ``outer`` and ``sum(axis)`` cost this kernel 11-14 s of compilation on a first run;
    these loops compile in about a second).
    """
    ready("rts")  # a first run: compiled beside this process (.prewarm)
    phi = writable(phi)
    y = writable(y)
    forward = kernel("rts_forward", rts_forward, made_here=True)  # at install, else numba
    xp, Pp, xf, Pf = forward(phi, writable(q), writable(p0), float(r), writable(rw), y,
                             *forward_work(phi.shape[0], y.shape[0]))
    N = xp.shape[0]
    J = np.empty_like(Pf)
    if N > 1:
        J[:-1] = (Pf[:-1] * phi[np.newaxis, np.newaxis, :]) @ np.linalg.pinv(Pp[1:])
    backward = kernel("rts_backward", _rts_backward, made_here=True)
    return backward(xp, Pp, xf, Pf, J, *backward_work(phi.shape[0], y.shape[0]))


def forward_work(n: int, N: int, covariances: bool = True) -> tuple[np.ndarray, ...]:
    """:func:`rts_forward`'s outputs and work arrays for ``n`` states and ``N`` samples,
    allocated here (numba compiles each ``np.zeros``/``np.empty``/``np.ones`` of a kernel
    for its own rank, a first run's cost): ``xp, Pp, xf, Pf, x, P, PH, K, A, AH, ones,
    P_last`` (``ones``: H = [1 … 1], the states are observed through their sum).
    ``covariances=False``: the filtered states alone (``Pp``, ``Pf`` of no samples), which
    lets the kernel hold its steady state."""
    M = N if covariances else 0
    return (np.empty((N, n)), np.empty((M, n, n)), np.empty((N, n)), np.empty((M, n, n)),
            np.zeros(n), np.zeros((n, n)), np.empty(n), np.empty(n), np.empty((n, n)),
            np.empty(n), np.ones(n), np.empty((n, n)))


def backward_work(n: int, N: int) -> tuple[np.ndarray, ...]:
    """:func:`_rts_backward`'s outputs and work arrays (as :func:`forward_work`):
    ``s, v, xs, Ps, d, D, JD``."""
    return (np.empty(N), np.empty(N), np.empty(n), np.empty((n, n)), np.empty(n),
            np.empty((n, n)), np.empty((n, n)))


@njit(cache=True, nogil=True)
def rts_forward(phi, q, p0, r, rw, y,  # pragma: no cover - compiled
                xp, Pp, xf, Pf, x, P, PH, K, A, AH, ones, P_last):
    """The filter of :func:`kf_smooth`: ``x_{k|k-1}, P_{k|k-1}, x_{k|k}, P_{k|k}``, shapes
    (N, n), (N, n, n), (N, n), (N, n, n), written into ``xp, Pp, xf, Pf`` and returned
    (every entry written); where ``y`` is NaN (or the innovation variance is not positive)
    the filtered values are the predicted ones. Work arrays as :func:`forward_work`
    allocates them.

    ``Pp`` and ``Pf`` of no samples (``forward_work(..., covariances=False)``): the states
    alone, and the covariance's steady state held as :func:`~.kalman._kf_run` holds it
    (once two consecutive observed samples with the same R start from bit-identical
    P_{k|k-1}, the gain is the previous one: the same floating-point numbers; a 6-h run's
    pass 1.3 -> 0.3 ms, the model error's 60 replicates)."""
    n = phi.shape[0]
    N = y.shape[0]
    for i in range(n):
        P[i, i] = p0[i]
    weighted = rw.shape[0] == N
    keep = Pp.shape[0] == N
    steady = False
    r_last = np.nan
    f = 0.0
    for k in range(N):
        for i in range(n):
            xp[k, i] = x[i]
        if keep:
            for i in range(n):
                for j in range(n):
                    Pp[k, i, j] = P[i, j]
        if np.isnan(y[k]):
            steady = False
            r_last = np.nan
        else:
            rk = r * rw[k] if weighted else r
            if steady and rk != r_last:
                steady = False
            hx = 0.0
            for i in range(n):
                hx += x[i]
            if not steady:
                # f = H P H' + R_k, H = [1, ..., 1];  K = P H' / f
                f_last = f
                f = sum_variance(P, PH, rk)
                if f > 0.0:
                    for i in range(n):
                        K[i] = PH[i] / f
                if not keep:
                    steady = repeats(P, P_last, rk == r_last and f == f_last and f > 0.0)
                    r_last = rk
            if f > 0.0:  # (else a degenerate variance: the prediction stands)
                e = y[k] - hx  # x = x + K (y - H x)
                for i in range(n):
                    x[i] += K[i] * e
                if not steady:
                    joseph_covariance(P, ones, K, PH, rk, A, AH)
        for i in range(n):
            xf[k, i] = x[i]
        if keep:
            for i in range(n):
                for j in range(n):
                    Pf[k, i, j] = P[i, j]
        # predict: x = F x ;  P = F P F' + Q  (F, Q diagonal; held in steady state)
        for i in range(n):
            x[i] *= phi[i]
        if not steady:
            for i in range(n):
                for j in range(n):
                    P[i, j] *= phi[i] * phi[j]
                P[i, i] += q[i]
    return xp, Pp, xf, Pf


@njit(cache=True, nogil=True)
def _rts_backward(xp, Pp, xf, Pf, J,  # pragma: no cover - compiled
                  s, v, xs, Ps, d, D, JD):
    """The backward pass of :func:`kf_smooth` given the gains ``J_k`` (N, n, n); ``s``
    and ``v`` (N,) filled and returned, work arrays as :func:`backward_work` allocates."""
    N, n = xf.shape
    tot_x = 0.0
    tot_p = 0.0
    for i in range(n):
        xs[i] = xf[N - 1, i]
        tot_x += xs[i]
        for j in range(n):
            Ps[i, j] = Pf[N - 1, i, j]
            tot_p += Ps[i, j]
    s[N - 1] = tot_x
    v[N - 1] = tot_p
    for k in range(N - 2, -1, -1):
        # x_{k|N} = x_{k|k} + J_k (x_{k+1|N} - x_{k+1|k})
        for i in range(n):
            d[i] = xs[i] - xp[k + 1, i]
            for j in range(n):
                D[i, j] = Ps[i, j] - Pp[k + 1, i, j]
        tot_x = 0.0
        for i in range(n):
            a = xf[k, i]
            for j in range(n):
                a += J[k, i, j] * d[j]
            xs[i] = a
            tot_x += a
        # P_{k|N} = P_{k|k} + J_k (P_{k+1|N} - P_{k+1|k}) J_k'
        for i in range(n):
            for j in range(n):
                a = 0.0
                for m in range(n):
                    a += J[k, i, m] * D[m, j]
                JD[i, j] = a
        tot_p = 0.0
        for i in range(n):
            for j in range(n):
                a = Pf[k, i, j]
                for m in range(n):
                    a += JD[i, m] * J[k, j, m]
                Ps[i, j] = a
                tot_p += a
        s[k] = tot_x
        v[k] = tot_p
    return s, v


#: this module's compiled kernels (:mod:`.prewarm` asks numba's cache for them)
KERNELS = (rts_forward, _rts_backward)


def warm() -> None:
    """Compile the smoother's two passes for the argument types :func:`kf_smooth` passes
    (a first run's second process, :mod:`.prewarm`)."""
    one = np.ones(2)
    kf_smooth(0.9 * one, 0.1 * one, one, 0.1, np.zeros(0), np.ones(8))
