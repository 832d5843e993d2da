"""The report: one HTML page with PNG plots of a subject's current model (layer 3).

:func:`write_report` diagnoses the model (or takes a diagnosis) and writes
``report.html`` with its figures into one self-contained folder: measured vs. model,
residuals with temperature, residuals vs. dT/dt and T, residual auto- and
cross-correlation with bands, estimate convergence with ±3σ bands, the ledger (error
falling step by step) and the Allan deviation of the residuals.
"""

from .page import default_dir, write_report

__all__ = ["write_report", "default_dir"]
