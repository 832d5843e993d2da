"""Where a model fails and which effect is missing: residual diagnostics
(:mod:`.diagnostics`), the prediction error (:mod:`.prederror`), the candidate terms ranked
by likelihood ratio (:mod:`.candidates`), the saturated reference and the verdict
(:mod:`.reference`, :mod:`.verdict`; several runs: :mod:`.joint`) and Allan-variance figures (:mod:`.allan`).
"""

from __future__ import annotations

from ..lazy import exports

#: each public name and the submodule defining it
EXPORTS: dict[str, str] = {
    "diagnose": "verdict",
    "fit_error": "verdict",
    "reference_fit": "reference",
    "Reference": "reference",
    "DiagnoseResult": "results",
    "rank_candidates": "candidates",
    "diagnose_fit": "diagnostics",
    "ResidualDiagnostics": "diagnostics",
    "model_error": "prederror",
    "ModelError": "prederror",
    "drift_tables": "allan",
    "allan_table": "allan",
    "joint_diagnose": "joint",
    "JointDiagnosis": "joint",
}
__all__ = sorted(EXPORTS)
__getattr__, __dir__ = exports(__name__, EXPORTS, globals())
