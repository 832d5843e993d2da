"""A shaped candidate's geometry: the shape parameters of a term (a lag τ, a switching
width w), the log grid over them on which its regressor's direction is measured after the
current model's own tangents are projected out, and the curvature (Lipschitz–Killing
coefficients) of that curve or surface that calibrates the supremum of its LR over the
shape (:func:`~gyrostand.core.chisq.sup_chi2_sf`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..data import Samples
from ..ml.fit import Problem
from ..model import Model, context
from ..results import FitResult
from ..terms.builtin import POSITIVE_KINDS, TERMS
from ..threads import one_blas_thread
from ..validate import prepare

#: points of the log grid over a candidate's shape on which its regressor's geometry is
#: measured: along a one-parameter shape; and along the first (a lag τ) and the second
#: (a switching width w) parameter of a two-parameter one. A sharp switch moves in time
#: with τ (the regressor changes fast along τ at the narrowest w), so that axis is finer:
#: measured on a 6-h clean cycle, the length of hysteresis's narrowest-w edge is 4.6, 6.5,
#: 7.1, 7.4 at 15, 41, 81, 161 points, the other edges within 1 % from 15 points. On the
#: cli_latency 6-h run: temp_rate's length 1.1791 / 1.1782 and warmup's 3.9866 / 3.9812 at
#: 81 / 41 points; hysteresis's (rim, area) (3.3339, 1.2272) at 81 × 15, (3.3258, 1.2266)
#: at 81 × 9, in 0.9 and 0.55 s of CPU (both without extrapolation). Now 61 × 7:
#: hysteresis's (8.25, 7.67) measured on the 6-h run of benchmarks/diagnose_speed.py where a
#: 321 × 33 grid gives (8.40, 7.85) and 81 × 9 without the extrapolation (8.14, 7.54), in
#: 0.20 s of CPU instead of 0.34 (each curvature is extrapolated from the grid and its
#: every other point, :func:`_extrapolated`; the sizes are odd so that it nests)
SHAPE_POINTS = 41
SHAPE_POINTS_2D = (61, 7)
#: regressor columns filtered (and projected) together: the filter keeps their innovations,
#: n·m a sample, and sums no Gram matrix. 32 of a 61-point slice at a time: on a 24-h
#: record (86,400 samples) hysteresis's grid peaked at 302 MB of arrays with 96 (a whole
#: slice and its projection's N × 61 temporary at once), 220 MB now, the same numbers
FILTER_COLUMNS = 32


def shape_params(model: Model, term: str) -> tuple[str, ...]:
    """The parameters of ``term`` (in ``model``) that are searched and not identified when
    its coefficient is 0 — a lag, a switching width, a warm-up's time constant — if the
    term is one whose test is calibrated over them (:func:`shape_curvatures`): a
    deterministic term with one coefficient, its regressor shaped by one or two positive
    nonlinear parameters. Else ``()``."""
    cls = TERMS[term]
    if cls.n_states or cls.role == "modifier":
        return ()
    lin = [q for q in cls.params if q.kind == "linear"]
    shapes = tuple(f"{term}.{q.name}" for q in cls.params if q.kind in POSITIVE_KINDS)
    if len(lin) != 1 or not 1 <= len(shapes) <= 2:
        return ()
    return tuple(n for n in shapes if n in model.param_names)


def lag_params(model: Model, term: str) -> tuple[str, ...]:
    """A modifier's one positive parameter, not identified under the null (temp_lag's τ):
    the shape of its *chord* score (:func:`shape_grid`). Else ``()``."""
    cls = TERMS[term]
    if cls.role != "modifier" or cls.n_states or any(q.kind == "linear" for q in cls.params):
        return ()
    shapes = tuple(f"{term}.{q.name}" for q in cls.params if q.kind in POSITIVE_KINDS)
    return shapes if len(shapes) == 1 and shapes[0] in model.param_names else ()


def shape_curvatures(samples: Samples, model: Model, base: FitResult, term: str,
                     seen: Callable[[np.ndarray], None] | None = None
                     ) -> tuple[float, ...]:
    """The Lipschitz–Killing curvatures of ``term``'s shape range in the metric of its
    score process under the current model (the null), for :func:`~.chisq.sup_chi2_sf`.

    At the null fit, the LR of the coefficient at a fixed shape θ is asymptotically Z(θ)²,
    Z(θ) the efficient score x(θ)'ε / √(x(θ)'M x(θ)): ε the whitened innovations (iid
    N(0, 1)), x(θ) the term's regressor through the current model's Kalman filter,
    whitened, and M the metric of :func:`efficient_metric` (the current parameters
    readjust with the candidate). As a Gaussian process Z(θ) = u(θ)'ε with
    u(θ) = √M x(θ) / ‖√M x(θ)‖; the curvatures are those of the curve (or surface) u(θ)
    on the unit sphere: its length (L₁); half its boundary's length (L₁) and its area
    (L₂) for a two-parameter shape, from the angles between neighbouring grid points.
    Measured on clean 2-h cycles: Z(3 s)² of temp_rate 1.36, 2.29, 1.14 against its refit
    LR at τ = 3 s of 1.35, 2.38, 1.19. θ spans the refit's own search range (:class:`~gyrostand.core.ml.fit.Problem`'s
    bounds) on a log grid (:data:`SHAPE_POINTS`, :data:`SHAPE_POINTS_2D`).
    ``seen(U)``: called with each block of grid columns u(θ) as it is made (the score
    screen, :mod:`.screen`, takes Z(θ) = u(θ)'ε from the same pass).
    """
    with one_blas_thread():  # tiny algebra: see ml.ml
        return _shape_curvatures(samples, model, base, term, seen)


def as_runs(samples: Samples | tuple[Samples, ...]) -> tuple[Samples, ...]:
    """The runs a diagnosis studies: one, or several fitted jointly (a tuple)."""
    return samples if isinstance(samples, tuple) else (samples,)


def _tangent_names(model: Model, p: dict[str, float]) -> tuple[list[str], list[str]]:
    """The parameters of ``model`` whose mean tangents :func:`mean_tangents` takes at
    ``p`` (model names): the coefficients, and the positive nonlinear parameters the mean
    moves with; and the latter alone."""
    lin = list(model.names_of_kind("linear"))
    nonlin = [n for n, q in model.params if q.kind in POSITIVE_KINDS and lin
              and p.get(n, 0.0) > 0]
    return lin + nonlin, nonlin


def shape_grid(samples: Samples | tuple[Samples, ...], model: Model, base: Any, term: str
               ) -> tuple[list[np.ndarray], Any]:
    """The log grid over ``term``'s shape (one axis per shape parameter, spanning the
    refit's search range) and ``unit(zs)``: u(θ) at log shape values ``zs``, shape
    (observed samples, len(zs)) (see :func:`shape_curvatures`). Several runs (a tuple,
    ``base`` their joint fit, :func:`~.multirun.joint_ml`): the score is the sum of the
    runs' scores, so u(θ) stacks the runs' whitened regressors, and the metric is that of
    the joint fit (a per-run coefficient, the bias, has its own column in each run).

    A modifier (:func:`lag_params`: temp_lag's τ) has no coefficient of its own; its u(τ)
    is the *chord* D(τ) = X(T_τ)θ − X(T)θ — the current mean with the modifier at τ less
    the current mean, the coefficients held — through the same filter and metric: the lag
    model is a = 1 of the family X(T)θ + a·D(τ), whose efficient score at a = 0 tests the
    lag at τ (θ's readjustment is the metric's)."""
    from ..ml.joint_problem import JointProblem, run_key

    runs = as_runs(samples)
    joint = isinstance(samples, tuple)
    used_runs = [prepare(s, "candidates") for s in runs]
    bigger = model.add(term)
    shapes = shape_params(bigger, term)
    chord = not shapes  # a modifier: its chord D(τ) (:func:`lag_params`)
    if chord:
        shapes = lag_params(bigger, term)
    if joint:
        prob: Any = JointProblem(bigger, used_runs, {})
        per_run = prob.per_run

        def jname(n: str, r: int) -> str:
            return run_key(n, r) if n in per_run else n

        bounds = [prob.bounds[prob.znames.index(jname(n, 0))] for n in shapes]
        run_values = [prob.run_params(base.values, r) for r in range(len(runs))]
    else:
        bounds = [(lambda pr: pr.bounds[pr.znames.index(n)])(Problem(bigger, used_runs[0], {}))
                  for n in shapes]
        run_values = [dict(base.values)]

        def jname(n: str, r: int) -> str:
            return n

    owner = bigger.term_of(shapes[0])
    lin = "" if chord else owner.linear[0]
    coefs = model.names_of_kind("linear")
    # per run: (ctx, used, p0, ok, scale, whitened tangents, their joint names, and for a
    # chord the coefficients θ and the current mean X(T)θ)
    parts = []
    for r, (used, vals) in enumerate(zip(used_runs, run_values, strict=True)):
        ctx = context(used, bigger)
        names, Tx = mean_tangents(model, vals, ctx)  # its first columns: X(T), by coefs
        E, f = model.filter_columns(vals, used, Tx)
        ok = np.isfinite(E[:, 0]) & (f > 0)
        scale = 1.0 / np.sqrt(f[ok])
        mean = None
        if chord:
            theta = np.array([vals[n] for n in coefs])
            mean = (theta, Tx[:, :len(coefs)] @ theta)
        parts.append((ctx, used, vals if chord else {**vals, lin: 0.0}, ok, scale,
                      E[ok, 1:] * scale[:, None], [jname(n, r) for n in names], mean))
    cols = list(dict.fromkeys(n for part in parts for n in part[6]))
    T = np.zeros((sum(int(part[3].sum()) for part in parts), len(cols)))
    row = 0
    for part in parts:
        m = part[5].shape[0]
        for j, n in enumerate(part[6]):
            T[row:row + m, cols.index(n)] = part[5][:, j]
        row += m
    K, d = efficient_metric(T, cols, base)

    def unit(zs: list[tuple[float, ...]]) -> np.ndarray:
        """u(θ) at the log shape values ``zs``: (observed samples, len(zs)); a regressor
        the current model already explains wholly gives a zero column."""
        blocks = []
        for ctx, used, p0, ok, scale, _, _, mean in parts:
            # through the filter :data:`FILTER_COLUMNS` at a time (memory), each block's
            # regressors written into the filter's input as they are made
            C = np.empty((int(ok.sum()), len(zs)))
            every = bool(ok.all())
            for i in range(0, len(zs), FILTER_COLUMNS):
                chunk = zs[i:i + FILTER_COLUMNS]
                Y = np.empty((ctx.t.size, 1 + len(chunk)))
                for j, z in enumerate(chunk):
                    at = {**p0, **{n: float(np.exp(v)) for n, v in
                                   zip(shapes, z, strict=True)}}
                    if mean is None:
                        Y[:, 1 + j] = owner.regressors(at, ctx)[lin]
                    else:  # the chord: the mean with the modifier at θ less the mean
                        Y[:, 1 + j] = bigger.regressors(at, ctx) @ mean[0] - mean[1]
                E = model.filter_matrix(p0, used, Y)[0]
                C[:, i:i + len(chunk)] = E[:, 1:] if every else E[ok, 1:]
            C *= scale[:, None]
            blocks.append(C)
        C = blocks[0] if len(blocks) == 1 else np.vstack(blocks)
        if K is not None:
            M = d[:, None] * (K.T @ C)
            for i in range(0, C.shape[1], FILTER_COLUMNS):  # no N × len(zs) temporary
                C[:, i:i + FILTER_COLUMNS] -= K @ M[:, i:i + FILTER_COLUMNS]
        norm = np.sqrt(np.einsum("ij,ij->j", C, C))
        live = norm > 1e-9 * max(float(norm.max(initial=0.0)), 1e-300)
        C /= np.where(live, norm, 1.0)  # in place: no temporary the size of C
        C[:, ~live] = 0.0
        return C

    k = (SHAPE_POINTS,) if len(shapes) == 1 else SHAPE_POINTS_2D
    return [np.linspace(lo, hi, n) for (lo, hi), n in zip(bounds, k, strict=True)], unit


#: step (in the log of a parameter) of the numerical derivative of the current model's
#: mean in :func:`mean_tangents`
TANGENT_STEP = 1e-4


def mean_tangents(model: Model, p: Any, ctx: Any) -> tuple[list[str], np.ndarray]:
    """The current model's parameters its mean X(p)θ depends on, and the derivative of
    that mean in each (columns, per natural unit), at the parameters ``p`` (or a fit's):
    a coefficient's regressor, and for a positive nonlinear parameter the mean's change
    with it (β: the temperature's input goes through the drift's dynamics)."""
    p = p.values if hasattr(p, "values") and not isinstance(p, dict) else p
    lin = model.names_of_kind("linear")
    X = model.regressors(p, ctx)
    theta = np.array([p[n] for n in lin])
    names, cols = list(lin), [X[:, j] for j in range(X.shape[1])]
    for n, q in model.params:
        if q.kind not in POSITIVE_KINDS or not theta.size or not p.get(n, 0.0) > 0:
            continue
        h = TANGENT_STEP
        d = (model.regressors({**p, n: p[n] * float(np.exp(h))}, ctx)
             - model.regressors({**p, n: p[n] * float(np.exp(-h))}, ctx)) @ theta
        if np.any(d != 0.0):
            names.append(n)
            cols.append(d / (2 * h * p[n]))
    return names, (np.column_stack(cols) if cols else np.zeros((ctx.t.size, 0)))


def efficient_metric(T: np.ndarray, names: list[str], base: Any
                     ) -> tuple[np.ndarray | None, np.ndarray]:
    """``(K, d)`` with ``c − K (d ⊙ K'c)`` = √M c, M = I − T V T': the metric of the
    efficient score of a candidate's coefficient. ``T``: the whitened mean tangents,
    ``V``: the current fit's covariance of those parameters (the inverse of the whole
    information, the noise parameters' part included). At the null fit a
    candidate's score is x'ε; its variance, once the current parameters readjust with it,
    is x'Mx, not x'x: measured on clean 2-h cycles, x'Mx/x'x = 0.54–0.58 for temp_rate
    (β and γ move with it), the ratio of its LR to the score taken orthogonal to the
    regressors alone. Where the fit has no covariance, the regressors are projected out
    (M = I − P_T)."""
    if T.shape[1] == 0:
        return None, np.zeros(0)
    Q, R = np.linalg.qr(T)
    cov = base.covariance
    if cov is not None and all(n in base.cov_names for n in names):
        idx = [base.cov_names.index(n) for n in names]
        A = R @ cov[np.ix_(idx, idx)] @ R.T
        lam, W = np.linalg.eigh(0.5 * (A + A.T))
        lam = np.clip(lam, 0.0, 1.0)
    else:
        lam, W = np.ones(T.shape[1]), np.eye(T.shape[1])
    return Q @ W, 1.0 - np.sqrt(1.0 - lam)


_efficient_metric = efficient_metric  # the name tests/workbench/test_calibrated_candidates uses


def _shape_curvatures(samples: Samples, model: Model, base: FitResult, term: str,
                      seen: Callable[[np.ndarray], None] | None = None
                      ) -> tuple[float, ...]:
    axes, unit = shape_grid(samples, model, base, term)
    if seen is not None:
        made = unit

        def unit(zs: list[tuple[float, ...]]) -> np.ndarray:
            U = made(zs)
            seen(U)
            return U

    if len(axes) == 1:
        U = unit([(v,) for v in axes[0]])
        return (_extrapolated(_arcs(U).sum(), _arcs(U[:, ::2]).sum()),)
    ax_a, ax_b = axes
    kb = ax_b.size
    fine, coarse = _Surface(), _Surface()
    for j, w in enumerate(ax_b):  # one slice of the first parameter at a time: memory
        U = unit([(a, w) for a in ax_a])
        edge = j in (0, kb - 1)
        fine.add(U, edge)
        if j % 2 == 0:  # the grid of every other point along both axes (a copy: a view
            coarse.add(np.ascontiguousarray(U[:, ::2]), edge)  # kept the whole slice)
    return (_extrapolated(0.5 * fine.rim, 0.5 * coarse.rim),
            _extrapolated(fine.area, coarse.area))


def _dots(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.clip(np.einsum("ij,ij->j", a, b), -1.0, 1.0)


def _arcs(U: np.ndarray) -> np.ndarray:
    """Angles between consecutive columns of ``U``."""
    return np.arccos(_dots(U[:, 1:], U[:, :-1]))


def _extrapolated(fine: float, coarse: float) -> float:
    """Richardson's extrapolation of a length or an area measured by chords and flat
    triangles on a grid (``fine``) and on its every other point (``coarse``): the error of
    either is O(h²), so (4·fine − coarse)/3 cancels its leading term; never below
    ``fine`` (a finer polygon inscribed in the curve is never shorter)."""
    return float(max(fine, (4.0 * fine - coarse) / 3.0))


class _Surface:
    """The rim length and area of the surface u(θ) on the sphere, from its grid slices
    added one at a time (each cell as two flat triangles from its sides' chords)."""

    def __init__(self) -> None:
        self.rim = 0.0
        self.area = 0.0
        self.prev: tuple[np.ndarray, np.ndarray] | None = None

    def add(self, U: np.ndarray, edge: bool) -> None:
        """The next slice ``U`` (columns along the first axis); ``edge``: the first or
        the last slice (its length is rim)."""
        along = _arcs(U)
        if edge:
            self.rim += float(along.sum())
        if self.prev is not None:
            P, prev_along = self.prev
            across = np.arccos(_dots(U, P))  # (a, w_{j−1}) → (a, w_j)
            self.rim += float(across[0] + across[-1])
            diag = _dots(U[:, :-1], P[:, 1:])  # (a_i, w_j) · (a_{i+1}, w_{j−1})
            c_a_prev = 2 - 2 * np.cos(prev_along)
            c_a = 2 - 2 * np.cos(along)
            c_b = 2 - 2 * np.cos(across)
            c_d = 2 - 2 * diag
            self.area += float(_triangles(c_a_prev, c_b[:-1], c_d).sum()
                               + _triangles(c_a, c_b[1:], c_d).sum())
        self.prev = (U, along)


def _triangles(x2: np.ndarray, y2: np.ndarray, z2: np.ndarray) -> np.ndarray:
    """Areas of planar triangles from their squared side lengths (Heron's formula)."""
    s = 2 * (x2 * y2 + y2 * z2 + z2 * x2) - (x2 * x2 + y2 * y2 + z2 * z2)
    return 0.25 * np.sqrt(np.maximum(s, 0.0))
