"""A deterministic candidate's test where χ² is not its law: next to a random process it
looks like, the LR's distribution is simulated under the current model (a parametric
bootstrap) and its tail taken from the simulated moments (a scaled χ², Satterthwaite).

A random walk's realisation over one record is close to a straight line (the spurious
trends of Nelson & Kang 1981), and its variance's ML estimate piles up at zero in short
records (Shephard & Harvey 1990), so the LR of a ``trend`` in a model that holds a
``random_walk`` is far above χ²(1) when the walk alone is true. Measured on 4-h chamber
cycles (benchmarks/advice_sequence.py's data, 10 seeds each), the LR of a trend added to
the true model: mean 3.4 with a random walk (q = 1e-3) alone and 4.7 with a lagged
temperature beside it, above 3.84 in 4 and 6 of 10 runs (χ²(1): mean 1, 5 %); the
workbench then added the trend after the walk, or the trend instead of it.

The test applies to the pairs of :data:`SIMULATED` (a ``trend`` beside a
``random_walk``): as a candidate of a model that holds the walk, and in the competition
of the two as candidates (:func:`~.competitors.order_competitors`). Each
replicate is the current fit's deterministic part plus a new draw of its random part
(its states, its measurement noise with the bins' weights, the record's missing samples
kept missing), refitted with and without the candidate from the current fit's values.
The replicates' seeds are fixed, so ``diagnose``, ``fit`` and the ledger give the same p.
"""

from __future__ import annotations

import zlib
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ...errors import GyrostandError
from ..chisq import chi2_sf
from ..data import Samples
from ..kalman import first_order_response
from ..ml.fit import ml
from ..model import Model
from ..results import FitResult
from ..threads import one_blas_thread, pool_width
from .prederror import deterministic_part

__all__ = ["SIM_REPLICATES", "SIMULATED", "looks_random", "null_replicate", "simulated_p"]

#: replicates behind a simulated p (their mean and variance fix the scaled χ²)
SIM_REPLICATES = 40
#: the replicates' seed (with the candidate's name and the record's length)
SEED = 20261205


#: (deterministic candidate, random term of the model) where the candidate's LR is referred
#: to its simulated law (the module's docstring). A warm-up beside a walk keeps χ², though
#: χ² is not its law either (its LR added to the true model of a random walk averaged 4.60
#: against χ²(2)'s 2, above its 5 % point in 3 of 12 runs: session 17): with the simulated
#: law the walk that stands in for a missing T² beat the real warm-up — warm-up + T² 19/20
#: -> 16/20 at 20 seeds, for temp_lag + random walk 7/20 -> 8/20
#: (benchmarks/results/advice_sequence.txt, session 17)
SIMULATED = frozenset({("trend", "random_walk")})


def looks_random(model: Model, term: str) -> bool:
    """Whether the deterministic ``term``'s LR against ``model`` is simulated: a random
    term of ``model`` forms a pair of :data:`SIMULATED` with it."""
    return any((term, t.name) in SIMULATED for t in model.terms if t.n_states > 0)


def null_replicate(model: Model, p: dict[str, float], samples: Samples,
                   rng: np.random.Generator, noise: dict[str, float] | None = None
                   ) -> np.ndarray:
    """A new record under ``model``: its deterministic part at ``p``, plus a draw of each
    state (x_0 ~ N(0, p0), x_k = φ x_{k−1} + w_k) and of the measurement noise (variance
    r·w_k) at ``noise`` (default ``p``), missing where ``samples`` is."""
    N = len(samples)
    ss = model.state_space({**p, **(noise or {})}, samples.dt)
    w = samples.noise_weights
    y = deterministic_part(model, p, samples) + rng.standard_normal(N) * np.sqrt(
        ss.r * (w if w.size else np.ones(N)))
    for i in range(ss.phi.size):
        e = rng.standard_normal(N) * np.sqrt(ss.q[i])
        e[0] = rng.standard_normal() * np.sqrt(ss.p0[i])
        y = y + first_order_response(e, float(ss.phi[i]), 0.0, 1.0, float(e[0]))
    y[~np.isfinite(samples.drift)] = np.nan
    return y


def simulated_p(samples: Samples, model: Model, base: FitResult, term: str, lr: float,
                replicates: int = SIM_REPLICATES) -> float | None:
    """P(LR* ≥ ``lr``) for ``model + term`` against ``model`` (fitted as ``base``), LR*
    the LR of replicates under ``base`` (:func:`null_replicate`), from the scaled χ² with
    their mean and variance; None when too few replicates could be fitted.

    The replicates are the null's (a restricted bootstrap). Taking their random part from
    the fit with the candidate instead made the law lighter than χ²'s where the walk was
    real (a lagged temperature and a walk, seed 501: p(trend | random_walk) 0.00085
    against χ²'s 0.0029 and the null's 0.092): a trend fitted beside a walk takes part of
    the walk's wander, and the walk's intensity with it."""
    bigger = model.add(term)
    key = zlib.crc32(f"{term}:{len(samples)}".encode())
    seeds = np.random.default_rng([SEED, key]).integers(2**62, size=replicates)

    def one(seed: int) -> float:
        y = null_replicate(model, dict(base.values), samples, np.random.default_rng(seed))
        s = samples.replace(drift=y)
        try:
            r0 = ml(s, model, start=base.values, grid=False, std_errors=False)
            r1 = ml(s, bigger, start=r0.values, grid=False, n_local=1,
                    std_errors=False)
        except GyrostandError:
            return np.nan
        assert r0.loglik is not None and r1.loglik is not None
        return max(2.0 * (r1.loglik - r0.loglik), 0.0)

    workers = pool_width(4)
    with one_blas_thread():
        if workers > 1:
            with ThreadPoolExecutor(workers, thread_name_prefix="simulated") as pool:
                lrs = np.array(list(pool.map(one, seeds)))
        else:
            lrs = np.array([one(s) for s in seeds])
    lrs = lrs[np.isfinite(lrs)]
    if lrs.size < replicates // 2:
        return None
    m, v = float(lrs.mean()), float(lrs.var(ddof=1))
    if not (m > 0 and v > 0):
        return None
    scale, df = v / (2.0 * m), 2.0 * m * m / v
    return chi2_sf(lr / scale, df)
