"""Physical explanations before random ones: the order in which ``diagnose`` proposes a
deterministic candidate and a random one that explain the same failure (a trend and a rate
random walk, a warm-up and a walk).

Both fitted together, each is tested given the other (the deterministic one by its simulated
law where the random one looks like it, :mod:`.simulated`); where the deterministic one is
not significant given the random one, held-out blocks of the record decide
(:mod:`.crossval`). Where neither is significant given the other the record ties them, and
the table says so, with what tells them apart.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping

from ...errors import GyrostandError
from ..chisq import chi2_sf
from ..data import Samples
from ..ml.fit import ml
from ..model import Model
from ..terms.builtin import separation
from .candidates import extra_df, halved
from .crossval import held_out_score
from .results import Candidate
from .simulated import looks_random, simulated_p

__all__ = ["COMPETITORS_TRIED", "order_competitors"]

log = logging.getLogger(__name__)


#: deterministic candidates tried, in their order, against the best stochastic one
COMPETITORS_TRIED = 3


def _held_out(samples: Samples, model: Model, c: Candidate, cache: dict[str, float]) -> float:
    """:func:`~.crossval.held_out_score` of ``model + c``, once per candidate."""
    if c.term not in cache:
        assert c.result is not None
        cache[c.term] = held_out_score(samples, model.add(c.term), c.result.values)
    return cache[c.term]


def _nested_says_random(samples: Samples, model: Model, d: Candidate, st: Candidate,
                        alpha_each: float, cache: dict[str, float] | None = None) -> bool:
    """Whether ``d`` is not significant once ``st`` is in the model (both fitted together,
    each tested given the other): ``st`` explains the failure as well as ``d`` does, or
    better (``st`` significant given ``d``). Where neither is significant given the other
    they explain the same failure and the data before the nested test cannot tell them
    apart: the held-out blocks decide (:func:`_random_explains_better`). ``d`` given
    ``st`` is referred to its simulated law where ``st`` looks like it (:mod:`.simulated`:
    a trend's LR beside a true random walk averaged 3.4-4.7, not χ²(1)'s 1). ``cache``
    keeps both p-values (keys ``"p:d|st"``, ``"p:st|d"``) for the table's note."""
    both = model.add(d.term, st.term)
    try:
        assert d.result is not None
        r = ml(samples, both, start=d.result.values, n_local=2)
    except GyrostandError:
        return False
    if r.loglik is None:
        return False
    df_d = len(both.param_names) - len(model.add(st.term).param_names)
    df_s = len(both.param_names) - len(model.add(d.term).param_names)
    lr_d = max(2.0 * (r.loglik - st.loglik_after), 0.0)
    lr_s = max(2.0 * (r.loglik - d.loglik_after), 0.0)
    # here the shapes are counted in df: the curvatures of d's shape were measured under
    # the current model, not with st in it (measured: with them, warm-up + (T − T0)²'s
    # warm-up lost to random_walk, p(warmup | random_walk) 0.0077 vs 0.0063 needed)
    p_d = chi2_sf(lr_d, df_d + extra_df(d.term))
    if st.result is not None and looks_random(model.add(st.term), d.term):
        sim = simulated_p(samples, model.add(st.term), st.result, d.term, lr_d)
        p_d = p_d if sim is None else sim
    p_s = chi2_sf(lr_s, df_s + extra_df(st.term))
    if halved(st.term):
        p_s *= 0.5
    log.info("competing %s/%s: p(%s | %s) = %.3g, p(%s | %s) = %.3g", d.term, st.term,
             d.term, st.term, p_d, st.term, d.term, p_s)
    if cache is not None:
        cache[f"p:{d.term}|{st.term}"], cache[f"p:{st.term}|{d.term}"] = p_d, p_s
    return p_d >= alpha_each


def _random_explains_better(samples: Samples, model: Model, d: Candidate, st: Candidate,
                            alpha_each: float, cache: dict[str, float]) -> bool:
    """Whether the stochastic candidate ``st`` goes before the deterministic ``d``: only
    when both kinds of evidence say so — fitted together, ``d`` is not significant given
    ``st`` (:func:`_nested_says_random`), and ``st`` predicts held-out blocks better (:mod:`.crossval`: each refitted without the block, the block's
    log predictive density given the data before it). The held-out score alone put a
    random walk first on a warm-up with a T² effect (each deterministic term alone
    leaves the other's structure, which a walk absorbs); a random walk proposed after a
    trend it explains is tested again at the next diagnosis, where the backward check
    (:func:`~.verdict.redundant_terms`) can name the trend redundant."""
    if not _nested_says_random(samples, model, d, st, alpha_each, cache):
        return False
    e_d, e_s = _held_out(samples, model, d, cache), _held_out(samples, model, st, cache)
    log.info("competing %s/%s: held-out ln p %.2f vs %.2f", d.term, st.term, e_d, e_s)
    return e_s > e_d


def _tie(cache: Mapping[str, float], d: str, st: str, alpha_each: float) -> str:
    """The note's clause on a tie: neither candidate significant given the other (both
    fitted together) — one record cannot rank them by likelihood (a trend of 1e-5 deg/h/s
    against a rate random walk on 4-h runs: on 20 of 20 seeds, benchmarks/results/
    advice_oracle.txt) — with what tells them apart; else nothing."""
    p_d, p_s = cache.get(f"p:{d}|{st}"), cache.get(f"p:{st}|{d}")
    if p_d is None or p_s is None or not (p_d >= alpha_each and p_s >= alpha_each):
        return ""
    apart = separation(d, st)
    return (f"; a tie on this record (neither significant given the other: p {p_d:.2g}, "
            f"{p_s:.2g})" + (f" — {apart}" if apart else ""))


def order_competitors(samples: Samples, model: Model, cands: list[Candidate],
                       alpha_each: float) -> list[Candidate]:
    """Physical explanations before random ones.

    When a deterministic candidate d and a stochastic one s are both significant, d is
    proposed first unless both kinds of evidence favour s (:func:`_random_explains_better`:
    fitted together, d not significant given s while s is given d; and s predicts held-out
    blocks of the record better, :mod:`.crossval`); when s wins, the next deterministic
    candidate is tried (up to :data:`COMPETITORS_TRIED`), and only when none survives is s
    the real one.
    Either way the table says they compete; the other is tested again after the first is
    added.
    """
    sig = [c for c in cands if c.ranked and c.p_value < alpha_each]
    det = [c for c in sig if not c.stochastic]
    sto = [c for c in sig if c.stochastic]
    if not det or not sto:
        return cands
    st = sto[0]
    cache: dict[str, float] = {}
    # the deterministic candidates in their order, until one survives the stochastic one
    # (a flexible effect, e.g. a lagged rate, may lose to it where the true one would not)
    lost = []  # those the stochastic one explains better: below it, not above
    for d in det[:COMPETITORS_TRIED]:
        if not _random_explains_better(samples, model, d, st, alpha_each, cache):
            first = d
            break
        lost.append(dataclasses.replace(d, competes=st.term, note=f"competes with "
                                        f"{st.term}: {st.term} explains it better"))
    else:
        d, first, lost = det[0], st, lost[1:]
    other = st if first is d else d
    held = first.term in cache and other.term in cache
    why = (f"predicts held-out blocks better (ln p {cache[first.term] - cache[other.term]:+.1f}"
           f" over {other.term})" if held else "both explain the failure" if first is d
           else "explains the failure better") + "; proposed first"
    tie = _tie(cache, d.term, st.term, alpha_each)
    why += tie
    marked = {d.term: dataclasses.replace(d, competes=st.term, tied=bool(tie)),
              st.term: dataclasses.replace(st, competes=d.term, tied=bool(tie))}
    marked[first.term] = dataclasses.replace(marked[first.term], note=f"competes with "
                                             f"{other.term}: {why}")
    marked[other.term] = dataclasses.replace(marked[other.term], note=f"competes with "
                                             f"{first.term}: tested again after it")
    # the pair where the better of them stood (a stronger candidate stays above it), then
    # the deterministic ones that lost to the stochastic one (measured: a trend that lost
    # to a walk stayed on top, above the lagged temperature's warm-up that beat it)
    moved = {first.term, other.term, *(x.term for x in lost)}
    at = min(i for i, c in enumerate(cands) if c.term in moved)
    rest = [c for c in cands if c.term not in moved]
    return [*rest[:at], marked[first.term], marked[other.term], *lost, *rest[at:]]
