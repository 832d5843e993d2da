"""A random candidate standing in for a deterministic misfit of temperature.

A slow random process added to a model that misses a static effect of temperature (a
cubic in T, outside the vocabulary) absorbs part of that misfit as a wander, and its LR is
significant: a second Markov process took LR 11-23 on 20 of 20 4-h runs with a hidden
cubic, a rate random walk up to 19 (benchmarks/advice_sequence.py's "cubic in T").
Proposed, it hides the missing shape — the advice ended "+markov2" or "+temp2, markov2,
temp_rate" on 9 of 20 seeds, and the user never heard that the effect lies outside the
vocabulary.

The saturated reference (:mod:`.reference`) tells the two apart by where the missing
effect lives. Its partial effects split the lack of fit into a function of temperature, of
its rate and of the time since switch-on. A random walk, a trend or a warm-up (what a
slow random process can be) load on the time group: its Wald statistic was 9.6-203 on 3
df on 16 of 16 runs with a hidden walk or trend (at the reference's 1 % level on 15). With
a hidden cubic it was 1.0-7.6 (p > 0.05 on 8 of 8) while the temperature group stood at
94-375 on 8-9 df. So a random candidate is not ranked when

* the lack of fit is significant (:attr:`.Reference.significant`),
* the reference finds the missing effect in temperature or its rate and not in time since
  switch-on (the time group is in the basis and not significant), and
* the lack of fit stays beside the candidate: its LR taken from the lack of fit's
  (``LR_ref − LR_c``, a lower bound of the lack of fit of the model with the candidate:
  the reference with the candidate fits at least as well as the reference) is still
  significant at the reference's level — a random process that explains the whole misfit
  (a true second correlation time, whose wander the basis also absorbs) stays ranked.

The candidate keeps its LR and p in the table with a note saying why it is not ranked; the
verdict then names the lack of fit, with its shape, as an effect outside the vocabulary.
"""

from __future__ import annotations

import dataclasses

from ..chisq import chi2_sf
from .candidates import ordered
from .reference import FREE_LR_SCALE, Reference
from .results import Candidate

__all__ = ["mark_stand_ins", "stands_in"]


def stands_in(c: Candidate, ref: Reference | None, alpha_each: float) -> str:
    """Why the random candidate ``c``, significant at ``alpha_each``, stands in for a
    deterministic misfit of temperature that the reference ``ref`` shows (the note's
    text), or ``""`` when it does not."""
    if ref is None or not c.stochastic or not c.ranked or not c.p_value < alpha_each \
            or not ref.significant:
        return ""
    groups = {q.group: q for q in ref.partial}
    time = groups.get("time")
    if time is None or time.significant:
        return ""
    where = [q for q in ref.partial if q.group != "time" and q.significant]
    if not where:
        return ""
    rest = max(ref.lr - c.lr_stat, 0.0)
    p_rest = chi2_sf(rest / FREE_LR_SCALE, ref.df)
    if not p_rest < ref.alpha:
        return ""
    names = " and ".join(f"{q.variable}" for q in where)
    return (f"stands in for a deterministic effect of {names}: the reference finds the "
            f"missing effect there, not in time since switch-on (Wald {time.wald:.1f} on "
            f"{time.df} df, p {time.p_value:.2g}), and the lack of fit stays beside it (LR "
            f">= {rest:.1f} on {ref.df} df, p {p_rest:.2g}): not ranked")


def mark_stand_ins(cands: list[Candidate], ref: Reference | None,
                   alpha_each: float) -> list[Candidate]:
    """``cands`` with each significant random candidate that :func:`stands_in` marked (not ranked, the
    note saying why), in :func:`~.candidates.ordered`'s order."""
    out = []
    changed = False
    for c in cands:
        why = stands_in(c, ref, alpha_each)
        if why:
            c = dataclasses.replace(c, stand_in=True, note=why)
            changed = True
        out.append(c)
    return ordered(out, alpha_each) if changed else out
