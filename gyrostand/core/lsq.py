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

import numpy as np

from ..errors import IdentificationError, ModelError
from .data import Samples
from .model import Model
from .results import Estimate, FitResult
from .validate import require_samples

SUPPORTED = {"markov", "temp", "bias", "white"}


def check_lsq_model(model: Model) -> None:
    """Raise :class:`ModelError` for a model least squares cannot represent."""
    extra = [n for n in model.names if n not in SUPPORTED]
    procs = [n for n in model.names if n in ("markov", "random_walk", "markov2")]
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


def lsq(samples: Samples, model: Model, *, regressor: str = "previous",
        sigma: float | None = None) -> FitResult:
    """Fit by least squares. ``regressor``: ``"previous"`` (Y_{k−1}) or ``"current"`` (Y_k).

    ``sigma`` fixes ``markov.sigma`` in the report (the regression does not use it).
    """
    check_lsq_model(model)
    if regressor not in ("previous", "current"):
        raise ModelError(f"regressor must be 'previous' or 'current', got {regressor!r}")
    warnings = list(samples.warnings)
    dt = samples.dt
    y, T = samples.drift, samples.temp
    ok = np.isfinite(y[1:]) & np.isfinite(y[:-1])
    idx = np.flatnonzero(ok) + 1  # rows k with Y_k and Y_{k-1}
    names = ["markov.beta"] + (["temp.gamma"] if "temp" in model else []) \
        + (["bias.c"] if "bias" in model else [])
    require_samples(samples, idx.size, len(names) + 2, "lsq")
    yr = y[idx - 1] if regressor == "previous" else y[idx]
    cols = [-yr * dt]
    if "temp" in model:
        cols.append(T[idx] * dt)
    if "bias" in model:
        cols.append(np.full(idx.size, dt))
    H = np.column_stack(cols)
    dY = y[idx] - y[idx - 1]
    HtH = H.T @ H
    cond = np.linalg.cond(HtH)
    if not np.isfinite(cond) or cond > 1e14:
        raise IdentificationError(
            "lsq: the regressors are collinear "
            + ("(the temperature is constant, so temp.gamma and bias.b cannot be told apart)"
               if "temp" in model and "bias" in model else "(the data do not vary enough)")
        )
    X = np.linalg.solve(HtH, H.T @ dY)
    res = dY - H @ X
    n, p = idx.size, len(names)
    s2 = float(res @ res) / (n - p)
    cov = s2 * np.linalg.inv(HtH)
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
    cons = np.flatnonzero(np.diff(idx) == 1)
    if cons.size > 10:
        c1 = float(np.mean(res[cons + 1] * res[cons]))
        sv2 = max(0.0, -c1 / phi) if phi > 0 else 0.0
        sv2_std = s2 / np.sqrt(cons.size) / max(phi, 1e-12)
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
        sig = float(np.nanstd(y))
        est["markov.sigma"] = Estimate(sig, sig, "y")
    j = 1
    if "temp" in model:
        est["temp.gamma"] = Estimate(float(X[j]), float(np.sqrt(cov[j, j])), "y/(s*degC)")
        j += 1
    est["white.sigma"] = Estimate(sv, sv_std, "y")
    if "bias" in model:
        c = float(X[j])
        if beta != 0:
            b = c / beta
            grad = np.zeros(p)
            grad[0], grad[j] = -c / beta**2, 1.0 / beta
            est["bias.b"] = Estimate(b, float(np.sqrt(grad @ cov @ grad)), "y")
        else:
            est["bias.b"] = Estimate(0.0, float(np.nanstd(y)), "y")
            warnings.append("lsq: beta = 0, bias.b undefined; reported as 0")
    params = {k: est[k] for k in model.param_names}
    residuals = np.full(samples.t.size, np.nan)
    residuals[idx] = res
    return FitResult(
        method="lsq", model=model, parameters=params, loglik=None, residuals=residuals,
        residual_var=np.full(samples.t.size, s2), warnings=tuple(warnings),
        source=samples.source, n_samples=len(samples), n_observed=samples.n_observed,
        dt=dt, covariance=cov, cov_names=tuple(names),
        info={"regressor": regressor, "discretization": "euler", "equation_error_var": s2},
    )
