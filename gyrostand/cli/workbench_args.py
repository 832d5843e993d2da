"""Arguments shared by the workbench subcommands (diagnose, fit, report)."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import DataError

if TYPE_CHECKING:
    from ..workbench import Subject


def add_subject_args(p: Any) -> None:
    p.add_argument("run", help="a run folder, or a CSV with columns t, drift, temp")
    p.add_argument("--gyro", default=None, help="which gyro of a multi-gyro run")
    p.add_argument("--model", default=None,
                   help="start from this model (comma-separated terms) instead of the "
                        "run's current one; default for a CSV: markov,temp,bias")
    p.add_argument("--unit", default=None,
                   help="the drift's unit (default: the DBC's for a run, 'y' for a CSV)")
    p.add_argument("--dt", type=float, default=None,
                   help="a CSV's sampling step in s (default: its most common step; "
                        "missing rows are gaps)")


def subject_of(args: argparse.Namespace) -> Subject:
    from ..workbench import open_subject

    check_run_folder(Path(args.run))
    return open_subject(args.run, gyro=args.gyro, model=args.model,
                        unit=getattr(args, "unit", None), dt=getattr(args, "dt", None))


def check_run_folder(path: Path) -> None:
    """A run folder's ``result.json`` has the shape the workbench reads (an object, ``dt``
    a positive number, ``gyros`` an object of objects whose ``model`` is a list of term
    names), else a :class:`DataError` naming the file and the key."""
    result = path / "result.json"
    if not (path.is_dir() and result.is_file()):
        return  # a CSV, or open_subject says what is missing
    try:
        info = json.loads(result.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise DataError(f"{result}: not UTF-8 text (byte {exc.start})") from None
    except json.JSONDecodeError as exc:
        raise DataError(f"{result}: line {exc.lineno}: invalid JSON ({exc.msg})") from None
    except OSError as exc:
        raise DataError(f"{result}: cannot read: {exc.strerror or exc}") from None
    if not isinstance(info, dict):
        raise DataError(f"{result}: expected a JSON object, got {type(info).__name__}")
    dt = info.get("dt", 1.0)
    if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not (
            math.isfinite(dt) and dt > 0):
        raise DataError(f"{result}: dt: expected a positive number of seconds, got "
                        f"{str(dt)[:40]!r}")
    gyros = info.get("gyros", {})
    if not isinstance(gyros, dict) or not all(isinstance(g, dict) for g in gyros.values()):
        raise DataError(f"{result}: gyros: expected an object of gyro objects")
    for name, g in gyros.items():
        model = g.get("model", [])
        if not (isinstance(model, list) and all(isinstance(m, str) for m in model)):
            raise DataError(f"{result}: gyros.{str(name)[:40]}.model: expected a list of "
                            f"term names")


def fmt_estimate(value: float, std: float, unit: str, fixed: bool = False,
                 drift_unit: str = "y") -> str:
    """``value ± std unit`` (:func:`gyrostand.render.text.estimate`)."""
    from ..render.text import estimate

    return estimate(value, std, unit, fixed, drift_unit)
