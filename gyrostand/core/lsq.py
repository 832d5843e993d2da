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

from dataclasses import dataclass, field

import numpy as np

from ..errors import IdentificationError, ModelError
from .data import MIN_TEMP_SPAN, Samples
from .model import Model
from .results import Estimate, FitResult
from .validate import prepare, require_samples

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


@dataclass
class LsqStats:
    """Sufficient statistics of the regression, accumulated row by row or in one go.

    Rows k have h_k (p,) and d_k = ΔY_k. Besides HᵀH, Hᵀd and dᵀd, the sums over
    *consecutive* rows (k−1, k) give the residuals' lag-1 autocovariance without storing
    the residuals: Σ r_k r_{k−1} = Σ d_k d_{k−1} − X·Σ(h_k d_{k−1} + h_{k−1} d_k)
    + Xᵀ(Σ h_k h_{k−1}ᵀ)X.
    """

    p: int
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

    def add_rows(self, H: np.ndarray, d: np.ndarray, pairs: np.ndarray) -> None:
        """Add rows ``H`` (n, p), ``d`` (n,); ``pairs`` indexes rows i with i−1 consecutive."""
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

    def add_y(self, y: np.ndarray) -> None:
        self.y_sum += float(np.sum(y))
        self.y_sq += float(y @ y)
        self.n_y += y.size

    @property
    def y_std(self) -> float:
        m = self.y_sum / max(self.n_y, 1)
        return float(np.sqrt(max(self.y_sq / max(self.n_y, 1) - m * m, 0.0)))


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
    cond = np.linalg.cond(st.HtH)
    if not np.isfinite(cond) or cond > 1e14:
        raise IdentificationError(
            "lsq: the regressors are collinear "
            + ("(the temperature is constant, so temp.gamma and bias.b cannot be told apart)"
               if "temp" in model and "bias" in model and temp_constant else "(the data do not vary enough)")
        )
    X = np.linalg.solve(st.HtH, st.Htd)
    rss = max(st.dd - 2 * float(X @ st.Htd) + float(X @ st.HtH @ X), 0.0)
    n = st.n
    s2 = rss / (n - p)
    cov = s2 * np.linalg.inv(st.HtH)
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
        c1 = (st.c_dd - float(X @ st.c_hd) + float(X @ st.c_hh @ X)) / st.n_pairs
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
    if "temp" in model:
        est["temp.gamma"] = Estimate(float(X[j]), float(np.sqrt(cov[j, j])), "y/(s*degC)")
        j += 1
    est["white.sigma"] = Estimate(sv, sv_std, "y")
    if "bias" in model:
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

    After the same samples, :meth:`estimates` equals :func:`lsq` on them (the same
    statistics, summed in another order: equal to rounding).
    """

    def __init__(self, model: Model, dt: float, *, regressor: str = "previous",
                 sigma: float | None = None):
        check_lsq_model(model)
        check_regressor(regressor)
        self.model, self.dt, self.regressor, self.sigma = model, float(dt), regressor, sigma
        self.stats = LsqStats(len(regressor_names(model)))
        self._prev_y = float("nan")
        self._last_row: tuple[np.ndarray, float] | None = None
        self.k = 0

    def update(self, y: float, T: float) -> None:
        """Add one sample (``y`` NaN = gap)."""
        self.k += 1
        if np.isnan(y):
            self._prev_y = y
            self._last_row = None
            return
        self.stats.add_y(np.array([y]))
        if not np.isnan(self._prev_y):
            H, d = rows(self.model, self.dt, np.array([self._prev_y]), np.array([y]),
                        np.array([T]), self.regressor)
            self.stats.add_row(H[0], float(d[0]), self._last_row)
            self._last_row = (H[0], float(d[0]))
        self._prev_y = y

    @property
    def ready(self) -> bool:
        return self.stats.n >= len(regressor_names(self.model)) + 2

    def estimates(self) -> tuple[dict[str, Estimate], list[str]]:
        """Current estimates and warnings (raises ``IdentificationError`` while collinear)."""
        warnings: list[str] = []
        params, *_ = solve(self.stats, self.model, self.dt, self.sigma, warnings)
        return params, warnings
