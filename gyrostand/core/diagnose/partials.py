"""The saturated reference's partial effects (:mod:`.reference`): what each group of its
basis — the temperature, its rate, the time since switch-on — adds, as a curve with bands
(the drift at a soak at T, on a steady ramp at dT/dt, over the time since switch-on) and
as a Wald test of the group against everything else in the reference."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..chisq import chi2_sf
from ..data import Samples
from ..model import context

__all__ = ["GRID", "GROUPS", "RANK_TOL", "Partial", "partial_effects", "rank"]

#: relative singular-value tolerance of the rank counts behind df
RANK_TOL = 1e-7
#: points of each partial-effect curve
GRID = 41
#: the groups of the basis, in the order reported
GROUPS = ("temperature", "rate", "time")


@dataclass(frozen=True)
class Partial:
    """One group's partial effect in the reference: the drift's change (drift unit) as a
    function of ``variable`` (``x``), with its standard deviation, and the Wald test that
    the group adds nothing (``wald`` on ``df``, ``p_value``)."""

    group: str
    variable: str
    unit: str
    x: np.ndarray
    effect: np.ndarray
    std: np.ndarray
    wald: float
    df: int
    p_value: float

    @property
    def significant(self) -> bool:
        return self.p_value < 0.01

    def peak(self) -> tuple[float, float, float]:
        """(x, effect, std) where the effect is largest among the points where it is
        clear of its band (|effect| > 2 std; all points when none is)."""
        a = np.abs(self.effect)
        clear = a > 2.0 * self.std
        i = int(np.argmax(np.where(clear, a, -1.0))) if clear.any() else int(np.argmax(a))
        return float(self.x[i]), float(self.effect[i]), float(self.std[i])

    def to_dict(self) -> dict[str, Any]:
        return {"group": self.group, "variable": self.variable, "unit": self.unit,
                "x": [float(v) for v in self.x], "effect": [float(v) for v in self.effect],
                "std": [float(v) for v in self.std], "wald": self.wald, "df": self.df,
                "p_value": self.p_value}




def rank(W: np.ndarray) -> int:
    """The numerical rank of ``W``'s columns, each scaled to unit norm (relative
    tolerance :data:`RANK_TOL`)."""
    if W.shape[1] == 0:
        return 0
    n = np.linalg.norm(W, axis=0)
    W = W[:, n > 0] / n[n > 0]
    if W.shape[1] == 0:
        return 0
    s = np.linalg.svd(W, compute_uv=False)
    return int(np.sum(s > RANK_TOL * s[0]))


def partial_effects(b: Any, p: Mapping[str, float], W: np.ndarray, wy: np.ndarray,
                    names: list[str], samples: Samples, scale: float = 1.0
                    ) -> tuple[Partial, ...]:
    """Each group's partial effect of the reference basis ``b`` (a
    :class:`~.reference.ReferenceBasis`) on a grid of its variable, with bands, from the
    GLS design ``W``, ``wy`` (whitened: unit noise) whose columns are ``names`` and its
    estimate in ``p``. Its Wald statistic is what the group adds to the fit of everything
    else, RSS(without the group) − RSS(all), divided by ``scale`` (its null mean over df),
    on the rank the group adds. θ'C⁺θ on the rank of the group's own covariance C (its
    eigenvalues above 1e-7 of the largest) counted a column the model already holds (the
    basis's T² through the drift beside ``temp2``) and dropped well-determined ones: on a
    hidden cubic (advice benchmark seed 504) it gave 251,722 on 9 df after ``temp2`` where
    the group adds 143.4 on 8, and 190.5 on 8 before it where it adds 370.3 on 9."""
    cov = np.linalg.pinv(W.T @ W, rcond=1e-12, hermitian=True)
    theta_all, *_ = np.linalg.lstsq(W, wy, rcond=1e-12)
    rss_all = float(np.sum((wy - W @ theta_all) ** 2))
    rank_all = rank(W)
    beta = p.get("markov.beta")
    T = np.asarray(samples.temp, dtype=float)
    T = T[np.isfinite(T)]
    ctx = context(samples, None)
    rate = ctx.temp_rate
    t = samples.t - samples.t[0]
    out = []
    for group in GROUPS:
        cols = [c for c in b.columns if c.group == group]
        if not cols:
            continue
        if group == "temperature":
            x = np.linspace(float(T.min()), float(T.max()), GRID)
            rows = []
            for c in cols:
                if c.name.startswith("K"):
                    rows.append(np.maximum(x - b.knots[int(c.name[1:])], 0.0) / b.t_half)
                    continue
                v = np.polynomial.legendre.legval(b.x(x), [0] * int(c.name[1:]) + [1])
                # a soak at T: the drift settles at θ·u(T)/β (an input of dε/dt)
                rows.append(v / beta if c.through_drift and beta else v)
            variable, unit = "T", "degC"
        elif group == "rate":
            x = np.linspace(float(np.nanmin(rate)), float(np.nanmax(rate)), GRID)
            rows = []
            for c in cols:
                # a steady ramp at rate r: every lag of the rate is r
                if c.name in ("r0", "rL"):
                    v = x / b.rate_scale
                elif c.name in ("s0", "sL"):
                    v = np.tanh(x / b.width)
                else:  # rin: dT/dt into dε/dt, settled
                    v = x / b.rate_scale / beta if beta else x / b.rate_scale
                rows.append(v)
            variable, unit = "dT/dt", "degC/s"
        else:
            x = np.linspace(0.0, float(t[-1]), GRID)
            rows = [x / max(float(t[-1]), 1.0) if c.name == "trend"
                    else np.exp(-x / b.taus[int(c.name[1:])]) for c in cols]
            variable, unit = "t", "s"
        idx = [names.index(b.key(c.name)) for c in cols]
        theta = np.array([p[b.key(c.name)] for c in cols])
        C = cov[np.ix_(idx, idx)]
        G = np.array(rows).T  # (grid, cols)
        eff = G @ theta
        std = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", G, C, G), 0.0))
        rest = [j for j in range(W.shape[1]) if j not in idx]
        th, *_ = np.linalg.lstsq(W[:, rest], wy, rcond=1e-12)
        wald = max(float(np.sum((wy - W[:, rest] @ th) ** 2)) - rss_all, 0.0) / scale
        df = rank_all - rank(W[:, rest])
        out.append(Partial(group, variable, unit, x, eff, std, wald, df,
                           chi2_sf(wald, df) if df else 1.0))
    return tuple(out)
