"""A fit result as plain text: the units as printed and the table of
:meth:`FitResult.summary() <gyrostand.core.results.FitResult.summary>`.

The core's own text (standard library only): the output package's text renderer
(:func:`gyrostand.report.text.fit_result`, ``identify``) prints the same table by calling
:func:`fit_table`, so the two never differ.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from typing import Protocol

__all__ = ["UNIT_TEXT", "DRIFT_UNIT", "unit_text", "fit_table", "shown_warnings"]

UNIT_TEXT = {"y": "y", "1/s": "1/s", "y/(s*degC)": "y/(s·°C)", "y/sqrt(s)": "y/√s"}

#: the drift's unit when nothing names it (a CSV without ``--unit``)
DRIFT_UNIT = "y"


def unit_text(unit: str, drift: str = DRIFT_UNIT) -> str:
    """A parameter's unit as printed, the drift's unit in place of ``y``.

    >>> unit_text("y/(s*degC)", "deg/h")
    '(deg/h)/(s·°C)'
    >>> unit_text("y*s/degC", "deg/h"), unit_text("y", "deg/h"), unit_text("1/s", "deg/h")
    ('(deg/h)·s/°C', 'deg/h', '1/s')
    """
    d = drift or DRIFT_UNIT
    if unit == "y":
        return d
    if "/" in d or "*" in d or " " in d:
        d = f"({d})"
    out = re.sub(r"\by\b", lambda _: d, unit)
    return (out.replace("sqrt(s)", "√s").replace("degC", "°C").replace("^2", "²")
            .replace("*", "·"))


class Estimated(Protocol):
    """What :func:`fit_table` reads of a parameter's estimate
    (:class:`~gyrostand.core.results.Estimate`)."""

    @property
    def value(self) -> float: ...
    @property
    def std(self) -> float: ...
    @property
    def unit(self) -> str: ...
    @property
    def fixed(self) -> bool: ...


class Named(Protocol):
    """What :func:`fit_table` reads of a model: its term names, in order."""

    @property
    def names(self) -> Sequence[str]: ...


class Tabulated(Protocol):
    """What :func:`fit_table` reads of a fit (:class:`~gyrostand.core.results.FitResult`)."""

    @property
    def method(self) -> str: ...
    @property
    def model(self) -> Named: ...
    @property
    def parameters(self) -> Mapping[str, Estimated]: ...
    @property
    def loglik(self) -> float | None: ...
    @property
    def warnings(self) -> tuple[str, ...]: ...
    @property
    def source(self) -> str: ...
    @property
    def n_samples(self) -> int: ...
    @property
    def n_observed(self) -> int: ...
    @property
    def dt(self) -> float: ...
    @property
    def unit(self) -> str: ...
    @property
    def residual_rms(self) -> float: ...


def fit_table(r: Tabulated) -> str:
    """A readable table of a fit with units (no final newline): the method, model and
    sample counts, the data's source, one row per parameter (value, standard deviation or
    ``fixed``, unit), the log-likelihood where the method has one, the residual RMS and
    the fit's warnings. Units are in the drift's unit when ``r.unit`` names it, else in
    ``y`` with a line saying so; one notation either way (:func:`unit_text`)."""
    lines = [
        f"method {r.method}   model {','.join(r.model.names)}   "
        f"samples {r.n_observed}/{r.n_samples} (dt {r.dt:g} s)",
        f"data   {r.source}",
        "",
        f"{'parameter':<16} {'value':>14} {'std':>12}  unit",
    ]
    named = r.unit != DRIFT_UNIT  # the drift's unit given (identify --unit)
    for k, e in r.parameters.items():
        std = "fixed" if e.fixed else f"{e.std:12.4g}"
        unit = unit_text(e.unit, r.unit)  # one notation, named or not
        lines.append(f"{k:<16} {e.value:14.6g} {std:>12}  {unit}")
    lines.append("")
    if r.loglik is not None:
        lines.append(f"log-likelihood {r.loglik:.6f}")
    lines.append(f"residual RMS   {r.residual_rms:.6g} {r.unit}")
    if not named:
        lines.append("(y = the drift's unit, e.g. deg/h)")
    for w in shown_warnings(r.warnings):
        lines.append(f"warning: {w}")
    return "\n".join(lines)


def shown_warnings(warnings: Sequence[str]) -> list[str]:
    """The warnings as a user reads them: a parameter's "is at its lower search bound" is
    left out where the same parameter "is at its plain shape" (that one names the bound
    and why the plain shape was kept: two lines for one parameter read as a contradiction).
    The fit's own list, and its JSON, keep both (identification reads the bound's).

    >>> shown_warnings(["ml: a.tau is at its lower search bound (at the edge of its "
    ...                 "plausible range)", "ml: a.tau is at its plain shape (0; ln L +0.59 "
    ...                 "over its search bound 3)", "ml: b.w is at its lower search bound (x)"])
    ['ml: a.tau is at its plain shape (0; ln L +0.59 over its search bound 3)', \
'ml: b.w is at its lower search bound (x)']
    """
    plain = {w.split()[1] for w in warnings
             if w.startswith("ml: ") and " is at its plain shape " in w}
    return [w for w in warnings if not (w.startswith("ml: ") and w.split()[1] in plain
                                        and " is at its lower search bound " in w)]
