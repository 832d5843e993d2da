"""The common scale and the linear coefficients concentrated out of the exact likelihood:
ln L at s² = S/n, and a parameter dict filled in from them (the single-run
:class:`~gyrostand.core.ml.fit.Problem` and the joint one share both)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..model import LOG_2PI, Model

__all__ = ["concentrated_loglik", "fill_natural"]


def concentrated_loglik(S: float, n: int, slogf: float, concentrate: bool
                        ) -> tuple[float, float]:
    """``(ln L, s²)`` from the whitened residual sum of squares ``S`` of ``n`` observations
    and ``Σ ln f``: with the common scale concentrated out, s² = S/n; else s² = 1."""
    S = max(S, 1e-300)
    if concentrate:
        s2 = S / n
        return float(-0.5 * (n * LOG_2PI + n * np.log(s2) + slogf + n)), s2
    return float(-0.5 * (n * LOG_2PI + slogf + S)), 1.0


def fill_natural(model: Model, concentrate: bool, lin_free: Sequence[str],
                 p: dict[str, float], theta: np.ndarray, s2: float) -> dict[str, float]:
    """``p`` with ``model``'s noise levels scaled by √s² (when the scale is concentrated
    out) and the free linear coefficients ``lin_free`` set to their GLS estimates
    ``theta``."""
    if concentrate:
        s = float(np.sqrt(s2))
        for n in model.names_of_kind("std"):
            p[n] = p[n] * s
    for n, v in zip(lin_free, theta, strict=True):
        p[n] = float(v)
    return p
