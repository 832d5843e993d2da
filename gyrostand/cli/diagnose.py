"""``gyrostand diagnose RUN``: where the current model fails and which effect is missing."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from .common import add_format_args, emit, workbench_command
from .workbench_args import add_subject_args, subject_of, subjects_of

if TYPE_CHECKING:
    from ..core.diagnose.prederror import ModelError
    from ..core.diagnose.results import DiagnoseResult


def add_parser(sub: Any) -> None:
    p = sub.add_parser("diagnose", help="diagnose the current model of a run (or of several "
                                        "runs of one gyro, jointly) and rank the missing "
                                        "effects")
    add_subject_args(p, several=True)
    add_format_args(p, "the diagnosis")
    p.add_argument("--no-screen", action="store_true",
                   help="refit every candidate term (by default a score test screens them "
                        "first and only those it cannot rule out are refitted)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .. import progress
    from ..report.views import AllanView, DiagnosisView
    from ..workbench import run_diagnose
    from ..workbench.advice import adopt_command

    if len(args.run) > 1:
        from ..workbench.joint import run_joint_diagnose

        emit(run_joint_diagnose(subjects_of(args)), args.format)
        return 0
    args.run = args.run[0]
    subject = subject_of(args)
    rep = run_diagnose(subject, screen=not args.no_screen)
    with progress.stage("diagnose", "Allan tables"):
        allan = AllanView.of_diagnosis(subject, rep)
    emit(DiagnosisView(rep, f"{subject.samples.source} (gyro {subject.gyro})",
                       subject.ledger_path, allan, workbench_command(args, "fit"),
                       adopt_command(subject) if rep.adequate else None),
         args.format)
    return 0


def render(rep: DiagnoseResult, source: str) -> str:
    """The diagnosis as text (:func:`gyrostand.report.text.diagnosis`)."""
    from ..report.text import diagnosis

    return diagnosis(rep, source)


def render_model_error(err: ModelError) -> list[str]:
    """The model error's lines of the text (:func:`gyrostand.report.text.model_error`)."""
    from ..report.text import model_error

    return model_error(err)
