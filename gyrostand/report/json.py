"""JSON documents: each kind's ``to_dict()`` (its JSON contract), indented by 2, strict
(no NaN: a non-finite number is an error, not invalid JSON), ending in a newline."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

from ..core.diagnose.joint import JointDiagnosis
from ..core.ml.joint import JointFit
from ..core.results import FitResult
from . import ByKind
from .views import AllanView, DiagnosisView, FitStepView, ReportPage, RunFinals, RunSummary

__all__ = ["RENDERER", "document"]


def document(obj: Any) -> str:
    """``obj.to_dict()`` as strict JSON."""
    return json.dumps(obj.to_dict(), indent=2, allow_nan=False) + "\n"


KINDS: dict[type, Callable[[Any], str]] = {
    kind: document for kind in (FitResult, DiagnosisView, FitStepView, AllanView, RunSummary,
                                RunFinals, ReportPage, JointFit, JointDiagnosis)}

RENDERER = ByKind("json", KINDS)
