"""The workbench's subject: one gyro's 1-s series and the model under study.

A *subject* is opened from any input the workbench reads (:mod:`.inputs`: a run folder, a
samples CSV, the project's Parquet export, or a raw CAN log with its session file). Several
runs of one gyro (:func:`open_subjects`) are studied together under one model
(:mod:`~gyrostand.workbench.joint`).

The current model of a gyro is the model of its last ledger step
(:mod:`~gyrostand.workbench.ledger`), else the configured one (the session's; for a CSV
or Parquet file :data:`DEFAULT_MODEL`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ..core.data import Samples
from ..core.model import Model
from ..core.summary import DRIFT_UNIT
from ..errors import DataError
from .inputs import DEFAULT_MODEL, input_kind, read_input
from .ledger import read_ledger

__all__ = ["Subject", "open_subject", "open_subjects", "current_model", "DEFAULT_MODEL"]


@dataclass(frozen=True)
class Subject:
    """What the workbench works on."""

    samples: Samples
    model: Model
    gyro: str
    ledger_path: Path
    run_dir: Path | None
    origin: str  # "run", "csv", "parquet" or "log" (:class:`~.inputs.Input`)
    unit: str = DRIFT_UNIT  # the drift's unit (deg/h from our DBC)
    path: Path | None = None  # the input as it was named (a run folder, a file)
    config: Path | None = None  # the session file that decoded a raw log
    #: the model was named (``--model``), not the ledger's current one: advice repeats it
    model_given: bool = False

    @property
    def out_dir(self) -> Path:
        return self.run_dir if self.run_dir is not None else self.ledger_path.parent


def current_model(ledger: Path, gyro: str, configured: Sequence[str]) -> Model:
    """The model of ``gyro``'s last ledger step, else ``configured``."""
    steps = [e for e in read_ledger(ledger) if e.get("gyro") == gyro and "model" in e]
    return Model.parse(steps[-1]["model"] if steps else list(configured))


def open_subject(path: str | Path, *, gyro: str | None = None,
                 model: str | Sequence[str] | None = None, unit: str | None = None,
                 dt: float | None = None, config: str | Path | None = None) -> Subject:
    """Open a run folder, a samples CSV, a Parquet export or a raw log (with ``config``,
    its session file) as a workbench subject (:func:`~.inputs.read_input`).

    ``unit``: the drift's unit (default: the DBC's, through the session file; the Parquet
    field's; ``y`` for a CSV that names none); ``dt``: a CSV's grid step (default its most
    common step); ``model``: start from this model instead of the current one.
    """
    src = read_input(path, gyro=gyro, dt=dt, config=config)
    current = (Model.parse(model) if model is not None
               else current_model(src.ledger, src.gyro, src.configured))
    return Subject(samples=src.samples, model=current, gyro=src.gyro, ledger_path=src.ledger,
                   run_dir=src.run_dir, origin=src.origin, unit=unit or src.unit,
                   path=Path(path), config=Path(config) if config is not None else None,
                   model_given=model is not None)


def open_subjects(paths: Sequence[str | Path], *, gyro: str | None = None,
                  model: str | Sequence[str] | None = None, unit: str | None = None,
                  dt: float | None = None, config: str | Path | None = None
                  ) -> list[Subject]:
    """Several runs of one gyro (any inputs; ``config`` decodes the raw logs among them),
    each opened as :func:`open_subject`
    (``--gyro`` picks the gyro in every folder). They are studied under one model: ``model``
    if given, else the first run's current model."""
    subjects = [open_subject(p, gyro=gyro, model=model, unit=unit, dt=dt,
                             config=config if input_kind(p) == "log" else None)
                for p in paths]
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
