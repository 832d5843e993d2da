"""The workbench's steps: diagnose the subject's model, refit it with terms added or
removed; each step is recorded in the ledger (:mod:`~gyrostand.workbench.ledger`).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..core.chisq import chi2_sf
from ..core.data import Samples
from ..core.design.separation import design_command
from ..core.diagnose.candidates import candidate_terms, step_score, term_test
from ..core.diagnose.prederror import ModelError
from ..core.diagnose.reference import reference_fit
from ..core.diagnose.results import TEST_CHI2, DiagnoseResult
from ..core.diagnose.screen import Score
from ..core.diagnose.verdict import ALPHA, diagnose, fit_error, misfit_error
from ..core.ml.fit import ml
from ..core.model import Model
from ..core.results import FitResult
from ..core.summary import DRIFT_UNIT
from ..errors import GyrostandError, OutputError
from .ledger import append_ledger, ledger_lock
from .subject import Subject, current_model

__all__ = ["fit_summary", "run_diagnose", "FitStep", "run_fit"]

log = logging.getLogger(__name__)


def fit_summary(r: FitResult, error: ModelError | None = None) -> dict[str, Any]:
    """One fit in a before/after: innovation RMS, ln L, model, and the model error
    (open-loop RMS of 60-s means over the run) with the floor the model predicts."""
    d: dict[str, Any] = {"rms": r.residual_rms, "loglik": r.loglik,
                         "model": list(r.model.names), "n_params": len(r.model.param_names)}
    if error is not None:
        d["model_error"] = _finite(error.rms)
        d["model_error_floor"] = _finite(error.floor)
        d["model_error_unit"] = error.unit
    return d


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def run_diagnose(subject: Subject, *, record: bool = True, command: str = "diagnose",
                 screen: bool = True) -> DiagnoseResult:
    """Diagnose the subject's current model; append the step to the ledger. Its stages
    show as ``command``'s progress (:mod:`gyrostand.progress`, on in the CLI only).
    ``screen=False``: refit every candidate (no score screen)."""
    from .. import progress

    with progress.stage(command, f"ML fit of {','.join(subject.model.names)}"):
        fit = ml(subject.samples, subject.model)
    n = len(candidate_terms(subject.model))
    with progress.stage(command, "candidates, reference, residuals, floor",
                        total=n, unit="candidates") as st:
        rep = diagnose(subject.samples, subject.model, base=fit, unit=subject.unit,
                       on_candidate=lambda term: st.update(1), screen=screen)
    if rep.look_alikes:
        rep = with_design_commands(rep, subject)
    if record:
        err = rep.model_error
        try:
            append_ledger(subject.ledger_path, {
                "gyro": subject.gyro, "action": "diagnose",
                "model": list(subject.model.names),
                "rms": rep.diagnosis.rms, "loglik": rep.fit.loglik, "adequate": rep.adequate,
                **({"model_error": _finite(err.rms), "model_error_floor": _finite(err.floor)}
                   if err is not None else {}),
                "ljung_box_p": rep.diagnosis.ljung_box_p,
                "best_candidate": rep.candidates[0].term if rep.candidates else None,
                "parameters": {k: e.to_dict() for k, e in rep.fit.parameters.items()},
            })
        except OutputError as exc:  # a diagnosis is still worth showing (e.g. disk full)
            log.warning("%s (the diagnosis is not in the ledger)", exc)
    return rep


def with_design_commands(rep: DiagnoseResult, subject: Subject) -> DiagnoseResult:
    """``rep`` with each look-alike pair's ``command``: the ``gyrostand design --separate``
    run that tells them apart within this run's limits (:func:`design_command`)."""
    source = subject.run_dir if subject.run_dir is not None else subject.samples.source
    gyro = subject.gyro if subject.origin == "run" else None
    def command(terms: Sequence[str]) -> str:
        a, b = terms
        return design_command(str(source), a, b, subject.samples, subject.model, gyro=gyro)

    return dataclasses.replace(rep, look_alikes=tuple(
        {**la, "command": command(la["terms"])} for la in rep.look_alikes))


@dataclass(frozen=True)
class FitStep:
    """Before/after of one model change."""

    before: FitResult
    after: FitResult
    added: tuple[str, ...]
    removed: tuple[str, ...]
    lr_stat: float
    df: int
    p_value: float
    before_error: ModelError | None = None
    after_error: ModelError | None = None
    #: the p-value's reference distribution (:data:`~gyrostand.core.diagnose.results.TEST_SUP`
    #: …): a one-term step gets the test its candidate gets in ``diagnose``
    test: str = TEST_CHI2

    @property
    def bigger_is_after(self) -> bool:
        """True when the test is of the added terms (the new model is the bigger one)."""
        return self.df > 0 or (self.df == 0 and bool(self.added))

    def to_dict(self) -> dict[str, Any]:
        """``lr_stat`` = 2 (ln L_bigger − ln L_smaller), the test of the smaller model
        (positive when the bigger model fits better, whichever way the step went)."""
        return {
            "model": list(self.after.model.names),
            "added": list(self.added), "removed": list(self.removed),
            "parameters": {k: e.to_dict() for k, e in self.after.parameters.items()},
            "before": fit_summary(self.before, self.before_error),
            "after": fit_summary(self.after, self.after_error),
            "lr_stat": self.lr_stat, "df": self.df, "p_value": self.p_value,
            "test": self.test,
            "warnings": list(self.after.warnings),
            "unit": self.after_error.unit if self.after_error is not None else DRIFT_UNIT,
        }


def changed_model(model: Model, add: Sequence[str], remove: Sequence[str]) -> Model:
    """``model`` with the terms ``remove`` removed and ``add`` added."""
    if not add and not remove:
        raise GyrostandError("fit needs at least one --add TERM or --remove TERM")
    new = model
    if remove:
        new = new.remove(*remove)
    if add:
        new = new.add(*add)
    return new


def fit_step(before: Any, after: Any, add: Sequence[str], remove: Sequence[str],
             samples: Samples | tuple[Samples, ...] | None = None,
             score: Score | None = None, **errors: ModelError | None) -> FitStep:
    """The step from the fit ``before`` to ``after`` (one run's, or a joint fit's: the
    degrees of freedom are the parameters the fits differ by) with its LR test.

    One term added or removed, with the ``samples`` the fits are of: the test ``diagnose``
    gives that term as a candidate (:func:`~gyrostand.core.diagnose.candidates.term_test`:
    the calibrated supremum over a shape, the boundary mixture, one more df for a nuisance
    parameter), so that its df, LR and p are the same numbers in ``diagnose``, ``fit`` and
    the ledger; ``score``: the term's score test at the smaller fit, which guards that
    p as in ``diagnose``, :func:`~gyrostand.core.diagnose.candidates.step_score`).
    Otherwise χ²(df), df the parameters the fits differ by."""
    assert before.loglik is not None and after.loglik is not None
    df = len(after.parameters) - len(before.parameters)
    # the test of the smaller model against the bigger one: LR = 2 (ln L_big − ln L_small)
    lr = 2.0 * (after.loglik - before.loglik)
    if df < 0 or (df == 0 and not add):
        lr = -lr
    test = TEST_CHI2
    if samples is not None and len(add) + len(remove) == 1 and df != 0:
        small, big = (before, after) if add else (after, before)
        df, p, test = term_test(samples, small.model, small, big, (*add, *remove)[0],
                                score=score)
        df = df if add else -df
    else:
        p = chi2_sf(max(lr, 0.0), abs(df)) if df else float("nan")
    return FitStep(before=before, after=after, added=tuple(add), removed=tuple(remove),
                   lr_stat=float(lr), df=df, p_value=p if np.isfinite(p) else 1.0,
                   test=test, **errors)


def run_fit(subject: Subject, add: Sequence[str] = (), remove: Sequence[str] = (),
            *, record: bool = True) -> FitStep:
    """Refit with terms added/removed; before and after side by side; ledger step (the
    ledger held meanwhile, :func:`~.ledger.ledger_lock`: a fit recorded by another command
    since the subject was opened is the starting model)."""
    if not record:
        return _fit(subject, add, remove, record=False)
    with ledger_lock(subject.ledger_path):
        if not subject.model_given:
            subject = dataclasses.replace(subject, model=current_model(
                subject.ledger_path, subject.gyro, subject.model.names))
        return _fit(subject, add, remove, record=True)


def _fit(subject: Subject, add: Sequence[str], remove: Sequence[str], *,
         record: bool) -> FitStep:
    new = changed_model(subject.model, add, remove)
    before = ml(subject.samples, subject.model)
    after = ml(subject.samples, new, start=before.values)
    # each floor from its fit's saturated reference (a misfit cannot inflate it, so the
    # floor does not fall with the error)
    fits = {"before": before, "after": after}
    refs = {k: reference_fit(subject.samples, r.model, r) for k, r in fits.items()}
    score = None
    one = len(add) + len(remove) == 1
    small = "before" if add else "after"
    if one:  # the score test diagnose guards that term's LR with
        score = step_score(subject.samples, fits[small].model, fits[small],
                           (*add, *remove)[0], refs[small])
    step = fit_step(before, after, add, remove, subject.samples, score=score)
    # the term significant at diagnose's level (Bonferroni over the smaller model's
    # candidates) shows the smaller model's misfit, which is judged as diagnose judges it
    # (:func:`misfit_error`)
    level = ALPHA / max(len(candidate_terms(fits[small].model)), 1)
    shown = small if one and step.p_value < level else None
    errors = {k: misfit_error(r, subject.samples, subject.unit, refs[k])[1] if k == shown
              else fit_error(r, subject.samples, subject.unit, refs[k])
              for k, r in fits.items()}
    step = dataclasses.replace(step, before_error=errors["before"],
                               after_error=errors["after"])
    if record:
        append_ledger(subject.ledger_path, {
            "gyro": subject.gyro, "action": "fit", **step.to_dict(),
        })
    return step
