"""Seeded, reproducible simulation of any model on a temperature series.

The simulation uses the model's own exact discretisation, so a model fitted to simulated
data sees exactly the process it assumes (and the tests can demand CRLB efficiency).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from .data import Samples
from .model import Model, context
from .profiles import TemperatureProfile


def simulate(
    model: Model,
    params: Mapping[str, float],
    profile: TemperatureProfile | None = None,
    *,
    t: np.ndarray | None = None,
    temp: np.ndarray | None = None,
    dt: float = 1.0,
    duration: float | None = None,
    seed: int | np.random.Generator | None = 0,
) -> Samples:
    """Simulate drift measurements.

    Give either a ``profile`` (sampled every ``dt`` up to ``duration`` or its end) or the
    arrays ``t`` (s) and ``temp`` (degC). ``params`` maps every ``<term>.<param>`` of the
    model to its true value (a shape parameter left out takes its default: e.g. a
    ``temp_rate`` without ``temp_rate.tau`` acts through no thermal lag). Returns :class:`Samples` with ``source`` describing the truth.

    >>> from gyrostand.core.profiles import paper_profile
    >>> m = Model.parse("markov,temp")
    >>> s = simulate(m, {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.01,
    ...                  "white.sigma": 0.0}, paper_profile(), seed=1)
    >>> len(s), s.dt
    (2001, 1.0)
    """
    params = {**model.defaults, **params}  # a shape left out: its plain one
    model.check_params(params)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    if profile is not None:
        t, temp = profile.grid(dt, duration)
    if t is None or temp is None:
        raise ValueError("simulate() needs a profile or both t and temp")
    t = np.asarray(t, dtype=float)
    temp = np.asarray(temp, dtype=float)
    base = Samples.from_arrays(t, np.zeros_like(t), temp, dt=dt, source="simulation")
    X = model.regressors(params, context(base, model))
    theta = np.array([params[n] for n in model.names_of_kind("linear")])
    y = X @ theta if theta.size else np.zeros_like(t)
    ss = model.state_space(params, dt)
    phi, q, p0, r = ss.phi, ss.q, ss.p0, ss.r
    N = t.size
    from scipy.signal import lfilter  # here: scipy.signal imports scipy.stats (0.5 s)

    for i in range(phi.size):
        # x_0 ~ N(0, p0), x_k = phi x_{k-1} + w_k, w_k ~ N(0, q)
        w = rng.standard_normal(N) * np.sqrt(q[i])
        w[0] = rng.standard_normal() * np.sqrt(p0[i])
        y = y + lfilter([1.0], [1.0, -phi[i]], w)
    y = y + rng.standard_normal(N) * np.sqrt(r)
    truth = ", ".join(f"{k}={params[k]:g}" for k in model.param_names)
    return Samples.from_arrays(t, y, temp, dt=dt, source=f"simulation of {model} ({truth})")
