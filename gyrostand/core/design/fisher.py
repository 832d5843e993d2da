"""Fisher information of the exact likelihood and the Cramér–Rao lower bound.

For a Gaussian state-space model with innovations e_k and variances f_k (Harvey 1989,
eq. 3.4.69):

    I_ij = Σ_k [ ½ (∂f_k/∂θ_i)(∂f_k/∂θ_j) / f_k²  +  E{(∂e_k/∂θ_i)(∂e_k/∂θ_j)} / f_k ]

f_k does not depend on the data; ∂e_k/∂θ does (for parameters of the dynamics), so its
expectation is a Monte Carlo average over data simulated at the true parameters. The
derivatives are central differences of the model's own innovations.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..data import Samples
from ..model import Model
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
    names = tuple(free) if free is not None else model.free_names(params)
    params = {**model.defaults, **params}  # a shape parameter left out: its plain one
    scale = max(abs(params[n]) for n in model.names_of_kind("std")) or 1.0
    h = np.array([rel_step * max(abs(params[n]), 1e-3 * scale if model.kind(n) == "std"
                                 else 1e-12) for n in names])
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
