"""The paper's least squares (Algorithm 1), measurements taken as error-free.

Euler form of model (1) with an optional bias b (Y = ε + b):

    ΔY_k = Y_k − Y_{k−1} = −β Δt (Y_r − b) + γ Δt T_k + e_k,   X = [β, γ, βb]ᵀ
    X̂ = (HᵀH)⁻¹ Hᵀ ΔY,   h_k = [−Y_r Δt, T_k Δt, Δt]

with ``Y_r = Y_{k−1}`` (standard regression, default) or ``Y_r = Y_k`` (the printed text's
literal form, which correlates with the noise; offered for comparison only).
σ follows from the equation-error variance, var e = 2σ²βΔt (Euler), and the measurement
noise σ_v from the residuals' lag-1 autocovariance, which white noise v makes −φσ_v².
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...errors import IdentificationError, ModelError
from ..data import MIN_TEMP_SPAN, Samples
from ..model import Model
from ..results import Estimate, FitResult
from ..validate import prepare, require_samples

SUPPORTED = {"markov", "temp", "bias", "white"}


def check_lsq_model(model: Model) -> None:
    """Raise :class:`ModelError` for a model least squares cannot represent."""
    extra = [n for n in model.names if n not in SUPPORTED]
    procs = [t.name for t in model.terms if t.role == "process"]
    if len(procs) > 1:
        raise ModelError(
            f"lsq cannot represent a sum of random processes ({' + '.join(procs)}): least "
            "squares has a single equation error and takes the measurements as error-free. "
            "Use --method lkf or --method ml"
        )
    if "markov" not in model.names:
        raise ModelError("lsq needs the 'markov' term (it regresses the drift's increments)")
    if extra:
        raise ModelError(f"lsq does not support the term(s) {', '.join(extra)}; use ml")


class GivensQR:
    """The triangular factor of the rows seen so far, updated one row at a time.

    Rows h_k (p,) with right-hand side d_k. After n rows, R (p×p, upper triangular) and z
    satisfy [H d] = Q [[R z], [0 e]] for some orthogonal Q, so

        X = R⁻¹ z,    RSS = Σ e² (= ‖d − H X‖²),    (HᵀH)⁻¹ = R⁻¹ R⁻ᵀ.

    A row is rotated into R by p Givens rotations, O(p²) per row and O(p²) to solve,
    without forming HᵀH: the solution's accuracy follows κ(H), not κ(H)² as the normal
    equations'. Plain Python floats: p is 1–3 here, where numpy's per-call overhead
    would dominate (a 3×3 ``np.linalg.cond`` + ``solve`` + ``inv`` per bin costs ~10×).
    """

    __slots__ = ("p", "R", "z", "rss", "n", "c_hd", "c_hh")

    def __init__(self, p: int) -> None:
        self.p = p
        self.R = [[0.0] * p for _ in range(p)]
        self.z = [0.0] * p
        self.rss = 0.0
        self.n = 0
        # Σ(h_k d_{k−1} + h_{k−1} d_k) and Σ h_k h_{k−1}ᵀ over consecutive rows (LsqStats)
        self.c_hd = [0.0] * p
        self.c_hh = [[0.0] * p for _ in range(p)]

    def add_pair(self, h: list[float], d: float, h1: list[float], d1: float) -> None:
        """The lag-1 sums of a row ``(h, d)`` whose previous row ``(h1, d1)`` is
        consecutive (as :meth:`LsqStats.add_row` does with numpy)."""
        c_hd, c_hh = self.c_hd, self.c_hh
        for i in range(self.p):
            hi = h[i]
            c_hd[i] += hi * d1 + h1[i] * d
            row = c_hh[i]
            for j in range(self.p):
                row[j] += hi * h1[j]

    def lag_terms(self, X: np.ndarray) -> tuple[float, float]:
        """``(X·c_hd, Xᵀ c_hh X)``."""
        x = X.tolist()
        p = self.p
        a = sum(x[i] * self.c_hd[i] for i in range(p))
        b = sum(x[i] * self.c_hh[i][j] * x[j] for i in range(p) for j in range(p))
        return a, b

    def add(self, h: list[float], d: float) -> None:
        a = list(h)
        R, z, p = self.R, self.z, self.p
        for i in range(p):
            ai = a[i]
            if ai == 0.0:
                continue
            Ri = R[i]
            r = math.hypot(Ri[i], ai)
            c, s = Ri[i] / r, ai / r
            Ri[i] = r
            for j in range(i + 1, p):
                rij, aj = Ri[j], a[j]
                Ri[j] = c * rij + s * aj
                a[j] = c * aj - s * rij
            zi = z[i]
            z[i] = c * zi + s * d
            d = c * d - s * zi
        self.rss += d * d
        self.n += 1

    def inverse(self) -> list[list[float]] | None:
        """R⁻¹ (upper triangular), or None when a diagonal element is 0."""
        R, p = self.R, self.p
        inv = [[0.0] * p for _ in range(p)]
        for i in range(p - 1, -1, -1):
            if R[i][i] == 0.0:
                return None
            inv[i][i] = 1.0 / R[i][i]
            for j in range(i + 1, p):
                acc = 0.0
                for m in range(i + 1, j + 1):
                    acc += R[i][m] * inv[m][j]
                inv[i][j] = -acc / R[i][i]
        return inv

    def solution(self) -> tuple[np.ndarray, float, np.ndarray, float] | None:
        """``(X, RSS, (HᵀH)⁻¹, κ₁(R)²)`` or None while R is singular. κ₁(R)² (the 1-norm
        condition number of R, squared) stands for κ(HᵀH) in the collinearity check."""
        inv = self.inverse()
        if inv is None:
            return None
        p, R, z = self.p, self.R, self.z
        X = [sum(inv[i][j] * z[j] for j in range(i, p)) for i in range(p)]
        cov = [[sum(inv[i][m] * inv[j][m] for m in range(max(i, j), p)) for j in range(p)]
               for i in range(p)]
        n1 = max(sum(abs(R[i][j]) for i in range(j + 1)) for j in range(p))
        ni = max(sum(abs(inv[i][j]) for i in range(j + 1)) for j in range(p))
        return np.array(X), self.rss, np.array(cov), (n1 * ni) ** 2


@dataclass
class LsqStats:
    """Sufficient statistics of the regression, accumulated row by row or in one go.

    Rows k have h_k (p,) and d_k = ΔY_k. With ``recursive=True`` (the online LSQ) the rows
    go into a :class:`GivensQR` instead of HᵀH and Hᵀd (left at zero), O(p²) per row and
    per solve in plain floats. Besides HᵀH, Hᵀd and dᵀd, the sums over
    *consecutive* rows (k−1, k) give the residuals' lag-1 autocovariance without storing
    the residuals: Σ r_k r_{k−1} = Σ d_k d_{k−1} − X·Σ(h_k d_{k−1} + h_{k−1} d_k)
    + Xᵀ(Σ h_k h_{k−1}ᵀ)X.
    """

    p: int
    recursive: bool = False
    HtH: np.ndarray = field(init=False)
    Htd: np.ndarray = field(init=False)
    dd: float = 0.0
    n: int = 0
    c_dd: float = 0.0
    c_hd: np.ndarray = field(init=False)
    c_hh: np.ndarray = field(init=False)
    n_pairs: int = 0
    y_sum: float = 0.0
    y_sq: float = 0.0
    n_y: int = 0

    def __post_init__(self) -> None:
        self.HtH = np.zeros((self.p, self.p))
        self.Htd = np.zeros(self.p)
        self.c_hd = np.zeros(self.p)
        self.c_hh = np.zeros((self.p, self.p))
        self.qr = GivensQR(self.p) if self.recursive else None

    def add_rows(self, H: np.ndarray, d: np.ndarray, pairs: np.ndarray) -> None:
        """Add rows ``H`` (n, p), ``d`` (n,); ``pairs`` indexes rows i with i−1 consecutive."""
        if self.qr is not None:
            rows_, ds, prev = H.tolist(), d.tolist(), set(pairs.tolist())
            for i, (h, dk) in enumerate(zip(rows_, ds, strict=True)):
                self.add_row_recursive(h, dk, (rows_[i - 1], ds[i - 1]) if i in prev else None)
            return
        self.HtH += H.T @ H
        self.Htd += H.T @ d
        self.dd += float(d @ d)
        self.n += d.size
        self.c_dd += float(d[pairs] @ d[pairs - 1])
        self.c_hd += H[pairs].T @ d[pairs - 1] + H[pairs - 1].T @ d[pairs]
        self.c_hh += H[pairs].T @ H[pairs - 1]
        self.n_pairs += pairs.size

    def add_row(self, h: np.ndarray, d: float, prev: tuple[np.ndarray, float] | None) -> None:
        """Add one row; ``prev`` is the previous row when it is consecutive."""
        if self.qr is not None:
            self.add_row_recursive(h.tolist(), d, None if prev is None
                                   else (prev[0].tolist(), prev[1]))
            return
        self.HtH += np.outer(h, h)
        self.Htd += h * d
        self.dd += d * d
        self.n += 1
        if prev is not None:
            h1, d1 = prev
            self.c_dd += d * d1
            self.c_hd += h * d1 + h1 * d
            self.c_hh += np.outer(h, h1)
            self.n_pairs += 1

    def add_row_recursive(self, h: list[float], d: float,
                          prev: tuple[list[float], float] | None) -> None:
        """:meth:`add_row` in plain floats, into the recursive factor (``recursive=True``)."""
        qr = self.qr
        assert qr is not None
        qr.add(h, d)
        self.dd += d * d
        self.n += 1
        if prev is not None:
            h1, d1 = prev
            self.c_dd += d * d1
            qr.add_pair(h, d, h1, d1)
            self.n_pairs += 1

    def add_y(self, y: np.ndarray) -> None:
        self.y_sum += float(np.sum(y))
        self.y_sq += float(y @ y)
        self.n_y += y.size

    @property
    def y_std(self) -> float:
        m = self.y_sum / max(self.n_y, 1)
        return float(np.sqrt(max(self.y_sq / max(self.n_y, 1) - m * m, 0.0)))


#: κ(HᵀH) above which the regressors count as collinear
COLLINEAR = 1e14


def regressor_names(model: Model) -> list[str]:
    return ["markov.beta"] + (["temp.gamma"] if "temp" in model else []) \
        + (["bias.c"] if "bias" in model else [])


def rows(model: Model, dt: float, y_prev: np.ndarray, y_cur: np.ndarray, T_cur: np.ndarray,
         regressor: str) -> tuple[np.ndarray, np.ndarray]:
    """Regression rows h_k = [−Y_r Δt, T_k Δt, Δt] and d_k = Y_k − Y_{k−1}."""
    yr = y_prev if regressor == "previous" else y_cur
    cols = [-yr * dt]
    if "temp" in model:
        cols.append(T_cur * dt)
    if "bias" in model:
        cols.append(np.full(yr.size, dt))
    return np.column_stack(cols), y_cur - y_prev


def solve(st: LsqStats, model: Model, dt: float, sigma: float | None,
          warnings: list[str], temp_constant: bool = False
          ) -> tuple[dict[str, Estimate], np.ndarray, np.ndarray, float]:
    """Estimates from the statistics: ``(params, X, cov, s2)``."""
    names = regressor_names(model)
    p = len(names)
    has_temp, has_bias = "temp" in model, "bias" in model
    got = st.qr.solution() if st.qr is not None and st.qr.n == st.n else None
    cond = got[3] if got is not None else (np.linalg.cond(st.HtH) if st.qr is None else np.inf)
    if not np.isfinite(cond) or cond > COLLINEAR:
        raise IdentificationError(
            "lsq: the regressors are collinear "
            + ("(the temperature is constant, so temp.gamma and bias.b cannot be told apart)"
               if has_temp and has_bias and temp_constant else "(the data do not vary enough)")
        )
    if got is not None:  # the recursive factor: O(p²), no HᵀH formed
        X, rss, HtH_inv = got[0], got[1], got[2]
    else:
        X = np.linalg.solve(st.HtH, st.Htd)
        rss = max(st.dd - 2 * float(X @ st.Htd) + float(X @ st.HtH @ X), 0.0)
        HtH_inv = np.linalg.inv(st.HtH)
    n = st.n
    s2 = rss / (n - p)
    cov = s2 * HtH_inv
    beta = float(X[0])
    est: dict[str, Estimate] = {}
    est["markov.beta"] = Estimate(beta, float(np.sqrt(cov[0, 0])), "1/s")
    if beta <= 0:
        warnings.append(
            f"lsq: beta = {beta:.3g} <= 0: the drift does not revert to a mean on this record; "
            "sigma cannot be derived from it"
        )
    # measurement noise from the residuals' lag-1 autocovariance: E r_k r_{k-1} = -phi sigma_v^2
    phi = 1.0 - beta * dt
    if st.n_pairs > 10:
        a, b = (st.qr.lag_terms(X) if got is not None and st.qr is not None
                else (float(X @ st.c_hd), float(X @ st.c_hh @ X)))
        c1 = (st.c_dd - a + b) / st.n_pairs
        sv2 = max(0.0, -c1 / phi) if phi > 0 else 0.0
        sv2_std = s2 / np.sqrt(st.n_pairs) / max(phi, 1e-12)
    else:
        sv2, sv2_std = 0.0, s2
    sv = float(np.sqrt(sv2))
    sv_std = float(sv2_std / (2 * sv)) if sv > np.sqrt(sv2_std) else float(np.sqrt(sv2_std))
    if sv2 > 2 * sv2_std:
        warnings.append(
            f"lsq: the residuals show measurement noise (white.sigma ≈ {sv:.3g}); least "
            "squares assumes error-free measurements and is biased by it — prefer ml"
        )
    # process noise: var e = q + sigma_v^2 (1 + phi^2), q = 2 sigma^2 beta dt (Euler)
    qv = max(s2 - sv2 * (1 + phi * phi), 1e-3 * s2)
    if sigma is not None:
        est["markov.sigma"] = Estimate(float(sigma), 0.0, "y", fixed=True)
    elif beta > 0:
        sig = float(np.sqrt(qv / (2 * beta * dt)))
        rel = np.sqrt(2.0 / (n - p) + cov[0, 0] / beta**2)
        est["markov.sigma"] = Estimate(sig, float(sig * rel / 2), "y")
    else:
        sig = st.y_std
        est["markov.sigma"] = Estimate(sig, sig, "y")
    j = 1
    if has_temp:
        est["temp.gamma"] = Estimate(float(X[j]), float(np.sqrt(cov[j, j])), "y/(s*degC)")
        j += 1
    est["white.sigma"] = Estimate(sv, sv_std, "y")
    if has_bias:
        c = float(X[j])
        if beta != 0:
            grad = np.zeros(p)
            grad[0], grad[j] = -c / beta**2, 1.0 / beta
            est["bias.b"] = Estimate(c / beta, float(np.sqrt(grad @ cov @ grad)), "y")
        else:
            est["bias.b"] = Estimate(0.0, st.y_std, "y")
            warnings.append("lsq: beta = 0, bias.b undefined; reported as 0")
    return {k: est[k] for k in model.param_names}, X, cov, s2


def lsq(samples: Samples, model: Model, *, regressor: str = "previous",
        sigma: float | None = None) -> FitResult:
    """Fit by least squares. ``regressor``: ``"previous"`` (Y_{k−1}) or ``"current"`` (Y_k).

    ``sigma`` fixes ``markov.sigma`` in the report (the regression does not use it).
    """
    check_lsq_model(model)
    check_regressor(regressor)
    samples = prepare(samples, "lsq")
    warnings = list(samples.warnings)
    dt = samples.dt
    y, T = samples.drift, samples.temp
    idx = np.flatnonzero(np.isfinite(y[1:]) & np.isfinite(y[:-1])) + 1  # Y_k and Y_{k-1}
    names = regressor_names(model)
    require_samples(samples, idx.size, len(names) + 2, "lsq")
    H, d = rows(model, dt, y[idx - 1], y[idx], T[idx], regressor)
    st = LsqStats(len(names))
    st.add_rows(H, d, np.flatnonzero(np.diff(idx) == 1) + 1)
    st.add_y(y[np.isfinite(y)])
    params, X, cov, s2 = solve(st, model, dt, sigma, warnings,
                               temp_constant=samples.temp_span < MIN_TEMP_SPAN)
    residuals = np.full(samples.t.size, np.nan)
    residuals[idx] = d - H @ X
    return FitResult(
        method="lsq", model=model, parameters=params, loglik=None, residuals=residuals,
        residual_var=np.full(samples.t.size, s2), warnings=tuple(warnings),
        source=samples.source, n_samples=len(samples), n_observed=samples.n_observed,
        dt=dt, covariance=cov, cov_names=tuple(names),
        info={"regressor": regressor, "discretization": "euler", "equation_error_var": s2},
    )


def check_regressor(regressor: str) -> None:
    if regressor not in ("previous", "current"):
        raise ModelError(f"regressor must be 'previous' or 'current', got {regressor!r}")


class OnlineLSQ:
    """Least squares updated one sample at a time, for the daemon.

    Each sample costs O(p²) (a Givens rotation of its row into the triangular factor,
    :class:`GivensQR`) and so does each solve: no HᵀH, no SVD per bin. After the same
    samples, :meth:`estimates` agrees with :func:`lsq` on them (normal equations) to
    ~1e-12 relative on the paper's records (tested to 1e-9).
    """

    def __init__(self, model: Model, dt: float, *, regressor: str = "previous",
                 sigma: float | None = None):
        check_lsq_model(model)
        check_regressor(regressor)
        self.model, self.dt, self.regressor, self.sigma = model, float(dt), regressor, sigma
        self.stats = LsqStats(len(regressor_names(model)), recursive=True)
        self._previous = regressor == "previous"
        self._temp, self._bias = "temp" in model, "bias" in model
        self._prev_y = float("nan")
        self._last_row: tuple[list[float], float] | None = None
        self.k = 0

    def update(self, y: float, T: float) -> None:
        """Add one sample (``y`` NaN = gap)."""
        self.k += 1
        if y != y:  # NaN: a gap
            self._prev_y = y
            self._last_row = None
            return
        st = self.stats
        st.y_sum += y
        st.y_sq += y * y
        st.n_y += 1
        yp = self._prev_y
        if yp == yp:  # not NaN: the row of :func:`rows`, in plain floats
            dt = self.dt
            h = [-(yp if self._previous else y) * dt]
            if self._temp:
                h.append(T * dt)
            if self._bias:
                h.append(dt)
            d = y - yp
            st.add_row_recursive(h, d, self._last_row)
            self._last_row = (h, d)
        self._prev_y = y

    @property
    def ready(self) -> bool:
        return self.stats.n >= self.stats.p + 2

    def estimates(self) -> tuple[dict[str, Estimate], list[str]]:
        """Current estimates and warnings (raises ``IdentificationError`` while collinear)."""
        warnings: list[str] = []
        params, *_ = solve(self.stats, self.model, self.dt, self.sigma, warnings)
        return params, warnings
