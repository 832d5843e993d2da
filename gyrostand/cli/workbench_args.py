"""Arguments shared by the workbench subcommands (identify, diagnose, fit, report, allan):
one input rule (:mod:`gyrostand.workbench.inputs`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..workbench import Subject


#: what a workbench input may be, for the help of every workbench command
INPUT_HELP = ("a run folder, a samples CSV (t, drift, temp), the Parquet export "
              "(<gyro>/samples.parquet of `gyrostand export --parquet`), or a raw CAN log "
              "(BLF, ASC, MF4, candump .log, ...) with --config")


def add_subject_args(p: Any, several: bool = False, model_help: str | None = None) -> None:
    """The subject's arguments; ``several``: one or more runs of the same gyro (studied
    jointly when more than one)."""
    if several:
        p.add_argument("run", nargs="+",
                       help=f"{INPUT_HELP}; several runs of the same gyro are studied "
                            "jointly (shared physics, each run its own bias and warm-up)")
    else:
        p.add_argument("run", help=INPUT_HELP)
    p.add_argument("--config", default=None, metavar="SESSION.yaml",
                   help="the session file that decodes a raw CAN log (its DBC mapping and "
                        "1-s binning, as replay bins it; the gyros, model and units too)")
    p.add_argument("--gyro", default=None, help="which gyro of a multi-gyro run")
    p.add_argument("--model", default=None,
                   help=model_help or "start from this model (comma-separated terms) instead "
                        "of the run's current one; default for a CSV: markov,temp,bias")
    p.add_argument("--unit", default=None,
                   help="the drift's unit (default: the DBC signal's, through the run's or "
                        "the --config session file; a Parquet export's; 'y' for a CSV that "
                        "names none)")
    p.add_argument("--dt", type=float, default=None,
                   help="a CSV's sampling step in s (default: its most common step; "
                        "missing rows are gaps)")


def subject_of(args: argparse.Namespace) -> Subject:
    from ..workbench import open_subject

    check_run_folder(Path(args.run))
    return open_subject(args.run, gyro=args.gyro, model=args.model,
                        unit=getattr(args, "unit", None), dt=getattr(args, "dt", None),
                        config=getattr(args, "config", None))


def subjects_of(args: argparse.Namespace) -> list[Subject]:
    """Every run of ``args.run`` (a list), as one gyro's subjects."""
    from ..workbench.subject import open_subjects

    for run in args.run:
        check_run_folder(Path(run))
    return open_subjects(args.run, gyro=args.gyro, model=args.model,
                         unit=getattr(args, "unit", None), dt=getattr(args, "dt", None),
                         config=getattr(args, "config", None))


def check_run_folder(path: Path) -> None:
    """A run folder's ``result.json`` has the shape the workbench reads, else a
    :class:`DataError` naming the file and the key (:func:`gyrostand.runfolder.read_result`)."""
    from ..runfolder import RESULT, read_result

    if path.is_dir() and (path / RESULT).is_file():  # else a CSV, or open_subject says
        read_result(path)


def fmt_estimate(value: float, std: float, unit: str, fixed: bool = False,
                 drift_unit: str = "y") -> str:
    """``value ± std unit`` (:func:`gyrostand.report.text.estimate`)."""
    from ..report.text import estimate

    return estimate(value, std, unit, fixed, drift_unit)
