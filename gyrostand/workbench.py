"""The model workbench: a run (or a CSV of 1-s samples), its current model, and a ledger.

A *subject* is one gyro's 1-s series with the model under study:

* a run folder written by ``gyrostand run``/``replay`` (``result.json`` names the gyros and
  their configured models; ``<gyro>/samples.csv`` holds the bins), or
* a plain CSV with columns ``t, drift, temp`` (the model then comes from ``--model``).

Every step (``diagnose``, ``fit --add/--remove``) is appended to a ledger, one JSON object
per line: ``<run>/ledger.jsonl`` (or ``<csv stem>.ledger.jsonl`` beside a CSV). The current
model of a gyro is the model of its last ledger step, else the configured one.
"""

from __future__ import annotations

import datetime as _dt
import json
import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .core.candidates import Report, diagnose, fit_error
from .core.data import Samples
from .core.ml import ml
from .core.model import Model
from .core.prederror import ModelError
from .core.results import DRIFT_UNIT, FitResult
from .errors import DataError, GyrostandError, OutputError

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


def read_ledger(path: Path) -> list[dict[str, Any]]:
    """All entries of a ledger (a missing ledger is empty); a bad line names its number."""
    if not path.exists():
        return []
    out = []
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    lines = text.split("\n")
    for i, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            entry = json.loads(line)
        except (json.JSONDecodeError, RecursionError) as exc:
            if i == len(lines):  # no line end: a step torn while being appended
                log.warning("%s: line %d: torn last entry left out", path, i)
                break
            why = exc.msg if isinstance(exc, json.JSONDecodeError) else "nested too deep"
            raise DataError(f"{path}: line {i}: not a JSON ledger entry ({why})") from None
        if not isinstance(entry, dict) or not isinstance(entry.get("model", []), (list, str)):
            raise DataError(f"{path}: line {i}: a ledger entry is a JSON object (with "
                            f"'model' a list of terms), got {type(entry).__name__}")
        out.append(entry)
    return out


def append_ledger(path: Path, entry: dict[str, Any]) -> dict[str, Any]:
    """Append one step (with its number and UTC time) and flush it to disk."""
    steps = read_ledger(path)
    entry = {"step": len(steps) + 1,
             "time": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"), **entry}
    try:
        if path.exists() and path.stat().st_size:  # cut a torn last entry (no line end)
            text = path.read_bytes()
            if not text.endswith(b"\n"):
                with path.open("rb+") as fh:
                    fh.truncate(text.rfind(b"\n") + 1)
        with path.open("a") as fh:
            fh.write(json.dumps(entry, allow_nan=False) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
    except OSError as exc:
        raise OutputError(f"{path}: cannot record the step: {exc.strerror or exc}") from exc
    return entry


def _run_samples(run_dir: Path, gyro: str, dt: float) -> Samples:
    path = run_dir / gyro / "samples.csv"
    if not path.exists():
        raise DataError(f"{run_dir}: no samples for gyro {gyro!r} ({path} is missing)")
    s = Samples.read_csv(path, dt=dt)
    # time from the first bin (the run's absolute epoch times are kept in the file)
    t = s.t - s.t[0]
    t.setflags(write=False)
    return s.replace(t=t)


def _drift_unit(info: dict[str, Any], gyro: str) -> str:
    """The drift signal's unit in the run's DBC (through its config), else ``y``."""
    from .config import load_config

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
        result = path / "result.json"
        if not result.exists():
            raise DataError(f"{path}: not a run folder (no result.json)")
        try:
            info = json.loads(result.read_text())
        except json.JSONDecodeError as exc:
            raise DataError(f"{result}: line {exc.lineno}: invalid JSON ({exc.msg})") from None
        gyros = info.get("gyros", {})
        if gyro is None:
            if len(gyros) != 1:
                raise DataError(f"{path}: the run has gyros {', '.join(gyros) or 'none'}; "
                                "choose one with --gyro")
            gyro = next(iter(gyros))
        if gyro not in gyros:
            raise DataError(f"{path}: no gyro {gyro!r} (the run has {', '.join(gyros)})")
        samples = _run_samples(path, gyro, float(info.get("dt", 1.0)))
        ledger = path / "ledger.jsonl"
        configured: Sequence[str] = gyros[gyro].get("model", DEFAULT_MODEL.split(","))
        run_dir: Path | None = path
        origin = "run"
        unit = unit or _drift_unit(info, gyro)
    elif path.suffix.lower() == ".csv" or path.is_file():
        samples = Samples.read_csv(path, dt=dt)
        gyro = gyro or path.stem
        ledger = path.with_name(path.stem + ".ledger.jsonl")
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


def fit_summary(r: FitResult, error: ModelError | None = None) -> dict[str, Any]:
    """One fit in a before/after: innovation RMS, ln L, model, and the model error
    (open-loop RMS of 60-s means over the run) with the floor the model predicts."""
    d: dict[str, Any] = {"rms": r.residual_rms, "loglik": r.loglik,
                         "model": list(r.model.names), "n_params": len(r.model.param_names)}
    if error is not None:
        d["model_error"] = _finite(error.rms)
        d["model_error_floor"] = _finite(error.floor)
        d["model_error_unit"] = error.unit
    return d


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def run_diagnose(subject: Subject, *, record: bool = True) -> Report:
    """Diagnose the subject's current model; append the step to the ledger."""
    rep = diagnose(subject.samples, subject.model, unit=subject.unit)
    if record:
        err = rep.model_error
        try:
            append_ledger(subject.ledger_path, {
                "gyro": subject.gyro, "action": "diagnose",
                "model": list(subject.model.names),
                "rms": rep.diagnosis.rms, "loglik": rep.fit.loglik, "adequate": rep.adequate,
                **({"model_error": _finite(err.rms), "model_error_floor": _finite(err.floor)}
                   if err is not None else {}),
                "ljung_box_p": rep.diagnosis.ljung_box_p,
                "best_candidate": rep.candidates[0].term if rep.candidates else None,
                "parameters": {k: e.to_dict() for k, e in rep.fit.parameters.items()},
            })
        except OutputError as exc:  # a diagnosis is still worth showing (e.g. disk full)
            log.warning("%s (the diagnosis is not in the ledger)", exc)
    return rep


@dataclass(frozen=True)
class FitStep:
    """Before/after of one model change."""

    before: FitResult
    after: FitResult
    added: tuple[str, ...]
    removed: tuple[str, ...]
    lr_stat: float
    df: int
    p_value: float
    before_error: ModelError | None = None
    after_error: ModelError | None = None

    @property
    def bigger_is_after(self) -> bool:
        """True when the test is of the added terms (the new model is the bigger one)."""
        return self.df > 0 or (self.df == 0 and bool(self.added))

    def to_dict(self) -> dict[str, Any]:
        """``lr_stat`` = 2 (ln L_bigger − ln L_smaller), the test of the smaller model
        (positive when the bigger model fits better, whichever way the step went)."""
        return {
            "model": list(self.after.model.names),
            "added": list(self.added), "removed": list(self.removed),
            "parameters": {k: e.to_dict() for k, e in self.after.parameters.items()},
            "before": fit_summary(self.before, self.before_error),
            "after": fit_summary(self.after, self.after_error),
            "lr_stat": self.lr_stat, "df": self.df, "p_value": self.p_value,
            "warnings": list(self.after.warnings),
            "unit": self.after_error.unit if self.after_error is not None else DRIFT_UNIT,
        }


def run_fit(subject: Subject, add: Sequence[str] = (), remove: Sequence[str] = (),
            *, record: bool = True) -> FitStep:
    """Refit with terms added/removed; before and after side by side; ledger step."""
    from scipy.stats import chi2

    if not add and not remove:
        raise GyrostandError("fit needs at least one --add TERM or --remove TERM")
    new = subject.model
    if remove:
        new = new.remove(*remove)
    if add:
        new = new.add(*add)
    before = ml(subject.samples, subject.model)
    after = ml(subject.samples, new, start=before.values)
    assert before.loglik is not None and after.loglik is not None
    df = len(new.param_names) - len(subject.model.param_names)
    # the test of the smaller model against the bigger one: LR = 2 (ln L_big − ln L_small)
    lr = 2.0 * (after.loglik - before.loglik)
    if df < 0 or (df == 0 and not add):
        lr = -lr
    p = float(chi2.sf(max(lr, 0.0), abs(df))) if df else float("nan")
    step = FitStep(before=before, after=after, added=tuple(add), removed=tuple(remove),
                   lr_stat=float(lr), df=df, p_value=p if np.isfinite(p) else 1.0,
                   before_error=fit_error(before, subject.samples, subject.unit),
                   after_error=fit_error(after, subject.samples, subject.unit))
    if record:
        append_ledger(subject.ledger_path, {
            "gyro": subject.gyro, "action": "fit", **step.to_dict(),
        })
    return step
