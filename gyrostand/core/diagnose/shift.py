"""A level shift of the drift — a bias jump — judged against the saturated reference.

A jump of the drift at one instant t₀ (a shock, a power or mode change of the gyro's
electronics, a connector) has no term in the vocabulary, and the saturated reference's
smooth bases in T, dT/dt and time (:mod:`.reference`) do not hold it either: measured on a
4-h chamber cycle with a jump of 0.15 deg/h at 2.5 h (benchmarks/advice_sequence.py,
"bias jump (outside)"), the workbench proposed ``trend`` (LR 34.5), and with it in the
model said ADEQUATE — the lack of fit p 0.008, the open-loop error at its floor — while
the jump's step, at its instant, had a score statistic of 88 there.

The test, at the reference's fit (its random part: the one a misfit moves least; at the
fit's the statistic was 61): with ε the reference's whitened innovations and x(t₀) a unit
step from sample t₀ through the same Kalman filter, whitened, both orthogonal to the
reference's tangents (every column of its saturated basis, the model's coefficients and the
mean's slopes along its rates: a smooth shape in T, dT/dt or time is the reference's, not a
jump) and to impulses at t₀ … t₀ + :data:`WINDOW` − 1 (a jump's first innovations — or a
glitch there — carry no weight: a spike is not a shift), the efficient score

    Z(t₀) = x̃'ε / ‖x̃‖ ~ N(0, 1)  at a fixed t₀;   the step's estimate x̃'ε / x̃'x̃ ± 1/‖x̃‖

is searched at the samples around the largest innovations (a jump's first innovation
stands out: 7σ of the white noise for 0.15 deg/h over σ 0.02; it is that sample, give or
take the filter's delay, where the statistic peaks: it falls from 88 to 12 ten samples
off), and its supremum is referred to Bonferroni over every admissible t₀ (the observed
samples but the first and last :data:`TRIM` of them: near an end a step is the bias or a
warm-up) — valid whatever the search visits, conservative by the correlation of
neighbouring t₀. Significant at :data:`SHIFT_ALPHA`, as the lack of fit is; a run without
a jump keeps the verdict it had.

Out of reach: a shift spread over minutes (a slow step; a smooth change is a warm-up, a
trend or the reference's time basis) or one smaller than ~4 σ of the white noise in its
first innovation (the search may not visit it); a rate random walk, which is a run of tiny
shifts, shows here only when the model lacks it — then its candidate is significant too.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..chisq import chi2_sf
from ..data import Samples
from ..model import Model, context
from ..threads import one_blas_thread
from ..validate import prepare
from .reference import Reference
from .results import p_text
from .shapes import mean_tangents

__all__ = ["LevelShift", "SHIFT_ALPHA", "Whitened", "level_shift", "whitened"]

#: level of the test in the verdict (the lack of fit's)
SHIFT_ALPHA = 0.001
#: fraction of the observed samples at each end where no break is sought
TRIM = 0.05
#: impulses projected out at the break and after it (the jump's first innovations)
WINDOW = 4
#: the largest innovations around which a break is sought, at least this many samples apart
OUTLIERS, APART = 10, 30
#: samples before and after each of them searched as t₀ (the filter's delay puts the
#: largest innovation at the jump or a few samples after it)
BEFORE, AFTER = 4, 2
#: most steps in T projected out at a break (the temperatures read around it)
MAX_LEVELS = 8


@dataclass(frozen=True)
class LevelShift:
    """The largest level shift found: at ``t`` (s from the run's first sample), its step
    (drift unit) and std, the score statistic Z², the admissible break positions it is
    referred to (Bonferroni), the p-value and the test's level."""

    t: float
    step: float
    std: float
    stat: float
    positions: int
    p_value: float
    alpha: float = SHIFT_ALPHA

    @property
    def significant(self) -> bool:
        return self.p_value < self.alpha

    def text(self, unit: str) -> str:
        """One line: where, how large, how sure."""
        return (f"at t = {self.t:.0f} s, a step of {self.step:+.3g} ± {self.std:.2g} {unit} "
                f"(score {self.stat:.1f}; Bonferroni over {self.positions} break times: "
                f"p {p_text(self.p_value)})")

    def to_dict(self) -> dict[str, Any]:
        return {"t": self.t, "step": self.step, "std": self.std, "stat": self.stat,
                "positions": self.positions, "p_value": self.p_value, "alpha": self.alpha,
                "significant": self.significant}


@dataclass(frozen=True)
class Whitened:
    """The reference's innovations, what the level shift and the periodic line are judged
    by (:func:`whitened`): the samples used, the reference's model and values, the
    observed rows ``ok``, their 1/√f ``w``, the whitened innovations ``eps`` (observed
    rows, orthogonal to ``Q``) and ``Q``, an orthonormal basis of the reference's whitened
    tangents (its coefficients' regressors and its mean's slopes along its rates)."""

    used: Samples
    model: Model
    values: dict[str, float]
    ok: np.ndarray
    w: np.ndarray
    eps: np.ndarray
    Q: np.ndarray

    def filtered(self, Y: np.ndarray) -> np.ndarray:
        """Columns ``Y[:, 1:]`` through the reference's Kalman filter, whitened, the
        tangents projected out (observed rows)."""
        C = self.model.filter_matrix(self.values, self.used, Y)[0][self.ok, 1:] * \
            self.w[:, None]
        C -= self.Q @ (self.Q.T @ C)
        return C


def whitened(samples: Samples, ref: Reference | None) -> Whitened | None:
    """The reference ``ref``'s whitened innovations on ``samples`` (None without its fit)."""
    if ref is None or ref.fit is None:
        return None
    with one_blas_thread():  # small algebra on long columns: see ml.ml
        used = prepare(samples, "reference innovations")
        model, vals = ref.model, dict(ref.fit.values)
        names, Tx = mean_tangents(model, vals, context(used, model))
        n_lin = len(model.names_of_kind("linear"))
        theta = np.array([vals[n] for n in names[:n_lin]])
        E, f = model.filter_columns(vals, used, Tx)
        e = E[:, 0] - E[:, 1:1 + n_lin] @ theta
        ok = np.isfinite(e) & (f > 0)
        w = 1.0 / np.sqrt(f[ok])
        Q = _basis(E[ok, 1:] * w[:, None])
        eps = e[ok] * w
        eps -= Q @ (Q.T @ eps)
    return Whitened(used=used, model=model, values=vals, ok=ok, w=w, eps=eps, Q=Q)


def level_shift(samples: Samples, ref: Reference | None, alpha: float = SHIFT_ALPHA,
                at: Whitened | None = None) -> LevelShift | None:
    """The largest level shift of ``samples``' drift against the reference ``ref`` (None
    without a reference fit, or too few samples to seek a break). ``at``: the reference's
    innovations, when already made (:func:`whitened`)."""
    at = at if at is not None else whitened(samples, ref)
    if at is None:
        return None
    with one_blas_thread():
        return _level_shift(at, alpha)


def _level_shift(at: Whitened, alpha: float) -> LevelShift | None:
    used, ok, eps = at.used, at.ok, at.eps
    obs = np.flatnonzero(ok)
    trim = int(TRIM * obs.size)
    if obs.size - 2 * trim < 2 * (BEFORE + AFTER + WINDOW):
        return None
    lo, hi = int(obs[trim]), int(obs[obs.size - trim - 1])  # admissible t₀: [lo, hi]
    positions = int(np.count_nonzero((obs >= lo) & (obs <= hi)))
    # the breaks sought: around the largest innovations inside [lo, hi]
    full = np.zeros(used.t.size)
    full[obs] = np.abs(eps)
    order = np.argsort(-full[lo:hi + 1], kind="stable") + lo
    picked: list[int] = []
    for k in order:
        if len(picked) >= OUTLIERS or full[k] == 0.0:
            break
        if all(abs(int(k) - j) >= APART for j in picked):
            picked.append(int(k))
    # per break sought, one step from its first t₀ and an impulse at each sample of its
    # t₀ range and window: a step from a later t₀ is that step less the impulses before
    # it (the filter is linear), so each t₀'s statistic is algebra on the group's Gram
    # matrix (:func:`_best_in_group`)
    # and steps in T at each temperature read around the break (above it, the drift is
    # shifted): where the drift jumps each time T crosses a level, that is the shape, not
    # a jump in time (a step of 0.4 deg/h above 40 °C scored 202-285 without them; with
    # one at the break's reading, off by a sensor quantum at the other crossings, 202)
    temp = np.nan_to_num(np.asarray(used.temp, dtype=float), nan=-np.inf)
    groups = []
    for k in sorted(picked):
        first, last = max(k - BEFORE, lo), min(k + AFTER, hi)
        pulses = list(range(first, min(last + WINDOW, used.t.size)))
        near = temp[max(first - 1, 0):last + WINDOW + 1]
        levels = np.unique(near[np.isfinite(near)])[1:]  # the lowest: 1{T ≥ it} ≈ the bias
        groups.append((first, last, pulses, levels[:MAX_LEVELS]))
    Y = np.zeros((used.t.size, 1 + sum(1 + len(g[2]) + len(g[3]) for g in groups)))
    col = 1
    for first, _, pulses, levels in groups:
        Y[first:, col] = 1.0
        Y[pulses, col + 1 + np.arange(len(pulses))] = 1.0
        for j, v in enumerate(levels):
            Y[:, col + 1 + len(pulses) + j] = temp >= v
        col += 1 + len(pulses) + len(levels)
    A = at.filtered(Y)
    b = A.T @ eps
    best: tuple[float, int, float, float] | None = None
    instant = 0
    col = 0
    for first, last, pulses, levels in groups:
        n = 1 + len(pulses) + len(levels)
        g = slice(col, col + n)
        # the group's Gram matrix (the reference's tangents projected out)
        G = A[:, g].T @ A[:, g]
        found = _best_in_group(G, b[g], first, last, len(levels))
        if found is not None and (best is None or found[0] > best[0]):
            best = found
            instant = _instant(G[:n - len(levels), :n - len(levels)],
                               b[g][:n - len(levels)], first, found[1])
        col += n
    if best is None:
        return None
    stat, t0, step, std = best
    p = min(1.0, positions * chi2_sf(stat, 1))
    return LevelShift(t=float(used.t[instant] - used.t[0]), step=step, std=std, stat=stat,
                      positions=positions, p_value=p, alpha=alpha)


def _instant(G: np.ndarray, b: np.ndarray, first: int, t0: int) -> int:
    """The jump's sample: the statistic's break ``t0`` leaves the samples ``t0`` …
    ``t0`` + :data:`WINDOW` − 1 free (a spike there is not a shift), so the jump lies among
    them; it is where a plain step (no sample free) fits best."""
    best, at = -1.0, t0
    for t in range(max(first, t0 - 1), min(t0 + WINDOW, first + G.shape[0] - 1) + 1):
        c = np.zeros(G.shape[0])
        c[0] = 1.0
        c[1:1 + t - first] = -1.0
        xx = float(c @ G @ c)
        if xx > 0.0 and float(c @ b) ** 2 / xx > best:
            best, at = float(c @ b) ** 2 / xx, t
    return at


def _best_in_group(G: np.ndarray, b: np.ndarray, first: int, last: int, levels: int
                   ) -> tuple[float, int, float, float] | None:
    """The largest Z² over t₀ = ``first`` … ``last`` of one group: its columns are a step
    from ``first``, impulses at ``first``, ``first`` + 1, … and ``levels`` steps in T (the
    last; Gram matrix ``G``, inner products with ε ``b``); (Z², t₀, the step's estimate,
    its std)."""
    best = None
    tsteps = list(range(G.shape[0] - levels, G.shape[0]))
    for t0 in range(first, last + 1):
        c = np.zeros(G.shape[0])
        c[0] = 1.0
        c[1:1 + t0 - first] = -1.0  # the step from t₀
        nuis = [1 + t0 - first + j for j in range(WINDOW)
                if 1 + t0 - first + j < G.shape[0] - levels] + tsteps
        Gn = G[np.ix_(nuis, nuis)]
        gx = G[nuis] @ c
        pinv = np.linalg.pinv(Gn, rcond=1e-10, hermitian=True)
        xx = float(c @ G @ c - gx @ pinv @ gx)
        if not xx > 1e-12 * max(float(c @ G @ c), 1e-300):
            continue
        xe = float(c @ b - gx @ pinv @ b[nuis])
        z2 = xe * xe / xx
        if best is None or z2 > best[0]:
            best = (z2, t0, xe / xx, 1.0 / float(np.sqrt(xx)))
    return best


def _basis(A: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the columns of ``A`` (its numerical rank's)."""
    if A.shape[1] == 0:
        return np.zeros((A.shape[0], 0))
    U, s, _ = np.linalg.svd(A, full_matrices=False)
    return U[:, s > 1e-10 * max(float(s[0]), 1e-300)]
