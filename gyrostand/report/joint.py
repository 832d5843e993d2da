"""The report of several runs of one gyro: the joint diagnosis as one document (the joint
fit, each run's own parameters and residual check, the bias repeatability and the ranked
candidates; no figures yet), in ``report-<gyro>-joint/`` beside the first run."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from ..render import render
from ..workbench import Subject
from ..workbench.joint import run_joint_diagnose
from .page import DOCUMENTS, PAGE, _atomic, default_dir

__all__ = ["write_joint_report"]


def write_joint_report(subjects: Sequence[Subject], out_dir: str | Path | None = None, *,
                       format: str = "html") -> Path:
    """Diagnose the runs jointly (no ledger step: a report only reads) and write the
    document in ``format``; return its path."""
    if format != "html" and format not in DOCUMENTS:
        raise ValueError(f"unknown report format {format!r}")
    first = subjects[0]
    out = (Path(out_dir) if out_dir is not None
           else default_dir(first).with_name(f"report-{first.gyro}-joint"))
    out.mkdir(parents=True, exist_ok=True)
    rep = run_joint_diagnose(subjects, record=False)
    doc = render(rep, format)
    path = out / (PAGE if format == "html" else DOCUMENTS[format])
    _atomic(path, lambda fh: fh.write(doc.encode("utf-8")))
    return path
