"""Output (layer 3): every result as text, JSON or HTML, and the report with its figures.

**Renderers.** A renderer turns one object into one document (a ``str`` ending in a
newline), behind one small protocol; each format is one module (:mod:`.text`,
:mod:`.json`, :mod:`.html`, whose layouts are the ``string.Template`` files of
``templates/``) with one function per kind of object, found along the object's class
hierarchy. The kinds:

* :class:`~gyrostand.core.results.FitResult` (``identify``),
* :class:`~.views.DiagnosisView` (``diagnose``), :class:`~.views.FitStepView` (``fit``),
* :class:`~.views.AllanView` (``allan``),
* :class:`~.views.RunSummary` (``run``/``replay``/``demo``) and :class:`~.views.RunFinals`
  (a run folder's ``report.txt``),
* :class:`~.views.ReportPage` (``report``'s HTML page, with its figures).

Adding a format is one module with a ``RENDERER`` and a line in :data:`MODULES`; adding a
kind is one function per format module.

**The report.** :func:`write_report` (:mod:`.page`) diagnoses a subject's current model
(or takes a diagnosis) and writes ``report.html`` with its figures (:mod:`.figures`,
from the series of :mod:`.series`) into one self-contained folder:
measured vs. model, residuals with temperature, residuals vs. dT/dt and T, residual auto-
and cross-correlation with bands, estimate convergence with ±3σ bands, the ledger (error
falling step by step) and the Allan deviation of the residuals; :mod:`.joint` the report
of several runs of one gyro (its figures: :mod:`.joint_figures`).

This package imports nothing heavy itself (the command line's parser reads
:data:`FORMATS`): a format's module is imported when used, and :func:`write_report` /
:func:`default_dir` (matplotlib) when first asked for.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from .page import default_dir, write_report

__all__ = ["FORMATS", "Renderer", "ByKind", "renderer", "render", "write_report",
           "default_dir"]

#: every output format, the first the default
FORMATS = ("text", "json", "html")

#: the module of each format (relative to this package)
MODULES = {"text": ".text", "json": ".json", "html": ".html"}

#: names exported lazily (PEP 562): name -> its module (relative to this package)
LAZY = {"write_report": ".page", "default_dir": ".page"}


class Renderer(Protocol):
    """What every format provides: ``render(obj)`` -> the document, ending in ``\\n``."""

    format: str

    def render(self, obj: Any) -> str: ...


class ByKind:
    """A :class:`Renderer` that dispatches on the object's kind: ``kinds`` maps a class to
    the function rendering it; the first class of ``type(obj).__mro__`` found wins."""

    def __init__(self, format: str, kinds: Mapping[type, Callable[[Any], str]]) -> None:
        self.format = format
        self.kinds = dict(kinds)

    def render(self, obj: Any) -> str:
        for cls in type(obj).__mro__:
            fn = self.kinds.get(cls)
            if fn is not None:
                return fn(obj)
        known = ", ".join(sorted(c.__name__ for c in self.kinds))
        raise TypeError(f"no {self.format} renderer for a {type(obj).__name__} "
                        f"(it renders: {known})")


def renderer(format: str) -> Renderer:
    """The renderer of ``format`` (one of :data:`FORMATS`)."""
    if format not in MODULES:
        raise ValueError(f"unknown output format {format!r} (one of: {', '.join(FORMATS)})")
    module = importlib.import_module(MODULES[format], __name__)
    r: Renderer = module.RENDERER
    return r


def render(obj: Any, format: str = "text") -> str:
    """``obj`` as a document in ``format``."""
    return renderer(format).render(obj)


def __getattr__(name: str) -> Any:
    """The report's writers (:data:`LAZY`), imported when first asked for."""
    if name in LAZY:
        return getattr(importlib.import_module(LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
