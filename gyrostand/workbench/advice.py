"""The workbench's next steps as lines to paste (:mod:`gyrostand.advice`): a command on
a subject's data as it was opened (:func:`subject_command`), and ``adopt`` of a run whose
session file does not hold its current model yet (:func:`adopt_command`)."""

from __future__ import annotations

from pathlib import Path

from ..advice import command_line
from ..core.model import Model
from ..errors import GyrostandError
from ..runfolder import read_result
from .subject import Subject

__all__ = ["subject_command", "adopt_command"]


def _gyros_of_run(run_dir: Path) -> int:
    try:
        return len(read_result(run_dir).get("gyros", {}))
    except GyrostandError:
        return 0


def subject_command(subject: Subject, command: str) -> str:
    """``gyrostand COMMAND DATA [--config C] [--gyro G] [--unit U]`` on the data
    ``subject`` was opened from (the run folder, the file), with what reopens it as it
    was: the raw log's session file, the gyro where the data holds several, a CSV's
    unit named on the command line, and ``--model`` when the subject's model was named
    (``report RUN --model …`` suggests a fit of that model, not of the ledger's)."""
    data = subject.run_dir or subject.path or Path(subject.samples.source)
    words: list[str | Path] = [command, data]
    if subject.origin == "log" and subject.config is not None:
        words += ["--config", subject.config]
    if subject.origin == "log" or (subject.run_dir is not None
                                   and _gyros_of_run(subject.run_dir) > 1):
        words += ["--gyro", subject.gyro]
    if subject.origin == "csv" and subject.unit != "y":
        words += ["--unit", subject.unit]
    if subject.model_given:  # a model named on the command line, not the ledger's
        words += ["--model", ",".join(subject.model.names)]
    return command_line(*words)


def adopt_command(subject: Subject) -> str | None:
    """``gyrostand adopt RUN`` of a run folder subject as a line to paste, when its
    session file does not hold the subject's model yet (else None: nothing to adopt, no
    run folder, or its session file cannot be read)."""
    from ..config.edit import gyro_lists

    if subject.run_dir is None:
        return None
    try:
        info = read_result(subject.run_dir)
        session = Path(str(info.get("config") or ""))
        written = gyro_lists(session.read_text(encoding="utf-8"), str(session))
        model = written[subject.gyro].model
    except (GyrostandError, OSError, KeyError, ValueError):
        return None
    if set(Model.parse(list(model)).names) == set(subject.model.names):
        return None
    several = len(info.get("gyros", {})) > 1
    return command_line("adopt", subject.run_dir, *(["--gyro", subject.gyro] if several
                                                     else []))
