"""The workbench's subject: one gyro's 1-s series and the model under study.

A *subject* is opened from

* a run folder written by ``gyrostand run``/``replay`` (``result.json`` names the gyros and
  their configured models; ``<gyro>/samples.csv`` holds the bins; read through
  :mod:`gyrostand.runfolder`), or
* a plain CSV with columns ``t, drift, temp`` (the model then comes from ``--model``).

Several runs of one gyro (:func:`open_subjects`) are studied together under one model
(:mod:`~gyrostand.workbench.joint`).

The current model of a gyro is the model of its last ledger step
(:mod:`~gyrostand.workbench.ledger`), else the configured one.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..core.data import Samples
from ..core.model import Model
from ..core.summary import DRIFT_UNIT
from ..errors import DataError, GyrostandError
from ..runfolder import LEDGER, csv_ledger_path, read_result, samples_path
from .ledger import read_ledger

__all__ = ["Subject", "open_subject", "open_subjects", "DEFAULT_MODEL"]

DEFAULT_MODEL = "markov,temp,bias"

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Subject:
    """What the workbench works on."""

    samples: Samples
    model: Model
    gyro: str
    ledger_path: Path
    run_dir: Path | None
    origin: str  # "run" or "csv"
    unit: str = DRIFT_UNIT  # the drift's unit (deg/h from our DBC)

    @property
    def out_dir(self) -> Path:
        return self.run_dir if self.run_dir is not None else self.ledger_path.parent


def _run_samples(run_dir: Path, gyro: str, dt: float) -> Samples:
    path = samples_path(run_dir, gyro)
    if not path.exists():
        raise DataError(f"{run_dir}: no samples for gyro {gyro!r} ({path} is missing)")
    s = Samples.read_csv(path, dt=dt)
    # time from the first bin (the run's absolute epoch times are kept in the file)
    t = s.t - s.t[0]
    t.setflags(write=False)
    return s.replace(t=t)


def _drift_unit(info: dict[str, Any], gyro: str) -> str:
    """The drift signal's unit in the run's DBC (through its config), else ``y``."""
    from ..config import load_config

    path = info.get("config")
    if not path:
        return DRIFT_UNIT
    try:
        cfg = load_config(path)
    except (GyrostandError, OSError, ValueError) as exc:
        log.info("drift unit unknown (config %s not readable: %s)", path, exc)
        return DRIFT_UNIT
    for g in cfg.gyros:
        if g.name == gyro:
            return g.drift.signal.unit or DRIFT_UNIT
    return DRIFT_UNIT


def open_subject(path: str | Path, *, gyro: str | None = None,
                 model: str | Sequence[str] | None = None, unit: str | None = None,
                 dt: float | None = None) -> Subject:
    """Open a run folder or a CSV as a workbench subject.

    ``unit``: the drift's unit (default: the DBC's, through the run's config; ``y`` for a
    CSV); ``dt``: a CSV's grid step (default its most common step).
    """
    path = Path(path)
    if path.is_dir():
        info = read_result(path)
        gyros = info.get("gyros", {})
        if gyro is None:
            if len(gyros) != 1:
                raise DataError(f"{path}: the run has gyros {', '.join(gyros) or 'none'}; "
                                "choose one with --gyro")
            gyro = next(iter(gyros))
        if gyro not in gyros:
            raise DataError(f"{path}: no gyro {gyro!r} (the run has {', '.join(gyros)})")
        samples = _run_samples(path, gyro, float(info.get("dt", 1.0)))
        ledger = path / LEDGER
        configured: Sequence[str] = gyros[gyro].get("model", DEFAULT_MODEL.split(","))
        run_dir: Path | None = path
        origin = "run"
        unit = unit or _drift_unit(info, gyro)
    elif path.suffix.lower() == ".csv" or path.is_file():
        samples = Samples.read_csv(path, dt=dt)
        gyro = gyro or path.stem
        ledger = csv_ledger_path(path)
        configured = DEFAULT_MODEL.split(",")
        run_dir = None
        origin = "csv"
    else:
        raise DataError(f"{path}: no such run folder or CSV file")
    if model is not None:
        current = Model.parse(model)
    else:
        steps = [e for e in read_ledger(ledger) if e.get("gyro") == gyro and "model" in e]
        current = Model.parse(steps[-1]["model"] if steps else configured)
    return Subject(samples=samples, model=current, gyro=gyro, ledger_path=ledger,
                   run_dir=run_dir, origin=origin, unit=unit or DRIFT_UNIT)




def open_subjects(paths: Sequence[str | Path], *, gyro: str | None = None,
                  model: str | Sequence[str] | None = None, unit: str | None = None,
                  dt: float | None = None) -> list[Subject]:
    """Several runs of one gyro (run folders or CSVs), each opened as :func:`open_subject`
    (``--gyro`` picks the gyro in every folder). They are studied under one model: ``model``
    if given, else the first run's current model."""
    subjects = [open_subject(p, gyro=gyro, model=model, unit=unit, dt=dt) for p in paths]
    first = subjects[0]
    units = {s.unit for s in subjects}
    if len(units) > 1:
        raise DataError("the runs' drift units differ ("
                        + ", ".join(f"{s.samples.source}: {s.unit}" for s in subjects)
                        + "): not one gyro; give --unit to override")
    if model is None:
        subjects = [dataclasses.replace(s, model=first.model) for s in subjects]
    folders = [s.gyro for s in subjects if s.origin == "run"]
    if len(set(folders)) > 1:
        raise DataError("the run folders hold different gyros (" + ", ".join(folders)
                        + "): choose one with --gyro")
    return subjects
