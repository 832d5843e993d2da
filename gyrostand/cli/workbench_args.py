"""Arguments shared by the workbench subcommands (diagnose, fit, report)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..workbench import Subject


def add_subject_args(p: Any) -> None:
    p.add_argument("run", help="a run folder, or a CSV with columns t, drift, temp")
    p.add_argument("--gyro", default=None, help="which gyro of a multi-gyro run")
    p.add_argument("--model", default=None,
                   help="start from this model (comma-separated terms) instead of the "
                        "run's current one; default for a CSV: markov,temp,bias")


def subject_of(args: argparse.Namespace) -> Subject:
    from ..workbench import open_subject

    return open_subject(args.run, gyro=args.gyro, model=args.model)


def fmt_estimate(value: float, std: float, unit: str, fixed: bool = False) -> str:
    from ..core.results import UNIT_TEXT

    sd = "fixed" if fixed else f"± {std:.3g}"
    return f"{value:.6g} {sd} {UNIT_TEXT.get(unit, unit)}"
