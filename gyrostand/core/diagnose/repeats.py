"""Whether an effect repeats across runs of the gyro (issue 23 item 4).

A deterministic effect of the gyro — a thermal coefficient, a trend since switch-on — is
the same at every switch-on: that is what makes it worth a term of the model and a
calibration. A random process is not: a rate random walk wanders its own way in each run.
On one record the two can tie (a trend and a walk, benchmarks/results/advice_oracle.txt:
neither significant given the other on 20 of 20 4-h trend runs), and ``diagnose``'s
``next:`` line then asks for a second switch-on. On the runs together a shared trend can
still win by likelihood where the two walks happened to drift the same way for part of
their records (4-h runs of a lag and a walk, seeds 516 and 518: the joint trend LR 57.6
against the walk's 50.2).

What separates them is whether the effect *repeats*: each run is fitted alone with the
candidate, and its linear coefficients are compared across the runs by Cochran's Q (the
inverse-covariance-weighted spread around their common estimate; with covariances V_r of
the k coefficients b_r, b̄ = (Σ V_r⁻¹)⁻¹ Σ V_r⁻¹ b_r and Q = Σ (b_r − b̄)' V_r⁻¹ (b_r − b̄)
~ χ²((R − 1) k) when the runs share one effect). Measured (benchmarks/results/repeats.txt:
pairs of 4-h runs built from frames, benchmarks/advice_sequence.py's data, each run fitted
alone):

* under the true model (clean, a temp_rate, a walk, a warm-up + T², a trend, temp_rate +
  trend; 20 pairs each) 200 tests of the shared terms: p < 0.05 on 10, p < 0.001 on none
  (the smallest 0.0018); a true trend's p ≥ 0.17;
* a trend fitted where a walk is the truth: p < 0.001 on 13 of 20 pairs, and on 11 of 20
  with a lagged temperature beside the walk (518: p 1.4e-4 — a tie the joint likelihood
  decided for the trend).

A significant shared deterministic candidate whose Q is significant at
:data:`REPEAT_ALPHA` is not ranked: its note says that it does not repeat (a random
process, or an event of one run, stands in for it), and the next candidate is proposed.
Where nothing else is significant and the model's random part is its first process alone
(:func:`slow_process`), the verdict says so too: what drives it is missing. With a walk in
the model a shared trend can stay significant and not repeat (518 after the walk: joint p
7.8e-5, Q p 1.3e-4, the two runs' walks drifting the same way): the walk is that wander.
Per-run terms (the turn-on bias, a warm-up: each switch-on its own) and random processes
are not tested; nor is a term without a linear coefficient (a lag).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import GyrostandError
from ..chisq import chi2_sf
from ..data import Samples
from ..ml.fit import ml
from ..ml.joint import JointFit
from ..model import Model
from ..results import FitResult
from ..terms.builtin import TERMS
from .results import Candidate, p_text

__all__ = ["REPEAT_ALPHA", "Repeats", "compared_coefficients", "linear_coefficients",
           "mark_unrepeated", "model_repeats", "per_run_fits", "q_of", "q_statistic",
           "repeat_test", "repeats_table", "shared_effect", "slow_process"]

log = logging.getLogger(__name__)

#: a shared effect whose per-run coefficients differ at this level does not repeat (under
#: the true model none of 200 tests on pairs of 4-h runs went below it)
REPEAT_ALPHA = 0.001


@dataclass(frozen=True)
class Repeats:
    """Cochran's Q of a term's linear coefficients across runs: ``values``/``stds`` per
    run (in the order of ``names``), ``stat`` Q on ``df`` = (runs − 1) × coefficients."""

    term: str
    names: tuple[str, ...]
    values: tuple[tuple[float, ...], ...]
    stds: tuple[tuple[float, ...], ...]
    stat: float
    df: int
    p_value: float
    alpha: float = REPEAT_ALPHA

    @property
    def repeats(self) -> bool:
        """Whether the runs are consistent with one effect (Q not significant)."""
        return not self.p_value < self.alpha

    def per_run(self) -> str:
        """Each coefficient's estimate ± std in each run."""
        return "; ".join(
            f"{n} per run " + ", ".join(f"{v[i]:.3g} ± {s[i]:.2g}"
                                        for v, s in zip(self.values, self.stds, strict=True))
            for i, n in enumerate(self.names))

    def text(self) -> str:
        """The per-run estimates and Q, as the note and the verdict print them."""
        verb = "repeats" if self.repeats else "does not repeat"
        return (f"{verb} across the {len(self.values)} runs (Cochran's Q {self.stat:.1f} on "
                f"{self.df} df, p {p_text(self.p_value)}; {self.per_run()})")

    def row(self) -> str:
        """One line of the table of the model's own shared effects."""
        return (f"  {self.term:<12} Q {self.stat:7.2f} on {self.df} df  p {self.p_value:9.2g}  "
                f"{'repeats' if self.repeats else 'DOES NOT REPEAT'}  ({self.per_run()})")

    def to_dict(self) -> dict[str, Any]:
        return {"term": self.term, "names": list(self.names),
                "values": [list(v) for v in self.values],
                "stds": [list(s) for s in self.stds], "stat": self.stat, "df": self.df,
                "p_value": self.p_value, "alpha": self.alpha, "repeats": self.repeats}


def repeats_table(reps: Sequence[Repeats]) -> list[str]:
    """The text table of the model's own shared effects (a title, a row each, a blank
    line), or no lines."""
    if not reps:
        return []
    return [f"does each shared effect repeat? (each run fitted alone; Cochran's Q, "
            f"p < {reps[0].alpha:.2g}: it does not)", *[r.row() for r in reps], ""]


def linear_coefficients(model: Model, term: str) -> tuple[str, ...]:
    """``term``'s linear coefficients in ``model``."""
    return tuple(n for n, q in model.params if n.split(".")[0] == term and q.kind == "linear")


def shared_effect(term: str) -> bool:
    """Whether ``term`` is a deterministic effect the runs share (not a random process,
    not a per-run term such as the turn-on bias or a warm-up)."""
    cls = TERMS.get(term)
    return cls is not None and cls.n_states == 0 and not getattr(cls, "per_run", False)


def compared_coefficients(model: Model, term: str) -> tuple[str, ...]:
    """The linear coefficients of ``term`` (added to ``model``) whose repetition across
    runs is tested: none for a random process, a per-run term or a term without one."""
    return linear_coefficients(model.add(term), term) if shared_effect(term) else ()


def slow_process(model: Model) -> bool:
    """Whether ``model``'s random part has a process besides its first (a rate random walk,
    a second Markov process): one that a shared effect which does not repeat can be the
    wander of."""
    return sum(TERMS[t].n_states for t in model.names if t in TERMS) > 1


def q_statistic(values: Sequence[np.ndarray], covs: Sequence[np.ndarray]) -> float:
    """Cochran's Q of per-run estimates ``values`` (each k) with covariances ``covs``
    (each k × k) around their inverse-covariance-weighted mean."""
    weights = [np.linalg.inv(c) for c in covs]
    mean = np.linalg.solve(sum(weights), sum(w @ b for w, b in zip(weights, values,
                                                                    strict=True)))
    return float(sum((b - mean) @ w @ (b - mean)
                     for w, b in zip(weights, values, strict=True)))


def per_run_fits(runs: Sequence[Samples], model: Model,
                 starts: Sequence[Mapping[str, float]] | None) -> list[FitResult] | None:
    """``model`` fitted to each run alone by ML (from ``starts``, each run's values in a
    joint fit: one local search; else from ML's start grid), or None if a fit fails."""
    out = []
    for i, s in enumerate(runs):
        start = starts[i] if starts is not None else None
        try:
            out.append(ml(s, model, start=start, grid=start is None, n_local=1,
                          hessian_passes=1))
        except GyrostandError as exc:
            log.info("%s: each run alone not fitted: %s", s.source, exc)
            return None
    return out


def q_of(term: str, names: tuple[str, ...], fits: Sequence[FitResult],
         alpha: float = REPEAT_ALPHA) -> Repeats | None:
    """Cochran's Q of the coefficients ``names`` of ``term`` over per-run ``fits`` (their
    covariance blocks); None where a fit has no usable covariance for them."""
    values, covs = [], []
    for r in fits:
        if r.covariance is None or any(n not in r.cov_names for n in names):
            return None
        idx = [r.cov_names.index(n) for n in names]
        cov = np.asarray(r.covariance)[np.ix_(idx, idx)]
        if not np.all(np.isfinite(cov)) or np.any(np.diag(cov) <= 0):
            return None
        values.append(np.array([r.value(n) for n in names]))
        covs.append(cov)
    stat = q_statistic(values, covs)
    df = (len(fits) - 1) * len(names)
    return Repeats(term=term, names=names,
                   values=tuple(tuple(float(x) for x in v) for v in values),
                   stds=tuple(tuple(float(x) for x in np.sqrt(np.diag(c))) for c in covs),
                   stat=stat, df=df, p_value=float(chi2_sf(stat, df)), alpha=alpha)


def repeat_test(runs: Sequence[Samples], model: Model, cand: Candidate,
                alpha: float = REPEAT_ALPHA) -> Repeats | None:
    """Cochran's Q of ``cand``'s linear coefficients over ``runs``, each run refitted
    alone with the candidate (from its own values in the candidate's joint fit); None
    where the term is not tested (:func:`compared_coefficients`) or a run's fit fails."""
    names = compared_coefficients(model, cand.term)
    if not names or len(runs) < 2:
        return None
    joint_runs = getattr(cand.result, "runs", None)
    fits = per_run_fits(runs, model.add(cand.term),
                        [r.values for r in joint_runs] if joint_runs is not None else None)
    return q_of(cand.term, names, fits, alpha) if fits is not None else None


def model_repeats(runs: Sequence[Samples], model: Model, fit: JointFit,
                  alpha: float = REPEAT_ALPHA) -> tuple[Repeats, ...]:
    """Whether each shared effect of ``model`` itself repeats across ``runs``: the model
    fitted to each run alone (from its values in the joint ``fit``), Cochran's Q of each
    shared deterministic term's linear coefficients, at ``alpha`` over the terms tested
    (Bonferroni). One that does not means one value for every switch-on does not describe
    the runs (an effect the term stands in for is missing, or the runs differ)."""
    terms = [t for t in model.names if shared_effect(t) and linear_coefficients(model, t)]
    if len(runs) < 2 or not terms:
        return ()
    fits = per_run_fits(runs, model, [r.values for r in fit.runs])
    if fits is None:
        return ()
    out = (q_of(t, linear_coefficients(model, t), fits, alpha / len(terms)) for t in terms)
    return tuple(r for r in out if r is not None)


def mark_unrepeated(runs: Sequence[Samples], model: Model, cands: Sequence[Candidate],
                    alpha_each: float) -> list[Candidate]:
    """``cands`` with each ranked shared deterministic candidate significant at
    ``alpha_each`` tested for repetition across ``runs`` (:func:`repeat_test`; its result
    kept in ``repeats``); one that does not repeat is not ranked and its note says why."""
    out = []
    for c in cands:
        if c.ranked and c.p_value < alpha_each:
            rep = repeat_test(runs, model, c)  # None for a term it does not compare
            if rep is not None:
                note = c.note if rep.repeats else (
                    f"{rep.text()}: not an effect of the gyro — a random process or one "
                    "run's event stands in for it")
                c = dataclasses.replace(c, repeats=rep, note=note)
        out.append(c)
    return out
