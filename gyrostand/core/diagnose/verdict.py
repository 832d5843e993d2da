"""The diagnosis of a model and its verdict, judged against a reference a misfit cannot move.

:func:`diagnose` fits the model (unless given the fit), ranks the candidate terms
(:mod:`.candidates`), fits the saturated reference (:mod:`.reference`) and measures the
model error with the floor drawn from the *reference's* random part. The verdict is
``adequate`` when

* the innovations are white (Ljung–Box p ≥ 0.01),
* no candidate is significant at 5 % after a Bonferroni correction for the number tried,
* the open-loop model error lies at the reference's floor (below its 99 % point), and
* the lack of fit against the reference is not significant (p ≥
  :data:`~.reference.LACK_OF_FIT_ALPHA`), and
* the drift shows no level shift against the reference (a bias jump: p ≥
  :data:`~.shift.SHIFT_ALPHA`, :mod:`.shift`), and its innovations no periodic line
  (Fisher's test, p ≥ :data:`~.periodic.PERIODIC_ALPHA`, :mod:`.periodic`).

When the lack of fit stays significant and no vocabulary term is, the effect is outside
the vocabulary: the reasons say which shape the reference finds (its partial effects of
T, of dT/dt and of time) and that a plugin term of that shape is the next step; so do they
for a level shift, which no smooth shape holds (the step at its instant), and for a
periodic disturbance (a sine and a cosine at its period).
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import ExitStack
from typing import Any

from ...errors import DataError, GyrostandError
from ..data import Samples
from ..ml.fit import ml
from ..ml.joint_problem import base_name
from ..model import Model, context
from ..results import FitResult
from ..summary import DRIFT_UNIT
from ..validate import prepare
from .candidates import (
    MIN_DIAGNOSE_SAMPLES,
    look_alikes,
    rank_candidates,
    refit_from_candidates,
    term_test,
)
from .competitors import order_competitors
from .diagnostics import ResidualDiagnostics, diagnose_fit, segments
from .periodic import Periodic, periodic
from .prederror import ModelError, model_error
from .reference import (
    REPORT_ALPHA,
    Reference,
    misfit_floor,
    reference_fit,
    second_start,
)
from .results import Candidate, DiagnoseResult, p_text
from .shift import LevelShift, level_shift, whitened
from .standin import mark_stand_ins

log = logging.getLogger(__name__)


def lack_of_fit_text(ref: Reference) -> str:
    """One line: the lack-of-fit test."""
    return (f"lack of fit against the saturated reference: LR {ref.lr:.1f} on {ref.df} df, "
            f"p {p_text(ref.p_value)}")


def describe_missing(ref: Reference, unit: str) -> list[str]:
    """Plain lines on what shape is missing: each significant group's peak effect."""
    out = []
    for q in ref.missing():
        x, e, s = q.peak()
        xs = f"{x:.3g} {q.unit}" if not math.isnan(x) else "?"
        out.append(f"{q.group}: {e:+.3g} ± {s:.2g} {unit} at {q.variable} = {xs} "
                   f"(Wald {q.wald:.1f} on {q.df} df)")
    return out


def fit_error(fit: FitResult, samples: Samples, unit: str = DRIFT_UNIT,
              reference: Reference | None = None) -> ModelError:
    """The model error (open-loop and h-step, window means) of ``fit`` on ``samples``; its
    floor from ``reference``'s random part (:func:`reference_fit`: its own where the lack
    of fit is significant, else the fit's)."""
    used = prepare(samples, "model error")
    noise = (reference.noise_model, reference.noise) if reference is not None else None
    return model_error(fit.model, fit.values, used, segments(context(used, None)), unit=unit,
                       noise=noise)


def misfit_error(fit: FitResult, samples: Samples, unit: str, ref: Reference | None,
                 err: ModelError | None = None) -> tuple[Reference | None, ModelError]:
    """The reference and model error of ``fit`` where a significant term has shown a
    misfit (a candidate of ``diagnose``, the term of a ``fit`` step): the floor the
    reference's where the misfit moved the fit's random part
    (:func:`~.reference.misfit_floor`), and the headline's unexplained part its size
    (:meth:`~.prederror.ModelError.misfit_shown`). ``err``: ``fit``'s error with ``ref``'s
    floor, if already made (it is remade only where the floor moves)."""
    moved = misfit_floor(ref, fit)
    if moved is not None or err is None:
        ref = moved or ref
        err = fit_error(fit, samples, unit, ref)
    return ref, err.misfit_shown()


#: the candidates' family level (``diagnose``'s default ``alpha``: Bonferroni over them)
ALPHA = 0.05


def _reference(samples: Samples, fit: FitResult) -> Reference | None:
    """The saturated reference of ``fit`` (one run only)."""
    return reference_fit(samples, fit.model, fit) if not isinstance(samples, tuple) else None


def checks(fit: FitResult, samples: Samples, unit: str, ref: Reference | None
           ) -> tuple[ResidualDiagnostics, ModelError, LevelShift | None, Periodic | None]:
    """The residual diagnostics of ``fit``, its model error with the floor of its
    reference ``ref``, and against ``ref`` the largest level shift and the strongest
    periodic line."""
    at = whitened(samples, ref)
    return (diagnose_fit(fit, samples), fit_error(fit, samples, unit, ref),
            level_shift(samples, ref, at=at), periodic(samples, ref, at=at))


#: notes on a degenerate optimum: at least this many candidates, every LR this small
DEGENERATE_MIN, DEGENERATE_LR = 3, 1e-6


def verdict_reasons(diag: ResidualDiagnostics, err: ModelError, ref: Reference | None,
                    sig: list[Candidate], alpha: float, m: int, unit: str,
                    shift: LevelShift | None = None,
                    cycle: Periodic | None = None) -> list[str]:
    """Why the model is not adequate (empty: it is)."""
    reasons = []
    if cycle is not None and cycle.significant:
        reasons.append(
            f"a periodic disturbance of the drift {cycle.text(unit)}: no term of the "
            "vocabulary has this shape — an effect outside the vocabulary (the chamber's "
            "compressor or fan cycling, a vibration); a plugin sine and cosine at that "
            "period is the next step (README: plugins)"
            + (", then the candidates judged again" if sig else ""))
    if shift is not None and shift.significant:
        reasons.append(
            f"a level shift of the drift {shift.text(unit)}: no term of the vocabulary has "
            "this shape — an effect outside the vocabulary (a bias jump: a shock, a power or "
            "mode change at that time); a plugin step at that instant is the next step "
            "(README: plugins)" + (", then the candidates judged again (they are measured "
                                   "with the jump in the data)" if sig else ""))
    if not diag.white:
        reasons.append(f"innovations are not white (Ljung–Box p = {diag.ljung_box_p:.2g} "
                       f"over {diag.lags} lags)")
    if sig:
        reasons.append(f"{', '.join(c.term for c in sig)} significant at {alpha:g} "
                       f"(Bonferroni over {m} candidates: p < {alpha / m:.2g})")
    if not err.at_floor():
        h = err.headline()
        reasons.append(
            f"the open-loop model error ({h['window_s']:g}-s means) is {h['rms']:.3g} "
            f"{unit}, above its floor {h['floor']:.3g} (99 % point {h['floor_limit']:.3g}): "
            "the model does not predict the drift from the temperature")
    if ref is not None and (ref.significant or (reasons and not sig and ref.reported)):
        shape = describe_missing(ref, unit)
        where = f" (the reference finds {'; '.join(shape)})" if shape else ""
        level = "" if ref.significant else (
            f" (at the report's level {REPORT_ALPHA:g}; the verdict's alone is {ref.alpha:g})")
        if sig:
            reasons.append(f"{lack_of_fit_text(ref)}{where}")
        else:
            # also where another check failed and the lack of fit stands at the report's
            # level only: a sharp step in T left non-white innovations and p 0.0013, and
            # the advice had no next step
            reasons.append(
                f"{lack_of_fit_text(ref)}{level}{where}: no term of the vocabulary explains "
                "it — an effect outside the vocabulary; a plugin term of that shape is the "
                "next step (README: plugins)")
    return reasons


#: the terms of the paper's model, never proposed for removal
CORE_TERMS = ("markov", "temp", "white", "bias")


def redundant_terms(samples: Samples | tuple[Samples, ...], model: Model, fit: FitResult,
                    alpha: float = ALPHA) -> list[dict[str, Any]]:
    """The terms of an adequate model that no longer earn their place: each term beyond
    :data:`CORE_TERMS` that no other term requires is removed and the smaller model
    refitted; a term whose test against the smaller model (the one it would get as a
    candidate there, :func:`~.candidates.term_test`) has p ≥ ``alpha`` is listed (term,
    lr_stat, df, p_value, test). Forward selection alone keeps what an earlier step added
    before the real effects were in: a random walk proposed first for a warm-up with a T²
    effect stayed after both were added (benchmarks/advice_sequence.py). ``samples`` a
    tuple: several runs of the gyro, each smaller model fitted jointly (``fit`` their
    joint fit)."""
    out = []
    needed = {r for t in model.terms for r in t.requires}
    for term in model.names:
        if term in CORE_TERMS or term in needed:
            continue
        smaller = model.remove(term)
        start = {k: v for k, v in fit.values.items()
                 if base_name(k) in smaller.param_names}  # a run's own copy: name@k
        try:
            if isinstance(samples, tuple):
                from ..ml.joint import joint_ml
                small: FitResult = joint_ml(samples, smaller, start=start,  # type: ignore[assignment]
                                            hessian_passes=1)
            else:
                small = ml(samples, smaller, start=start)
            df, p, test = term_test(samples, smaller, small, fit, term)
        except GyrostandError as exc:
            log.info("removal of %s not tested: %s", term, exc)
            continue
        assert fit.loglik is not None and small.loglik is not None
        if p >= alpha:
            out.append({"term": term, "lr_stat": max(2 * (fit.loglik - small.loglik), 0.0),
                        "df": df, "p_value": p, "test": test})
    return out


def diagnose(samples: Samples, model: Model, *, base: FitResult | None = None,
             alpha: float = ALPHA, terms: list[str] | None = None,
             unit: str = DRIFT_UNIT,
             on_candidate: Callable[[str], None] | None = None,
             screen: bool = True) -> DiagnoseResult:
    """Fit ``model`` by ML (unless ``base`` is given), diagnose it, rank the candidates
    (``screen``: refit only those a score test cannot rule out, :mod:`.screen`).

    A significant candidate whose effect is not identified sends the current model back to
    a refit from that candidate's optimum; if the current fit rises, every candidate is
    recomputed (at most twice) and a note says so. ``on_candidate(term)``: called as each
    candidate's refit ends (a progress count).
    """
    if samples.n_observed < MIN_DIAGNOSE_SAMPLES:
        raise DataError(
            f"{samples.source}: {samples.n_observed} observed samples are too few to judge "
            f"a model (diagnose needs at least {MIN_DIAGNOSE_SAMPLES})")
    fit = base if base is not None else ml(samples, model)
    first = fit
    notes: list[str] = []
    cands: list[Candidate] = []
    # the reference first: its random part is a second start of the candidate refits
    ref = _reference(samples, fit)
    with ExitStack() as stack:
        # the residual checks and the model error of the current fit need no candidate:
        # from the main thread they run beside the refits
        early: Future | None = None
        if threading.current_thread() is threading.main_thread():
            side = stack.enter_context(
                ThreadPoolExecutor(max_workers=1, thread_name_prefix="diagnose"))
            early = side.submit(checks, first, samples, unit, ref)
        for _ in range(3):
            cands = rank_candidates(samples, model, fit, terms, also=second_start(ref), alpha=alpha,
                                    on_done=on_candidate, screen=screen)
            m = max(len(cands), 1)
            alpha_each = alpha / m
            better = refit_from_candidates(samples, model, fit, cands, alpha_each)
            if better is None or len(notes) >= 2:
                break
            assert better.loglik is not None and fit.loglik is not None
            notes.append(f"the current fit was not at its maximum; refitted (ln L "
                         f"{fit.loglik:.2f} → {better.loglik:.2f}) and every candidate "
                         "recomputed")
            fit = better
            ref = _reference(samples, fit)
        m = max(len(cands), 1)
        alpha_each = alpha / m
        # a random process standing in for a misfit of temperature is not ranked, before
        # it competes with anything (:mod:`.standin`)
        cands = order_competitors(samples, model, mark_stand_ins(cands, ref, alpha_each),
                                  alpha_each)
        if early is not None and fit is first:
            diag, err, shift, cycle = early.result()
        else:
            diag, err, shift, cycle = checks(fit, samples, unit, ref)
    if len(cands) >= DEGENERATE_MIN and all(c.lr_stat < DEGENERATE_LR for c in cands):
        notes.append("every candidate's LR is 0: the fit sits at a degenerate optimum (each "
                     "refit, started also from the saturated reference's random part, "
                     "found nothing above it); judge it by the reference's lack of fit")
    sig = [c for c in cands if c.ranked and c.p_value < alpha_each]
    if sig:  # a significant candidate shows a misfit
        ref, err = misfit_error(fit, samples, unit, ref, err)
    reasons = verdict_reasons(diag, err, ref, sig, alpha, m, unit, shift, cycle)
    return DiagnoseResult(model=model, fit=fit, diagnosis=diag, candidates=tuple(cands),
                  adequate=not reasons, alpha=alpha,
                  redundant=tuple(redundant_terms(samples, model, fit, alpha))
                  if not reasons else (),
                  look_alikes=tuple(look_alikes(cands, alpha_each)), reasons=tuple(reasons),
                  model_error=err, notes=tuple(notes), unit=unit, reference=ref,
                  level_shift=shift, periodic=cycle)
