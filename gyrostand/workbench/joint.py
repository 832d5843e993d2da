"""The workbench on several runs of one gyro: a joint diagnosis, written to every run's
ledger (:mod:`gyrostand.core.multirun` does the numerics)."""

from __future__ import annotations

import logging
from collections.abc import Sequence

from ..core.multirun import JointDiagnosis, joint_diagnose
from ..errors import OutputError
from .ledger import append_ledger
from .subject import Subject

__all__ = ["run_joint_diagnose"]

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
