"""``gyrostand allan RUN|CSV [--gyro G] [--model TERMS] [--unit U] [--format F]``: the
Allan deviation of a gyro's drift and its IEEE Std 952 figures (angle random walk, bias
instability with its τ, rate random walk, rate ramp) with confidence intervals, for the
raw drift and for the residual after the thermal model (fitted by ML)."""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..plugins import available_terms
from ..runfolder.layout import RESULT
from .common import add_format_args, emit

if TYPE_CHECKING:
    from ..core.diagnose.allan import AllanTable
    from ..workbench import Subject

log = logging.getLogger(__name__)


def add_parser(sub: Any) -> None:
    p = sub.add_parser("allan", help="Allan-variance table (IEEE Std 952: ARW, bias "
                                     "instability, RRW) of the raw drift and the residual",
                       description=__doc__)
    p.add_argument("run", help="a run folder, or a CSV with columns t, drift, temp")
    p.add_argument("--gyro", default=None, help="which gyro of a multi-gyro run")
    p.add_argument("--model", default=None,
                   help="thermal model of the residual (comma-separated terms of: "
                        f"{', '.join(available_terms())}); default the run's current model")
    p.add_argument("--unit", default=None,
                   help="the drift's unit (default: the DBC signal's unit from the run's "
                        "session file, else 'y'); deg/h and deg/s add deg/√h, deg/h/√h")
    p.add_argument("--level", type=float, default=0.95, help="confidence level (0.95)")
    add_format_args(p, "the tables")
    p.set_defaults(func=run)


def _drift_unit(subject: Subject) -> str:
    """The drift signal's unit from the run's session file, when it can be read."""
    if subject.run_dir is None:
        return "y"
    try:
        from ..config import load_config

        info = json.loads((subject.run_dir / RESULT).read_text())
        cfg = load_config(Path(info["config"]))
        return cfg.gyro(subject.gyro).drift.signal.unit or "y"
    except Exception as exc:  # the session file moved, changed, ...: a generic unit
        log.info("drift unit unknown (%s): using 'y'", exc)
        return "y"


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from ..core.diagnose.allan import MIN_SAMPLES
    from ..core.ml.fit import ml
    from ..errors import DataError
    from ..report.views import AllanView
    from ..workbench import open_subject

    subject = open_subject(args.run, gyro=args.gyro, model=args.model)
    n = int(np.count_nonzero(np.isfinite(subject.samples.drift)))
    if n < MIN_SAMPLES:  # before the ML fit, which may fail less clearly on so few
        raise DataError(f"{subject.samples.source}: an Allan table needs at least "
                        f"{MIN_SAMPLES} samples of drift, got {n}")
    unit = args.unit or _drift_unit(subject)
    emit(AllanView.of(subject, ml(subject.samples, subject.model), unit, args.level),
         args.format)
    return 0


def render(tables: list[AllanTable], gyro: str, dt: float) -> str:
    """The tables as text (:func:`gyrostand.report.text.allan`)."""
    from ..report.text import allan
    from ..report.views import AllanView

    raw, resid = tables
    return allan(AllanView(gyro, "", raw.unit, dt, (), raw.level, raw, resid))
