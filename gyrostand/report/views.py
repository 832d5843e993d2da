"""What a renderer is given: a result with the context its documents name.

A :class:`~gyrostand.core.results.FitResult` renders on its own; a diagnosis, a fit step,
Allan tables and a run's end need the data's name, the ledger, the run's paths: each view
below holds one such object and that context, and ``to_dict()`` is its JSON contract (the
keys ``diagnose --json``, ``fit --json``, ``allan --json`` have always printed).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from ..runfolder import json_safe

if TYPE_CHECKING:
    from ..core.diagnose.allan import AllanTable
    from ..core.diagnose.results import DiagnoseResult
    from ..core.model import Model
    from ..core.results import FitResult
    from ..workbench import FitStep, Subject

log = logging.getLogger(__name__)

__all__ = ["DiagnosisView", "FitStepView", "AllanView", "RunSummary", "RunFinals",
           "ReportPage", "Plot", "GyroFinals", "RunEnd"]


class GyroFinals(Protocol):
    """What the renderers read of one gyro's final fits at a run's end (the session's
    :class:`~gyrostand.session.final.GyroFinal`): ``fits[method]`` a :class:`FitResult`
    or the error that stopped it, ``unit`` the drift's, ``to_dict()`` its JSON."""

    @property
    def gyro(self) -> str: ...
    @property
    def model(self) -> Model: ...
    @property
    def bins(self) -> int: ...
    @property
    def gaps(self) -> int: ...
    @property
    def observed(self) -> int: ...
    @property
    def fits(self) -> Mapping[str, FitResult | str]: ...
    @property
    def unit(self) -> str: ...

    def to_dict(self) -> dict[str, Any]: ...


class RunEnd(Protocol):
    """What the renderers read of a finished run (the session's
    :class:`~gyrostand.session.runend.RunOutcome`): its folder and files, each gyro's
    final fits, why it stopped, its final state and its counts."""

    @property
    def run_dir(self) -> Path: ...
    @property
    def result_json(self) -> Path: ...
    @property
    def report(self) -> Path: ...
    @property
    def finals(self) -> Sequence[GyroFinals]: ...
    @property
    def stop_reason(self) -> str: ...
    @property
    def state(self) -> str: ...
    @property
    def stats(self) -> Mapping[str, Any]: ...


#: a diagnosis's next step where nothing says how the data was named (``--add TERM`` follows)
FIT_RUN = "gyrostand fit RUN"


@dataclass(frozen=True)
class DiagnosisView:
    """A diagnosis (``diagnose``): ``source`` names the data (e.g. ``run.csv (gyro az)``),
    ``ledger`` the ledger the step was written to (text only)."""

    report: DiagnoseResult
    source: str
    ledger: Path | None = None
    allan: AllanView | None = None
    #: the ``fit`` command of this data as the user can paste it (the next step)
    fit_command: str = FIT_RUN
    #: the ``adopt`` command of the run (the next step once ADEQUATE), when it has one
    adopt_command: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return _with_allan(self.report.to_dict(), self.allan)


@dataclass(frozen=True)
class FitStepView:
    """A before/after of one model change (``fit``)."""

    step: FitStep
    ledger: Path | None = None
    #: the lines that say the next step (``next: COMMAND`` and its note), text only
    next: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return self.step.to_dict()


@dataclass(frozen=True)
class AllanView:
    """The Allan tables of one gyro (``allan``): the raw drift's and the residual's after
    ``model``, at confidence ``level``; ``unit`` the drift's, ``dt`` the sampling step (s)."""

    gyro: str
    source: str
    unit: str
    dt: float
    model: tuple[str, ...]
    level: float
    raw: AllanTable
    residual: AllanTable

    @classmethod
    def of(cls, subject: Subject, fit: FitResult, unit: str,
           level: float = 0.95) -> AllanView:
        """The tables of ``subject``'s drift: raw, and the residual after ``fit``'s model
        (:func:`gyrostand.core.diagnose.allan.drift_tables`)."""
        from ..core.diagnose.allan import drift_tables

        s = subject.samples
        raw, resid = drift_tables(s, fit, unit=unit, level=level)
        return cls(subject.gyro, s.source, unit, s.dt, tuple(fit.model.names), level, raw,
                   resid)

    @classmethod
    def of_diagnosis(cls, subject: Subject, report: DiagnoseResult) -> AllanView | None:
        """:meth:`of` the diagnosis's ML fit in its unit, or None (logged) where the data
        are too short for an Allan table."""
        try:
            return cls.of(subject, report.fit, report.unit)
        except ValueError as exc:
            log.warning("no Allan tables: %s", exc)
            return None

    @property
    def tables(self) -> list[AllanTable]:
        return [self.raw, self.residual]

    def to_dict(self) -> dict[str, Any]:
        return {"gyro": self.gyro, "source": self.source, "unit": self.unit, "dt": self.dt,
                "model": list(self.model), "level": self.level, "raw": self.raw.to_dict(),
                "residual": self.residual.to_dict()}


@dataclass(frozen=True)
class RunSummary:
    """The end of a run as the command that ran it prints it: why it stopped, each gyro's
    final table (with the simulation's ``truths`` where known), the counts, the paths."""

    outcome: RunEnd
    truths: Mapping[str, Mapping[str, float]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        o = self.outcome
        return {"stop_reason": o.stop_reason, "state": o.state, "run_dir": str(o.run_dir),
                "result": str(o.result_json) if o.result_json.is_file()
                and getattr(o, "result_written", True) else None,
                "report": str(o.report) if o.report.is_file() else None,
                "gyros": {f.gyro: f.to_dict() for f in o.finals},
                "stats": json_safe(o.stats), "unwritten": list(o.stats.get("unwritten", []))}


@dataclass(frozen=True)
class RunFinals:
    """A run folder's ``report.txt``: session ``session`` from ``source``, the final fits
    of every gyro, the run's ``stats``, the simulation's ``truths`` where known."""

    session: str
    source: str
    finals: Sequence[GyroFinals]
    stats: Mapping[str, Any]
    truths: Mapping[str, Mapping[str, float]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"session": self.session, "source": self.source,
                "gyros": {f.gyro: f.to_dict() for f in self.finals},
                "stats": json_safe(dict(self.stats))}


@dataclass(frozen=True)
class Plot:
    """One figure of the report page: its PNG's file name, alt text, caption, pixel size,
    and ``src``: the image as a ``data:`` URI when embedded (else the page links ``file``)."""

    file: str
    alt: str
    caption: str
    size: tuple[int, int] = (0, 0)
    src: str = ""


@dataclass(frozen=True)
class ReportPage:
    """The HTML report of a subject's current model (``report``): the diagnosis ``report``,
    its ``plots`` (written beside the page), the ledger's ``steps``, where the convergence
    figure's estimates come from, and when and by which version the page was written."""

    subject: Subject
    report: DiagnoseResult
    plots: Sequence[Plot]
    steps: Sequence[Mapping[str, Any]]
    conv_source: str
    written: str
    version: str
    allan: AllanView | None = None
    #: the next steps as lines to paste (:mod:`gyrostand.workbench.advice`): ``fit`` and
    #: ``diagnose`` on this data, ``adopt`` of its run once ADEQUATE (None: no run)
    fit_command: str = FIT_RUN
    diagnose_command: str = "gyrostand diagnose RUN"
    adopt_command: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return _with_allan(self.report.to_dict(), self.allan)


def _with_allan(doc: dict[str, Any], allan: AllanView | None) -> dict[str, Any]:
    """A diagnosis's JSON with its Allan tables under ``"allan"`` (``{"raw": ...,
    "residual": ..., "unit": ..., ...}``, as ``allan --json`` prints them), when computed."""
    return {**doc, "allan": allan.to_dict()} if allan is not None else doc
