"""Random against deterministic, decided by what each predicts on data it was not fitted on.

A slow deterministic effect (a trend, a warm-up, a lagged response) and a random process
(a rate random walk, a second Markov process) can explain the same record about equally
well; which one is real shows in what each *predicts*. Block cross-validation: the record's
``K`` blocks (:func:`blocks`) are held out in turn; the candidate model is refitted by exact
ML with the block missing (started from its fit to the whole record), and scored by the
log predictive density of the block given the data before it,

    ln p(y_block | y_before; θ̂₋ᵦ) = Σ_{k in block} ln N(e_k; 0, f_k)

(the prediction-error decomposition: the Kalman filter's innovations e_k and their
variances f_k at θ̂₋ᵦ over the block), summed over the blocks (a proper scoring rule: a model is paid for its bands as well as its
mean — a trend fitted where a random walk is real extrapolates a slope the walk does not
keep, with a band too narrow for it; a random walk fitted where a trend is real predicts
each block flat from its start). Measured on 2-h chamber cycles (4 seeds each): a trend
(c = 2e-5) scored above a random walk 3/4, a random walk (q = 5e-3) above a trend 3/4 —
within one record the two are look-alikes at these sizes, so the score decides only which
is proposed first, and the other is tested again after it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ...errors import GyrostandError
from ..data import Samples
from ..ml.fit import ml
from ..model import Model

__all__ = ["BLOCKS", "blocks", "held_out_score"]

#: blocks held out in turn
BLOCKS = 3
#: each block's share of the record
BLOCK_SHARE = 0.15


def blocks(n: int, k: int = BLOCKS, share: float = BLOCK_SHARE) -> list[tuple[int, int]]:
    """``k`` blocks [a, b) of ``share``·n samples, spread over the record's second part
    onwards (each after at least a fifth of the record, so every block is predicted from
    data before it), the last ending at the record's end."""
    length = max(int(share * n), 1)
    first = max(n // 5, 1)
    starts = np.linspace(first, n - length, k).astype(int)
    return [(int(a), int(a) + length) for a in starts]


def held_out_score(samples: Samples, model: Model, start: Mapping[str, float],
                   k: int = BLOCKS) -> float:
    """The held-out log score of ``model``: Σ over :func:`blocks` of ln p(y_block | y
    before it) at the parameters fitted without the block (exact: the prediction-error
    decomposition over the block, Σ_k ln N(e_k; 0, f_k) of the filter run on the whole
    record), higher is better; ``-inf`` when a refit fails."""
    total = 0.0
    for a, b in blocks(len(samples), k):
        y = samples.drift.copy()
        y[a:b] = np.nan
        try:
            r = ml(samples.replace(drift=y), model, start=dict(start), n_local=1,
                   std_errors=False)
        except GyrostandError:
            return float("-inf")
        e, f = model.innovations(r.values, samples)
        e, f = e[a:b], f[a:b]
        ok = np.isfinite(e) & (f > 0)
        total += float(-0.5 * np.sum(np.log(2 * np.pi * f[ok]) + e[ok] ** 2 / f[ok]))
    return total
