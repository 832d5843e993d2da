"""Allan-variance figures of a gyro, as IEEE Std 952 (Annex C) reports them.

The overlapping Allan variance of a rate series x (sampled every Δt, averaged over
τ = m·Δt; :func:`~gyrostand.core.diagnose.diagnostics.allan_deviation`, octave-spaced m) of a gyro
is the sum of its noise terms' contributions (IEEE Std 952-1997, C.1–C.5)::

    σ²(τ) = N²/τ  +  B_f²  +  K²·τ/3  +  R²·τ²/2
            ARW      bias     RRW        rate ramp
                     instab.

* **angle random walk N** (y·√s; the τ^−½ slope line read at τ = 1 s),
* **bias instability B** (y): the flat bottom of σ(τ) is B_f = B·√(2 ln 2/π) = 0.664·B,
  so B = min σ(τ) / 0.664, reported with the τ of that minimum,
* **rate random walk K** (y/√s; the τ^+½ slope line read at τ = 3 s),
* **rate ramp R** (y/s; the τ^+1 line at τ = √2 s): a trend, e.g. the thermal drift of a
  raw record.

The slope lines are fitted jointly: weighted least squares of σ̂²(τ_i) on the four terms
(each coefficient ≥ 0: every subset of terms is tried, the best non-negative one kept), with
weights edf_i / (2 σ²(τ_i)²) (Var σ̂² = 2σ⁴/edf), iterated so that the weights use the
fitted σ² and each τ's dominant noise type.

**Equivalent degrees of freedom** of the overlapping estimator at m (NIST TN 1337,
Howe–Allan–Barnes 1981), with N_p = n + 1 phase points of n rate samples:

    white FM (ARW):     edf = [3(N_p−1)/(2m) − 2(N_p−2)/N_p] · 4m²/(4m²+5)
    flicker FM (B):     edf = 2(N_p−2)²/(2.3N_p − 4.9)   (m = 1),   5N_p²/(4m(N_p+3m))
    random-walk FM (K): edf = (N_p−2)/m · [(N_p−1)² − 3m(N_p−1) + 4m²]/(N_p−3)²

(rate ramp: the random-walk formula). The confidence interval of σ²(τ) at level 1 − α is
[σ̂²·edf/χ²_{1−α/2}(edf), σ̂²·edf/χ²_{α/2}(edf)] (exact χ² quantiles, scipy.special). A
figure's interval is that of the τ where its term carries the largest share of the fitted
σ², with the other fitted terms at that τ subtracted; B's is that of its minimum. The
intervals are the statistical uncertainty of the estimator; they leave out the bias of
the slope-line reading where terms overlap (on a simulated gyro with the ARW/flat and
flat/RRW crossovers at 0.05 s and 100 s: N +1.8 %, B +1..3 %; tests/core/test_allan.py).

numpy, and scipy.special for the χ² quantile (not scipy.stats: its import costs ~0.6 s).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import DataError
from ..data import Samples
from ..model import Model, context
from ..results import FitResult
from .diagnostics import allan_deviation

__all__ = [
    "MIN_SAMPLES",
    "BIAS_FACTOR",
    "TERMS",
    "AllanFigure",
    "AllanTable",
    "allan_table",
    "drift_tables",
    "edf_overlapping",
    "chi2_quantile",
    "thermal_residual",
]

#: flat level of σ(τ) over bias instability B: √(2 ln 2 / π)
BIAS_FACTOR = math.sqrt(2.0 * math.log(2.0) / math.pi)
#: (name, power of τ in σ², factor c in σ² = c·X²·τ^p, noise type for the edf, read-at τ)
TERMS: tuple[tuple[str, int, float, str, float | None], ...] = (
    ("angle_random_walk", -1, 1.0, "white", 1.0),
    ("bias_instability", 0, BIAS_FACTOR**2, "flicker", None),
    ("rate_random_walk", 1, 1.0 / 3.0, "random_walk", 3.0),
    ("rate_ramp", 2, 0.5, "random_walk", math.sqrt(2.0)),
)
_SYMBOL = {"angle_random_walk": "N", "bias_instability": "B", "rate_random_walk": "K",
           "rate_ramp": "R"}


def edf_overlapping(n: int, m: np.ndarray, noise: np.ndarray | str) -> np.ndarray:
    """Equivalent degrees of freedom of the overlapping Allan variance of ``n`` rate
    samples at averaging factors ``m`` for ``noise`` 'white', 'flicker' or 'random_walk'
    (per m, or one for all); formulas in the module docstring.

    Examples:
        >>> [round(float(e), 1) for e in edf_overlapping(1000, np.array([1, 10, 100]),
        ...                                              "white")]
        [665.8, 146.2, 13.0]
    """
    m = np.asarray(m, dtype=float)
    kinds = np.broadcast_to(np.asarray(noise), m.shape)
    p = float(n + 1)
    white = (3 * (p - 1) / (2 * m) - 2 * (p - 2) / p) * 4 * m**2 / (4 * m**2 + 5)
    flicker = np.where(m == 1, 2 * (p - 2) ** 2 / (2.3 * p - 4.9), 5 * p**2 / (4 * m * (p + 3 * m)))
    rw = (p - 2) / m * ((p - 1) ** 2 - 3 * m * (p - 1) + 4 * m**2) / (p - 3) ** 2
    out = np.where(kinds == "white", white, np.where(kinds == "flicker", flicker, rw))
    return np.maximum(out, 1.0)


def chi2_quantile(q: float, nu: np.ndarray) -> np.ndarray:
    """The ``q`` quantile of χ²_ν, exact: 2 P⁻¹(ν/2, q), P the regularised lower
    incomplete gamma function (scipy.special.gammaincinv; what scipy.stats' ``chi2.ppf``
    computes). It replaced a Wilson–Hilferty approximation (16 % low at ν = 3, q = 2.5 %).

    >>> round(float(chi2_quantile(0.975, np.array(10.0))), 2), round(float(chi2_quantile(
    ...     0.025, np.array(10.0))), 2)
    (20.48, 3.25)
    """
    from scipy.special import gammaincinv

    nu = np.asarray(nu, dtype=float)
    return 2.0 * gammaincinv(0.5 * nu, q)


def _wls(X: np.ndarray, y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Non-negative weighted least squares over every subset of columns (≤ 4 columns)."""
    best, best_sse = np.zeros(X.shape[1]), math.inf
    sw = np.sqrt(w)
    for k in range(1, X.shape[1] + 1):
        for cols in itertools.combinations(range(X.shape[1]), k):
            A = X[:, cols] * sw[:, None]
            coef, *_ = np.linalg.lstsq(A, y * sw, rcond=None)
            if np.any(coef < 0):
                continue
            sse = float(np.sum((A @ coef - y * sw) ** 2))
            if sse < best_sse:
                best_sse = sse
                best = np.zeros(X.shape[1])
                best[list(cols)] = coef
    return best


@dataclass(frozen=True)
class AllanFigure:
    """One IEEE 952 figure: value, its confidence interval, the τ it was read at (s) and
    the τ whose point gave the interval (s); ``unit`` in terms of the drift unit y."""

    name: str
    symbol: str
    value: float
    lo: float
    hi: float
    unit: str
    tau_read: float | None
    tau_ci: float | None

    def to_dict(self) -> dict[str, Any]:
        return {"symbol": self.symbol, "value": self.value, "ci": [self.lo, self.hi],
                "unit": self.unit, "tau_read": self.tau_read, "tau_ci": self.tau_ci}


@dataclass(frozen=True)
class AllanTable:
    """The Allan deviation of a series and its IEEE 952 figures.

    ``tau`` (s), ``adev`` (y), ``edf``, ``lo``/``hi`` (the σ interval) per τ, shape (T,);
    ``figures`` by name (:data:`TERMS`); ``fit`` the fitted σ²(τ) coefficients
    ``N², B_f², K², R²`` by name; ``level`` the confidence level; ``n`` samples used.
    """

    label: str
    unit: str
    dt: float
    n: int
    level: float
    tau: np.ndarray
    adev: np.ndarray
    edf: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    figures: Mapping[str, AllanFigure]
    fitted_adev: np.ndarray
    warnings: tuple[str, ...] = field(default_factory=tuple)

    def to_dict(self) -> dict[str, Any]:
        return {
            "label": self.label, "unit": self.unit, "dt": self.dt, "n": self.n,
            "level": self.level,
            "figures": {k: f.to_dict() for k, f in self.figures.items()},
            "curve": {"tau": self.tau.tolist(), "adev": self.adev.tolist(),
                      "edf": self.edf.tolist(), "lo": self.lo.tolist(),
                      "hi": self.hi.tolist(), "fitted": self.fitted_adev.tolist()},
            "warnings": list(self.warnings),
        }


#: the fewest finite samples an Allan table is made of (τ up to n/8 needs a few octaves)
MIN_SAMPLES = 16


def _units(y: str) -> dict[str, str]:
    return {"angle_random_walk": f"{y}·√s", "bias_instability": y,
            "rate_random_walk": f"{y}/√s", "rate_ramp": f"{y}/s"}


def allan_table(x: np.ndarray, dt: float, *, unit: str = "y", label: str = "series",
                level: float = 0.95, iterations: int = 4) -> AllanTable:
    """Allan deviation of the rate series ``x`` (shape (n,), NaN gaps filled linearly;
    sampled every ``dt`` s) and its IEEE 952 figures with ``level`` intervals.

    Raises :class:`~gyrostand.errors.DataError` (a ValueError) for fewer than
    :data:`MIN_SAMPLES` finite samples."""
    x = np.asarray(x, dtype=float)
    n = int(x.size)
    if int(np.count_nonzero(np.isfinite(x))) < MIN_SAMPLES:
        raise DataError(f"{label}: an Allan table needs at least {MIN_SAMPLES} samples, got "
                        f"{int(np.count_nonzero(np.isfinite(x)))}")
    warnings: list[str] = []
    finite = np.isfinite(x)
    gaps = n - int(np.count_nonzero(finite))
    if gaps:
        # linear between the neighbours: a constant fill (the mean) would put a spike into
        # a wandering raw drift and raise the white-noise level
        k = np.arange(n)
        x = np.interp(k, k[finite], x[finite])
        warnings.append(f"{gaps} gap(s) filled linearly between their neighbours")
    tau, adev = allan_deviation(x, dt)
    ok = np.isfinite(adev) & (adev > 0)
    tau, adev = tau[ok], adev[ok]
    m = np.rint(tau / dt)
    avar = adev**2
    X = np.column_stack([c * tau**p for _, p, c, _, _ in TERMS])
    kinds = np.full(tau.shape, "white", dtype=object)
    fitted = avar.copy()
    coef = np.zeros(len(TERMS))
    for _ in range(iterations):
        edf = edf_overlapping(n, m, kinds.astype(str))
        coef = _wls(X, avar, edf / (2.0 * np.maximum(fitted, 1e-300) ** 2))
        parts = X * coef
        fitted = np.maximum(parts.sum(axis=1), 1e-300)
        kinds = np.array([TERMS[int(i)][3] for i in np.argmax(parts, axis=1)], dtype=object)
    edf = edf_overlapping(n, m, kinds.astype(str))
    alpha = 1.0 - level
    lo_f = edf / chi2_quantile(1.0 - alpha / 2, edf)  # σ² interval, relative
    hi_f = edf / chi2_quantile(alpha / 2, edf)
    units = _units(unit)
    parts = X * coef
    figures: dict[str, AllanFigure] = {}
    for j, (name, _p, _c, _k, read) in enumerate(TERMS):
        if name == "bias_instability":
            i = int(np.argmin(adev))
            if i == tau.size - 1:
                warnings.append("bias_instability: σ(τ) still falls at the longest τ (no "
                                "flat minimum): B is an upper bound")
            figures[name] = AllanFigure(
                name, "B", float(adev[i] / BIAS_FACTOR),
                float(adev[i] * math.sqrt(lo_f[i]) / BIAS_FACTOR),
                float(adev[i] * math.sqrt(hi_f[i]) / BIAS_FACTOR), units[name],
                float(tau[i]), float(tau[i]))
            continue
        value = math.sqrt(coef[j])  # X = √coef: the term's line c·X²·τ^p read anywhere
        if coef[j] <= 0:
            figures[name] = AllanFigure(name, _SYMBOL[name], 0.0, 0.0, 0.0, units[name],
                                        read, None)
            continue
        share = parts[:, j] / fitted
        i = int(np.argmax(share))
        others = fitted[i] - parts[i, j]
        scale = X[i, j]  # σ² contribution per unit coef at τ_i
        lo = math.sqrt(max(fitted[i] * lo_f[i] - others, 0.0) / scale)
        hi = math.sqrt(max(fitted[i] * hi_f[i] - others, 0.0) / scale)
        figures[name] = AllanFigure(name, _SYMBOL[name], value, lo, hi, units[name], read,
                                    float(tau[i]))
        if share[i] < 0.5:
            warnings.append(f"{name}: never more than {share[i]:.0%} of the Allan variance "
                            "(no clear region; its interval is wide)")
    return AllanTable(label=label, unit=unit, dt=float(dt), n=n, level=level, tau=tau,
                      adev=adev, edf=edf, lo=adev * np.sqrt(lo_f), hi=adev * np.sqrt(hi_f),
                      figures=figures, fitted_adev=np.sqrt(fitted),
                      warnings=tuple(warnings))


def thermal_residual(model: Model, params: Mapping[str, float], samples: Samples) -> np.ndarray:
    """The drift after the thermal model: y − (the model's deterministic part: γ·T through
    the drift's dynamics, bias and the other input/output terms), the stochastic part
    (Gauss–Markov, white noise, random walks) left in. Shape (N,), NaN at gaps."""
    X = model.regressors(params, context(samples, model))
    theta = np.array([params[k] for k in model.names_of_kind("linear")])
    det = X @ theta if theta.size else np.zeros(len(samples))
    return np.asarray(samples.drift, dtype=float) - det


def drift_tables(samples: Samples, fit: FitResult, *, unit: str = "y",
                 level: float = 0.95) -> tuple[AllanTable, AllanTable]:
    """The two tables a gyro test reports: of the raw drift, and of the residual after
    ``fit``'s thermal model (:func:`thermal_residual` at its estimates), both sampled every
    ``samples.dt`` s, labelled ``raw drift`` and ``residual after <model>``."""
    raw = allan_table(samples.drift, samples.dt, unit=unit, label="raw drift", level=level)
    resid = allan_table(thermal_residual(fit.model, fit.values, samples), samples.dt,
                        unit=unit, label=f"residual after {','.join(fit.model.names)}",
                        level=level)
    return raw, resid
