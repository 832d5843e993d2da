"""``gyrostand term new --from RUN``: a plugin term of the shape the saturated reference
shows missing, written as a package the user reviews, installs and tests with ``fit --add``.

The subject's current model is fitted by ML and judged against its saturated reference
(:mod:`~gyrostand.core.diagnose.reference`). A significant level shift of the drift (a bias
jump, :mod:`~gyrostand.core.diagnose.shift`) becomes a step at its instant, first: no smooth
shape holds it, and until it is in the model every smooth test is judged around it.
Otherwise the most significant missing group's partial
effect (the drift at a soak at T, or over the time since switch-on) is fitted by a sparse
formula (:mod:`~gyrostand.core.diagnose.formula`), and the formula becomes one
:class:`~gyrostand.core.terms.Term` with a single coefficient ``a`` — the drift's change at
the shape's peak (drift unit) — an ``output`` term whose regressor is the shape at this
bin's temperature (or time), so ML, the LKF online and batch, ``diagnose`` and the summary
frame take it as they take any plugin (README: plugins).

The package: ``<out>/pyproject.toml`` (entry point ``gyrostand.terms``) and
``<out>/gyrostand_<name>.py``; ``pip install -e <out>`` makes the term known to every
command, or a session file's ``plugins: [gyrostand_<name>]`` with ``<out>`` on the path.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from ..core.diagnose.formula import SUPPORTED, Formula, score_formula
from ..core.diagnose.reference import Partial, reference_fit
from ..core.diagnose.shift import LevelShift, level_shift
from ..core.ml.fit import ml
from ..errors import ConfigError, DataError, OutputError
from ..plugins import known_terms
from .subject import Subject

__all__ = ["NewTerm", "new_term", "term_source"]

NAME = re.compile(r"^[a-z][a-z0-9_]{1,30}$")


@dataclass(frozen=True)
class NewTerm:
    """What ``term new`` wrote: the term's name, the partial effect (or the level shift)
    and formula it came from, the package folder and its module."""

    name: str
    partial: Partial | None
    formula: Formula
    folder: Path
    module: Path
    lack_of_fit_p: float
    shift: LevelShift | None = None


def shift_formula(shift: LevelShift) -> Formula:
    """A level shift as a formula in the time since switch-on: the unit step at its
    instant, the step's estimate its amplitude."""
    return Formula(variable="t", forms=((f"step at {shift.t:g} s", f"(x >= {shift.t!r}) * 1.0"),),
                   coef=(1.0,), peak=1.0, amplitude=shift.step, r2=float("nan"),
                   score=shift.stat)


def evidence(f: Formula, q: Partial | None, shift: LevelShift | None, unit: str) -> str:
    """What the generated module's docstring says the term came from."""
    if shift is not None:
        return (f"That run's drift shifted its level {shift.text(unit)}.\n"
                "A bias jump: an event of that run (a shock, a power or mode change, a "
                "connector), not a\nproperty of the gyro's thermal response — look at the run's "
                "log at that time. Here it is\na step at its instant, so that the rest of the "
                "model is judged without it:")
    assert q is not None
    what = {"T": "the temperature T (degC)", "t": "the time since switch-on t (s)"}[f.variable]
    return (f"The saturated reference of that run showed a missing partial effect of {what}\n"
            f"(Wald {q.wald:.1f} on {q.df} df, p = {q.p_value:.2g}); its sparse formula, the "
            f"forms chosen by\ntheir score statistic at the run's fit"
            + (f" (LM {f.score:.1f})" if f.score is not None else "")
            + f"\n(R² = {f.r2:.3f} of the partial effect's variation beyond a constant"
            + (" and a linear part" if f.variable == "T" else "") + "):")


def term_source(name: str, f: Formula, q: Partial | None, run: str, unit: str,
                shift: LevelShift | None = None) -> str:
    """The plugin module's text for the term ``name`` of shape ``f`` (from the partial
    effect ``q``, or from the level shift ``shift``)."""
    cls = "".join(w.capitalize() for w in name.split("_"))
    x_of = {"T": ("ctx.temp", "now.T"), "t": ("ctx.t - ctx.t[0]", "now.t")}[f.variable]
    forms = "\n".join(f"#   {c:+.4g} · {n}" for (n, _), c in zip(f.forms, f.coef, strict=True))
    # a polynomial's lower powers at the output, each its own coefficient b<k>
    low = [(f"b{n.rsplit('^', 1)[1]}", n, e, c) for n, e, c in f.lower]
    lower_doc = "".join(f"\n    drift += {k} · {n}   ({k} ≈ {c:.4g} on the run: a lower power of the "
                        f"polynomial, at the output)" for k, n, _, c in low)
    lower_params = "".join(f"\n              Param(\"{k}\", \"linear\", \"y\", \"drift at {n} = 1\"),"
                           for k, n, _, _ in low)
    lower_math = "".join(f" + {k} {n}" for k, n, _, _ in low)
    word_x = re.compile(r"\bx\b")
    lower_x = "".join(f', self.key("{k}"): {word_x.sub("x_", e)}' for k, _, e, _ in low)
    return f'''"""{name}: a drift term generated by ``gyrostand term new`` from {run}.

{evidence(f, q, shift, unit)}

    drift += a · g(x),   g(x) = (Σ c_j f_j(x)) / {f.peak:.6g}  (peak |g| = 1 on the run){lower_doc}

{forms}

a: the drift's change at the shape's peak ({unit}); the run's {'step' if shift else 'reference'} put it at
{f.amplitude:.4g}. Review the shape before you rely on it: it is a fit to one run's curve.
Install: pip install -e <this folder>; test: gyrostand fit RUN --add {name}.
"""

import numpy as np

from gyrostand.core.terms import Param, Term


def shape(x):
    """g(x), the generated shape (dimensionless, peak 1 over the run it came from)."""
    x = np.asarray(x, dtype=float)
    return {f.expression()}


class {cls}(Term):
    name = "{name}"
    params = (Param("a", "linear", "y", "drift change at the shape's peak"),{lower_params})
    role = "output"
    math = "+ a g({f.variable}), g = {' + '.join(n for n, _ in f.forms)} (normalised){lower_math}"

    def regressors(self, p, ctx):
        x_ = np.asarray({x_of[0]}, dtype=float)
        return {{self.key("a"): shape(x_){lower_x}}}

    def causal_regressors(self, p, now):
        x_ = float({x_of[1]})
        return {{self.key("a"): float(shape(x_)){lower_x}}}
'''


def _pyproject(name: str) -> str:
    return f'''[build-system]
requires = ["setuptools>=61"]
build-backend = "setuptools.build_meta"

[project]
name = "gyrostand-{name.replace('_', '-')}"
version = "0.1.0"
description = "gyrostand plugin term {name} (generated by gyrostand term new)"
dependencies = ["gyrostand", "numpy"]

[tool.setuptools]
py-modules = ["gyrostand_{name}"]

[project.entry-points."gyrostand.terms"]
{name} = "gyrostand_{name}:{"".join(w.capitalize() for w in name.split("_"))}"
'''


def new_term(subject: Subject, name: str, out: Path | None = None,
             force: bool = False) -> NewTerm:
    """Write the plugin package of the shape ``subject``'s reference shows missing."""
    if not NAME.match(name):
        raise ConfigError(f"term name {name!r}: lower-case letters, digits and _, "
                          "starting with a letter (2-31 characters)")
    if name in known_terms():
        raise ConfigError(f"term name {name!r} is taken (a built-in or installed term)")
    fit = ml(subject.samples, subject.model)
    ref = reference_fit(subject.samples, subject.model, fit)
    shift = level_shift(subject.samples, ref)
    if shift is not None and not shift.significant:
        shift = None
    missing = [q for q in ref.missing() if q.variable in SUPPORTED]
    if shift is None and (not ref.reported or not missing):
        raise DataError(
            f"{subject.samples.source}: the model {subject.model} shows no significant lack "
            f"of fit in T or in time (reference p = {ref.p_value:.2g}"
            + ("; the missing shape is in dT/dt: the vocabulary's rate terms cover it"
               if ref.reported else "") + "): there is no missing shape to write")
    q = missing[0] if shift is None else None
    f = shift_formula(shift) if shift is not None else score_formula(
        missing[0], subject.samples, subject.model, fit)
    folder = Path(out) if out is not None else _default_folder(subject, name)
    module = folder / f"gyrostand_{name}.py"
    if module.exists() and not force:
        raise OutputError(f"{module} exists (--force to overwrite)")
    folder.mkdir(parents=True, exist_ok=True)
    module.write_text(term_source(name, f, q, subject.samples.source, subject.unit, shift),
                      encoding="utf-8")
    (folder / "pyproject.toml").write_text(_pyproject(name), encoding="utf-8")
    return NewTerm(name=name, partial=q, formula=f, folder=folder, module=module,
                   lack_of_fit_p=ref.p_value, shift=shift)


def _default_folder(subject: Subject, name: str) -> Path:
    """``gyrostand-<name>/`` in the run folder (beside a CSV)."""
    return subject.out_dir / f"gyrostand-{name.replace('_', '-')}"
