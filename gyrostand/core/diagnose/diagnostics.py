"""Where the model fails: residual analysis of a maximum-likelihood fit.

Everything here works on a :class:`FitResult` of :func:`gyrostand.core.ml.fit.ml` and the
samples it was fitted to:

* one-step innovations e_k and their standardized form e_k/√f_k (white N(0, 1) when the
  model is right), and smoothed residuals y_k − ŷ_{k|N} (the smoothed measurement noise);
* RMS, the Ljung–Box whiteness test, normalized-innovation (NIS) consistency;
* cross-correlation of the standardized innovations with the *filtered* regressor of every
  candidate effect (the regressor passed through the same Kalman filter, i.e. prewhitened,
  as MATLAB's ``resid`` does) with ±1.96/√n bands;
* a table of residual mean / RMS per segment of the temperature profile (heating,
  cooling, soak) and the Allan deviation of the residuals.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..chisq import chi2_ppf, ljung_box
from ..data import Samples
from ..kalman import kf_run, kf_smooth
from ..model import Model, context
from ..results import FitResult
from ..terms.builtin import TERMS, Context, term_class

#: |dT/dt| below this (degC/s) is a soak: 0.05 degC/min
SOAK_RATE = 0.05 / 60.0
#: shortest segment reported (s)
MIN_SEGMENT_S = 120.0


def autocorrelation(z: np.ndarray, lags: int) -> np.ndarray:
    """Sample autocorrelation ρ_0..ρ_lags of ``z`` (NaN skipped)."""
    z = z[np.isfinite(z)]
    z = z - z.mean()
    d = float(z @ z) or 1.0
    return np.array([1.0] + [float(z[k:] @ z[:-k]) / d for k in range(1, lags + 1)])


def cross_correlation(a: np.ndarray, b: np.ndarray, lags: int) -> np.ndarray:
    """Normalized cross-correlation r_ab(τ) = corr(a_k, b_{k−τ}) for τ = −lags..lags."""
    ok = np.isfinite(a) & np.isfinite(b)
    a = np.where(ok, a - a[ok].mean(), 0.0)
    b = np.where(ok, b - b[ok].mean(), 0.0)
    d = float(np.sqrt((a @ a) * (b @ b))) or 1.0
    out = np.empty(2 * lags + 1)
    for i, tau in enumerate(range(-lags, lags + 1)):
        if tau >= 0:
            out[i] = float(a[tau:] @ b[: a.size - tau]) / d
        else:
            out[i] = float(a[:tau] @ b[-tau:]) / d
    return out


def allan_deviation(x: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Overlapping Allan deviation of a rate-like series ``x`` sampled every ``dt``.

    σ²(τ) = ½ ⟨(x̄_{k+m} − x̄_k)²⟩ with x̄ averages over m samples, τ = m·dt, m = 1, 2, 4, ...
    Gaps (NaN) are filled with the mean (they are few; the series is a residual).
    """
    x = np.where(np.isfinite(x), x, np.nanmean(x))
    n = x.size
    c = np.concatenate([[0.0], np.cumsum(x)])
    taus, devs = [], []
    m = 1
    while 2 * m < n // 2 or (m == 1 and n >= 3):
        avg = (c[m:] - c[:-m]) / m
        d = avg[m:] - avg[:-m]
        taus.append(m * dt)
        devs.append(float(np.sqrt(0.5 * np.mean(d * d))))
        m *= 2
    return np.array(taus), np.array(devs)


def segments(ctx: Context) -> list[dict[str, Any]]:
    """Heating / cooling / soak segments from the temperature rate (index ranges)."""
    rate = ctx.temp_rate
    # 1 heating, -1 cooling, 0 soak (a NaN rate too); a segment is a run of one code
    code = np.where(rate > SOAK_RATE, 1, np.where(rate < -SOAK_RATE, -1, 0))
    if code.size == 0:
        return []
    cut = (np.flatnonzero(code[1:] != code[:-1]) + 1).tolist()
    kind = {1: "heating", -1: "cooling", 0: "soak"}
    out: list[dict[str, Any]] = [
        {"kind": kind[int(code[a])], "start": a, "stop": b}
        for a, b in zip([0, *cut], [*cut, int(code.size)], strict=True)]
    # merge segments shorter than MIN_SEGMENT_S into their predecessor
    min_n = max(1, int(MIN_SEGMENT_S / ctx.dt))
    merged: list[dict[str, Any]] = []
    for s in out:
        if merged and (s["stop"] - s["start"] < min_n or s["kind"] == merged[-1]["kind"]):
            merged[-1]["stop"] = s["stop"]
        else:
            merged.append(dict(s))
    return merged


def candidate_regressor(term: str, ctx: Context, p: Mapping[str, float]) -> np.ndarray | None:
    """The signature of a candidate effect in the data (before filtering): the term's own
    :meth:`~gyrostand.core.terms.base.Term.signature` (output effects their regressor,
    input effects their response through the drift dynamics, ``temp_lag`` the change a
    small lag makes). None only where the term says so: it has no deterministic signature
    (``no_signature``: the random processes show in the autocorrelation instead), or the
    fitted model lacks a parameter the signature needs (``signature_needs``, e.g. no
    ``markov.beta`` to filter an input through). An unknown term is a ModelError; a term
    that neither has a signature nor says why not is one too, naming it.
    """
    cls = term_class(term)
    if cls.no_signature or any(k not in p for k in cls.signature_needs):
        return None
    return cls().signature(p, ctx)


@dataclass(frozen=True)
class ResidualDiagnostics:
    """Residual diagnostics of one fit (arrays aligned with the samples)."""

    innovations: np.ndarray
    standardized: np.ndarray
    smoothed: np.ndarray
    fitted: np.ndarray
    rms: float
    smoothed_rms: float
    ljung_box_q: float
    ljung_box_p: float
    lags: int
    nis_mean: float
    nis_band: tuple[float, float]
    acf: np.ndarray
    xcorr: Mapping[str, np.ndarray]
    band: float
    segments: tuple[dict[str, Any], ...]
    allan_tau: np.ndarray
    allan_dev: np.ndarray
    extra: Mapping[str, Any] = field(default_factory=dict)

    @property
    def white(self) -> bool:
        return self.ljung_box_p >= 0.01

    def to_dict(self) -> dict[str, Any]:
        return {
            "rms": self.rms, "smoothed_rms": self.smoothed_rms,
            "ljung_box_q": self.ljung_box_q, "ljung_box_p": self.ljung_box_p, "lags": self.lags,
            "nis_mean": self.nis_mean, "nis_band": list(self.nis_band),
            "segments": [dict(s) for s in self.segments],
            "xcorr_max": {k: float(np.max(np.abs(v))) for k, v in self.xcorr.items()},
            "xcorr_band": self.band,
        }


def diagnose_fit(result: FitResult, samples: Samples, *, lags: int | None = None,
                 xcorr_lags: int = 60) -> ResidualDiagnostics:
    """Residual diagnostics of an ML fit of ``result.model`` to ``samples``."""
    model: Model = result.model
    p = result.values
    ctx = context(samples, model)
    e = np.asarray(result.residuals, dtype=float)
    f = np.asarray(result.residual_var, dtype=float)
    z = e / np.sqrt(f)
    n = int(np.count_nonzero(np.isfinite(z)))
    # a short record cannot carry 60 lags: at most a quarter of its length
    xcorr_lags = max(1, min(xcorr_lags, len(samples) // 4))
    if lags is None:
        lags = int(min(max(10, np.log(max(n, 2))), max(1, n // 5)))
    q, pval = ljung_box(z, lags)
    nis = float(np.nanmean(z * z))
    band = (chi2_ppf(0.025, n) / n, chi2_ppf(0.975, n) / n)
    # smoothed residuals: y − deterministic part − smoothed stochastic part
    X = model.regressors(p, ctx)
    theta = np.array([p[k] for k in model.names_of_kind("linear")])
    det = X @ theta if theta.size else np.zeros(len(samples))
    ss = model.state_space(p, samples.dt)
    phi, qv, p0, r = ss.phi, ss.q, ss.p0, ss.r
    w = samples.noise_weights
    sm, _ = kf_smooth(phi, qv, p0, r, w, np.ascontiguousarray(samples.drift - det))
    smoothed = samples.drift - det - sm
    fitted = samples.drift - e
    # cross-correlation with every candidate's regressor, prewhitened by the same filter
    xcorr = {}
    for term in TERMS:
        if term in model.names:
            continue
        reg = candidate_regressor(term, ctx, p)
        if reg is None:
            continue
        Y = np.column_stack([np.where(np.isfinite(samples.drift), reg, np.nan), reg])
        E, ff, *_ = kf_run(phi, qv, p0, r, w, Y, True)
        xcorr[term] = cross_correlation(z, E[:, 1] / np.sqrt(ff), xcorr_lags)
    segs = []
    for s in segments(ctx):
        sl = slice(s["start"], s["stop"])
        es = e[sl][np.isfinite(e[sl])]
        segs.append({
            "kind": s["kind"], "t_start": float(samples.t[s["start"]]),
            "t_stop": float(samples.t[s["stop"] - 1]),
            "temp_start": float(samples.temp[s["start"]]),
            "temp_stop": float(samples.temp[s["stop"] - 1]),
            "n": int(es.size),
            "mean": float(es.mean()) if es.size else 0.0,
            "rms": float(np.sqrt(np.mean(es * es))) if es.size else 0.0,
            "smoothed_mean": float(np.nanmean(smoothed[sl])) if es.size else 0.0,
        })
    taus, adev = allan_deviation(smoothed, samples.dt)
    finite = np.isfinite(e)
    return ResidualDiagnostics(
        innovations=e, standardized=z, smoothed=smoothed, fitted=fitted,
        rms=float(np.sqrt(np.mean(e[finite] ** 2))),
        smoothed_rms=float(np.sqrt(np.nanmean(smoothed**2))),
        ljung_box_q=q, ljung_box_p=pval, lags=lags, nis_mean=nis, nis_band=band,
        acf=autocorrelation(z, xcorr_lags), xcorr=xcorr, band=float(1.96 / np.sqrt(max(n, 1))),
        segments=tuple(segs), allan_tau=taus, allan_dev=adev,
    )
