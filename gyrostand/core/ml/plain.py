"""A shape parameter at its plain shape: where ML's search range cannot reach it."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import TypeVar

from ...errors import IdentificationError
from ..model import Model
from ..results import FitResult
from .search import bound_warning

F = TypeVar("F")


def plain_shapes(res: FitResult, finish: F, model: Model, fixed: Mapping[str, float] | None,
                 refit: Callable[[dict[str, float], Mapping[str, float]], tuple[FitResult, F]]
                 ) -> tuple[FitResult, F]:
    """``res``, or the fit with a shape parameter at its plain shape where that is better;
    each with its ``finish`` (what adds its standard errors, computed for the kept fit
    only).

    A shape parameter whose plain shape (its default, e.g. no lag: τ = 0) lies below its
    log-scale search range stops at the lower bound; the plain shape itself is then fitted
    too (``refit(held, start)``: the parameter held at its default, the rest started at
    ``res``) and kept when its likelihood is higher, the parameter reported held at the
    default and still listed at its bound (the data put it there). Measured: a hidden
    hysteresis (τ = 0) fitted with τ at its 3-s bound lost 13–30 in ln L to the plain
    shape on 3 of 3 seeds, and the saturated reference called the model inadequate.
    """
    defaults = model.defaults
    held = dict(fixed or {})
    for name in res.info.get("at_bound", ()):
        if name not in defaults or name in held or res.loglik is None:
            continue
        if not any(w.startswith(bound_warning(name, "lower")) for w in res.warnings):
            # at its upper bound (a hysteresis width: a tanh nearly linear in the rate)
            # the default lies inside the range the search had: measured, 5 of 5 such
            # refits lost (by up to 21 in ln L), each a local search of 0.1 s
            continue
        d = defaults[name]
        v = res.parameters[name].value
        if not d < v:
            continue
        try:
            alt, alt_finish = refit({**held, name: d}, res.values)
        except IdentificationError:
            continue
        if alt.loglik is not None and alt.loglik > res.loglik + 1e-6:
            warnings = (*alt.warnings, *(w for w in res.warnings if name in w),
                        f"ml: {name} is at its plain shape ({d:g}; ln L "
                        f"{alt.loglik - res.loglik:+.2f} over its search bound {v:.3g})")
            info = {**alt.info, "plain": [*alt.info.get("plain", ()), name],
                    "at_bound": [*alt.info.get("at_bound", ()), name]}
            res = dataclasses.replace(alt, warnings=tuple(dict.fromkeys(warnings)),
                                      info=info)
            finish = alt_finish
    return res, finish
