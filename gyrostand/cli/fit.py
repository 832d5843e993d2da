"""``gyrostand fit RUN --add TERM [--add ...] [--remove TERM]``: refit, before/after."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from ..plugins import available_terms
from .common import add_format_args, emit, workbench_command
from .workbench_args import add_subject_args, subject_of, subjects_of

if TYPE_CHECKING:
    from ..workbench import FitStep, Subject


def add_parser(sub: Any) -> None:
    p = sub.add_parser("fit", help="add or remove model terms, refit, show before/after "
                                   "(several runs of one gyro: jointly)")
    add_subject_args(p, several=True)
    terms = ", ".join(available_terms())
    p.add_argument("--add", action="append", default=[], metavar="TERM",
                   help=f"add a model term (repeatable); one of: {terms}")
    p.add_argument("--remove", action="append", default=[], metavar="TERM",
                   help="remove a term of the current model (repeatable; 'white' stays)")
    add_format_args(p, "the step")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..errors import ModelError
    from ..report.views import FitStepView
    from ..workbench import run_fit

    for opt, names in (("--add", args.add), ("--remove", args.remove)):
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:  # a ledger step records each change once
            raise ModelError(f"{opt} {twice[0]} is given {names.count(twice[0])} times")
    both = sorted(set(args.add) & set(args.remove))
    if both:
        raise ModelError(f"{both[0]} is both added (--add) and removed (--remove)")
    if len(args.run) > 1:
        from ..workbench.joint import run_joint_fit

        subjects = subjects_of(args)
        emit(FitStepView(run_joint_fit(subjects, args.add, args.remove),
                         subjects[0].ledger_path), args.format)
        return 0
    args.run = args.run[0]
    subject = subject_of(args)
    step = run_fit(subject, args.add, args.remove)
    emit(FitStepView(step, subject.ledger_path, next_lines(args, subject, step)),
         args.format)
    return 0


def next_lines(args: argparse.Namespace, subject: Subject, step: FitStep) -> tuple[str, ...]:
    """The step after a fit, as lines to paste: ``adopt`` once the new model's verdict is
    ADEQUATE (a diagnose of it in the ledger said so) and its run's session file does not
    hold it yet; else ``diagnose`` for the verdict, naming the adopt to follow."""
    import dataclasses

    from ..workbench import read_ledger
    from ..workbench.advice import adopt_command

    model = step.after.model
    adopt = adopt_command(dataclasses.replace(subject, model=model))
    judged = [e for e in read_ledger(subject.ledger_path)
              if e.get("gyro") == subject.gyro and e.get("action") == "diagnose"
              and set(e.get("model", ())) == set(model.names)]
    if adopt is not None and judged and judged[-1].get("adequate"):
        return (f"next: {adopt}", "      (this model was judged ADEQUATE: adopt writes it "
                "into the run's session file; the daemon uses it from its next run)")
    then = (f"; once ADEQUATE: {adopt}" if adopt is not None else "")
    return (f"next: {workbench_command(args, 'diagnose', skip=('model',))}",
            f"      (the verdict on the new model{then})")


def render(step: FitStep) -> str:
    """The step as text (:func:`gyrostand.report.text.fit_step`)."""
    from ..report.text import fit_step
    from ..report.views import FitStepView

    return fit_step(FitStepView(step))
