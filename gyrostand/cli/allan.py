"""``gyrostand allan RUN|CSV|PARQUET|LOG [--config SESSION.yaml] [--gyro G] [--model TERMS]
[--unit U] [--format F]``: the Allan deviation of a gyro's drift and its IEEE Std 952
figures (angle random walk, bias instability with its τ, rate random walk, rate ramp) with
confidence intervals, for the raw drift and for the residual after the thermal model
(fitted by ML)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from ..plugins import available_terms
from .common import add_format_args, emit
from .workbench_args import add_subject_args, subject_of

if TYPE_CHECKING:
    from ..core.diagnose.allan import AllanTable


def add_parser(sub: Any) -> None:
    p = sub.add_parser("allan", help="Allan-variance table (IEEE Std 952: ARW, bias "
                                     "instability, RRW) of the raw drift and the residual",
                       description=__doc__)
    add_subject_args(p, model_help="thermal model of the residual (comma-separated terms "
                                   f"of: {', '.join(available_terms())}); default the run's "
                                   "current model")
    p.add_argument("--level", type=float, default=0.95, help="confidence level (0.95)")
    add_format_args(p, "the tables")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from ..core.diagnose.allan import MIN_SAMPLES
    from ..core.ml.fit import ml
    from ..errors import DataError
    from ..report.views import AllanView

    subject = subject_of(args)
    n = int(np.count_nonzero(np.isfinite(subject.samples.drift)))
    if n < MIN_SAMPLES:  # before the ML fit, which may fail less clearly on so few
        raise DataError(f"{subject.samples.source}: an Allan table needs at least "
                        f"{MIN_SAMPLES} samples of drift, got {n}")
    emit(AllanView.of(subject, ml(subject.samples, subject.model), subject.unit, args.level),
         args.format)
    return 0


def render(tables: list[AllanTable], gyro: str, dt: float) -> str:
    """The tables as text (:func:`gyrostand.report.text.allan`)."""
    from ..report.allan_text import allan
    from ..report.views import AllanView

    raw, resid = tables
    return allan(AllanView(gyro, "", raw.unit, dt, (), raw.level, raw, resid))
