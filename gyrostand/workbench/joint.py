"""The workbench on several runs of one gyro: a joint diagnosis, written to every run's
ledger (:mod:`gyrostand.core.ml.joint` does the numerics)."""

from __future__ import annotations

import logging
from collections.abc import Sequence

from ..core.diagnose.joint import JointDiagnosis, joint_diagnose
from ..core.ml.joint import joint_ml
from ..errors import OutputError
from .ledger import append_ledger
from .steps import FitStep, changed_model, fit_step
from .subject import Subject

__all__ = ["run_joint_diagnose", "run_joint_fit"]

log = logging.getLogger(__name__)


def run_joint_diagnose(subjects: Sequence[Subject], *, record: bool = True) -> JointDiagnosis:
    """Diagnose the runs' common model jointly; append the step to each run's ledger (with
    the runs it was judged with, the shared parameters and that run's own ones)."""
    model = subjects[0].model
    rep = joint_diagnose([s.samples for s in subjects], model, unit=subjects[0].unit)
    if record:
        sources = [s.samples.source for s in subjects]
        for s, run in zip(subjects, rep.fit.runs, strict=True):
            chk = run.info.get("residual_check", {})
            try:
                append_ledger(s.ledger_path, {
                    "gyro": s.gyro, "action": "diagnose", "model": list(model.names),
                    "joint": sources, "loglik": rep.fit.loglik, "adequate": rep.adequate,
                    "ljung_box_p": chk.get("ljung_box_p"),
                    "best_candidate": rep.candidates[0].term if rep.candidates else None,
                    "parameters": {k: e.to_dict() for k, e in run.parameters.items()},
                    "repeatability": (rep.fit.repeatability.to_dict()
                                      if rep.fit.repeatability is not None else None),
                })
            except OutputError as exc:
                log.warning("%s (the diagnosis is not in the ledger)", exc)
    return rep


def run_joint_fit(subjects: Sequence[Subject], add: Sequence[str] = (),
                  remove: Sequence[str] = (), *, record: bool = True) -> FitStep:
    """Refit the runs jointly with terms added/removed: before and after (joint fits), the
    joint LR test (a per-run parameter counted once per run); a step in each run's
    ledger."""
    model = subjects[0].model
    new = changed_model(model, add, remove)
    runs = [s.samples for s in subjects]
    before = joint_ml(runs, model)
    after = joint_ml(runs, new, start=before.values)
    step = fit_step(before, after, add, remove, tuple(runs))
    if record:
        sources = [s.samples.source for s in subjects]
        entry = step.to_dict()
        for s, run in zip(subjects, after.runs, strict=True):
            try:
                append_ledger(s.ledger_path, {
                    "gyro": s.gyro, "action": "fit", **entry, "joint": sources,
                    "parameters": {k: e.to_dict() for k, e in run.parameters.items()},
                })
            except OutputError as exc:
                log.warning("%s (the step is not in the ledger)", exc)
    return step
