"""Fisher information of the exact likelihood and the Cramér–Rao lower bound.

For a Gaussian state-space model with innovations e_k and variances f_k (Harvey 1989,
eq. 3.4.69):

    I_ij = Σ_k [ ½ (∂f_k/∂θ_i)(∂f_k/∂θ_j) / f_k²  +  E{(∂e_k/∂θ_i)(∂e_k/∂θ_j)} / f_k ]

f_k does not depend on the data; ∂e_k/∂θ does (for parameters of the dynamics), so its
expectation is a Monte Carlo average over data simulated at the true parameters. The
derivatives are central differences of the model's own innovations.

Split by what a temperature program can change (:func:`information`, the design search's):
the data are y = μ(θ; T) + n with the noise n independent of the temperature record T, and
the filter is linear in the data, so ∂e/∂θ = −K_θ(∂μ/∂θ) + (∂K_θ/∂θ) n — a part m fixed
by the program and a part with zero mean that does not depend on it. Hence, exactly,

    I(T) = I_mean(T) + I_noise,   I_mean = Σ_k m_k m_k' / f_k,   m = K_θ(∂μ/∂θ),
    I_noise = ½ Σ_k ∂f ∂f' / f² + E{Σ_k (∂K_θ/∂θ n)_k (∂K_θ/∂θ n)_k' / f_k},

the cross terms vanishing in expectation. I_mean is one Kalman pass over the columns of
∂μ/∂θ (no simulation); I_noise is the same for every program on the grid (a Monte Carlo
average computed once and reused by every profile a search evaluates).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence

import numpy as np

from ..data import Samples
from ..kalman import NO_WEIGHTS, kf_innovations, kf_run
from ..model import Model, context
from ..simulation import simulate


def fisher_information(
    model: Model,
    params: Mapping[str, float],
    t: np.ndarray,
    temp: np.ndarray,
    *,
    dt: float = 1.0,
    free: Sequence[str] | None = None,
    n_mc: int = 100,
    seed: int = 12345,
    rel_step: float = 1e-4,
) -> tuple[np.ndarray, tuple[str, ...]]:
    """Expected Fisher information of the ``free`` parameters (default: all but a shape
    parameter held at its plain default, :meth:`Model.free_names`).

    Returns ``(I, names)`` with ``I`` of shape (p, p). Parameters not in ``free`` are
    taken as known (e.g. ``markov.sigma`` in the paper's setting).
    """
    names, params, h = _steps(model, params, free, rel_step)
    p = len(names)
    rng = np.random.default_rng(seed)

    def shifted(i: int, sign: float) -> dict[str, float]:
        q = dict(params)
        q[names[i]] += sign * h[i]
        return q

    I_e = np.zeros((p, p))
    df = None
    for _ in range(n_mc):
        s = simulate(model, params, t=t, temp=temp, dt=dt, seed=rng)
        de = np.empty((s.t.size, p))
        dfs = np.empty((s.t.size, p))
        for i in range(p):
            ep, fp = model.innovations(shifted(i, +1), s)
            em, fm = model.innovations(shifted(i, -1), s)
            de[:, i] = (ep - em) / (2 * h[i])
            dfs[:, i] = (fp - fm) / (2 * h[i])
        _, f = model.innovations(params, s)
        I_e += (de / f[:, None]).T @ de
        df = (dfs, f)
    assert df is not None
    dfs, f = df
    I_f = 0.5 * (dfs / f[:, None] ** 2).T @ dfs
    info = I_e / n_mc + I_f
    return 0.5 * (info + info.T), names


def _steps(model: Model, params: Mapping[str, float], free: Sequence[str] | None,
           rel_step: float) -> tuple[tuple[str, ...], dict[str, float], np.ndarray]:
    """The free names, every parameter's value, and each free one's difference step."""
    names = tuple(free) if free is not None else model.free_names(params)
    params = {**model.defaults, **params}  # a shape parameter left out: its plain one
    scale = max(abs(params[n]) for n in model.names_of_kind("std")) or 1.0
    h = np.array([rel_step * max(abs(params[n]), 1e-3 * scale if model.kind(n) == "std"
                                 else 1e-12) for n in names])
    return names, params, h


def _mean(model: Model, q: Mapping[str, float], base: Samples) -> np.ndarray:
    """μ(θ) on the record's temperature: the model's regressors times its linear part."""
    X = model.regressors(q, context(base, model))
    theta = np.array([q[n] for n in model.names_of_kind("linear")])
    return X @ theta if theta.size else np.zeros(len(base))


def mean_information(model: Model, params: Mapping[str, float], t: np.ndarray,
                     temp: np.ndarray, *, dt: float = 1.0, free: Sequence[str] | None = None,
                     rel_step: float = 1e-4, still: Collection[str] = ()
                     ) -> tuple[np.ndarray, tuple[str, ...]]:
    """I_mean of the module docstring: exact, no simulation; the part of the information a
    temperature program changes. ``still``: parameters the mean does not depend on
    (:func:`mean_free`), whose column of ∂μ/∂θ is 0 without differencing."""
    names, params, h = _steps(model, params, free, rel_step)
    base = Samples.from_arrays(np.asarray(t, float), np.zeros(len(t)), np.asarray(temp, float),
                               dt=dt)
    D = np.zeros((len(base), max(len(names), 1)))
    linear = model.names_of_kind("linear")
    X = model.regressors(params, context(base, model)) if linear else None
    for i, n in enumerate(names):
        if X is not None and n in linear:  # ∂μ/∂θ of a linear coefficient: its regressor
            D[:, i] = X[:, linear.index(n)]
            continue
        if n in still:
            continue
        up, down = dict(params), dict(params)
        up[n] += h[i]
        down[n] -= h[i]
        D[:, i] = (_mean(model, up, base) - _mean(model, down, base)) / (2 * h[i])
    ss = model.state_space(params, dt)
    G = kf_run(ss.phi, ss.q, ss.p0, ss.r, NO_WEIGHTS, D, False)[2]  # Σ m m' / f
    G = G[:len(names), :len(names)]
    return 0.5 * (G + G.T), names


def mean_free(model: Model, params: Mapping[str, float], t: np.ndarray, temp: np.ndarray,
              *, dt: float = 1.0, free: Sequence[str] | None = None, rel_step: float = 1e-4
              ) -> tuple[str, ...]:
    """The noise levels (kind ``std``) of ``free`` the mean response does not depend on:
    by the term contract a noise level is not in the mean, and this checks it on ``temp``
    (μ bit-for-bit the same at θ ± h). Their columns of ∂μ/∂θ are exactly 0 on any
    program, so :func:`mean_information` may skip their differences (``still``): the same
    information, in ~3/7 of the regressor evaluations for the design's usual model."""
    names, params, h = _steps(model, params, free, rel_step)
    base = Samples.from_arrays(np.asarray(t, float), np.zeros(len(t)), np.asarray(temp, float),
                               dt=dt)
    out = []
    for i, n in enumerate(names):
        if model.kind(n) != "std":
            continue
        up, down = dict(params), dict(params)
        up[n] += h[i]
        down[n] -= h[i]
        if np.array_equal(_mean(model, up, base), _mean(model, down, base)):
            out.append(n)
    return tuple(out)


def noise_information(model: Model, params: Mapping[str, float], n: int, *,
                      dt: float = 1.0, free: Sequence[str] | None = None, n_mc: int = 40,
                      seed: int = 12345, rel_step: float = 1e-4
                      ) -> tuple[np.ndarray, tuple[str, ...]]:
    """I_noise of the module docstring for a record of ``n`` samples (no gaps): the same
    for every temperature program; a Monte Carlo average over ``n_mc`` noise records."""
    names, params, h = _steps(model, params, free, rel_step)
    p = len(names)
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    flat = np.zeros(n)
    mu = _mean(model, params, Samples.from_arrays(t, flat, flat, dt=dt))

    def filt(q: Mapping[str, float], y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ss = model.state_space(q, dt)
        E, f = kf_innovations(ss.phi, ss.q, ss.p0, ss.r, y[:, None])
        return E[:, 0], f

    # parameters that change the filter (the others: ∂K/∂θ = 0 and ∂f/∂θ = 0)
    moves = [i for i, nm in enumerate(names)
             if not _same_filter(model, params, nm, h[i], dt)]
    I_e = np.zeros((p, p))
    _, f = filt(params, flat)
    dfs = np.zeros((n, p))
    for i in moves:
        up, down = dict(params), dict(params)
        up[names[i]] += h[i]
        down[names[i]] -= h[i]
        dfs[:, i] = (filt(up, flat)[1] - filt(down, flat)[1]) / (2 * h[i])
    for _ in range(n_mc if moves else 0):
        noise = simulate(model, params, t=t, temp=flat, dt=dt, seed=rng).drift - mu
        dn = np.zeros((n, p))
        for i in moves:
            up, down = dict(params), dict(params)
            up[names[i]] += h[i]
            down[names[i]] -= h[i]
            dn[:, i] = (filt(up, noise)[0] - filt(down, noise)[0]) / (2 * h[i])
        I_e += (dn / f[:, None]).T @ dn
    I_f = 0.5 * (dfs / f[:, None] ** 2).T @ dfs
    info = I_e / max(n_mc, 1) + I_f
    return 0.5 * (info + info.T), names


def _same_filter(model: Model, params: Mapping[str, float], name: str, h: float,
                 dt: float) -> bool:
    up = dict(params)
    up[name] += h
    a, b = model.state_space(params, dt), model.state_space(up, dt)
    return bool(np.array_equal(a.phi, b.phi) and np.array_equal(a.q, b.q)
                and np.array_equal(a.p0, b.p0) and a.r == b.r)


def information(model: Model, params: Mapping[str, float], t: np.ndarray, temp: np.ndarray,
                *, dt: float = 1.0, free: Sequence[str] | None = None,
                noise: np.ndarray | None = None, n_mc: int = 40, seed: int = 12345,
                still: Collection[str] = ()) -> tuple[np.ndarray, tuple[str, ...]]:
    """The expected information split as in the module docstring: I_mean on ``temp``
    plus I_noise (``noise``: one computed before for this grid, reused; else computed
    here from ``n_mc`` records)."""
    I_m, names = mean_information(model, params, t, temp, dt=dt, free=free, still=still)
    if noise is None:
        noise = noise_information(model, params, len(t), dt=dt, free=free, n_mc=n_mc,
                                  seed=seed)[0]
    return I_m + noise, names


def crlb(model: Model, params: Mapping[str, float], t: np.ndarray, temp: np.ndarray, *,
         dt: float = 1.0, free: Sequence[str] | None = None, n_mc: int = 100,
         seed: int = 12345) -> dict[str, float]:
    """√CRLB of each free parameter: the smallest std any unbiased estimator can have."""
    info, names = fisher_information(model, params, t, temp, dt=dt, free=free, n_mc=n_mc,
                                  seed=seed)
    C = np.linalg.inv(info)
    return {n: float(np.sqrt(C[i, i])) for i, n in enumerate(names)}


def crlb_for(samples: Samples, model: Model, params: Mapping[str, float], **kw) -> dict:
    """:func:`crlb` on the time grid and temperature of ``samples``."""
    return crlb(model, params, samples.t, samples.temp, dt=samples.dt, **kw)
