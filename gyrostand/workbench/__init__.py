"""The model workbench: a run (or a CSV of 1-s samples), its current model, and a ledger.

* :mod:`.subject`: what the workbench works on (one gyro's series and its model), opened
  from a run folder (through :mod:`gyrostand.runfolder`) or a plain CSV;
* :mod:`.ledger`: ``ledger.jsonl``, one JSON object per step;
* :mod:`.steps`: ``diagnose`` and ``fit --add/--remove``, each appended to the ledger.

Every step (``diagnose``, ``fit --add/--remove``) is appended to the ledger,
``<run>/ledger.jsonl`` (or ``<csv stem>.ledger.jsonl`` beside a CSV). The current model of
a gyro is the model of its last ledger step, else the configured one.
"""

from .ledger import append_ledger, read_ledger
from .steps import FitStep, fit_summary, run_diagnose, run_fit
from .subject import DEFAULT_MODEL, Subject, open_subject

__all__ = ["Subject", "open_subject", "DEFAULT_MODEL", "read_ledger", "append_ledger",
           "FitStep", "fit_summary", "run_diagnose", "run_fit"]
