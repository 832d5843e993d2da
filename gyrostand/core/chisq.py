"""The χ² distribution's tail and quantile, from scipy.special (not scipy.stats), and
the Ljung–Box whiteness test it calibrates (:func:`ljung_box`).

scipy.stats costs ~0.6–1 s to import (its whole distribution zoo); the tests of the core
need only two functions of one distribution (and the tail of a χ² process's supremum,
:func:`sup_chi2_sf`, built on them). They are the ones scipy.stats' ``chi2`` calls
(``chi2.sf(x, k) = chdtrc(k, x)``, ``chi2.ppf(p, k) = 2 P⁻¹(k/2, p)`` with P the regularised
lower incomplete gamma function), so the numbers are identical:

    sf(x; k)  = Q(k/2, x/2) = 1 − P(k/2, x/2)
    ppf(p; k) = 2 P⁻¹(k/2, p)
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.special import chdtrc, gammaincinv


def chi2_sf(x: float, df: float) -> float:
    """P(χ²_df > x), the p-value of a likelihood-ratio or portmanteau statistic ``x``."""
    return float(chdtrc(df, x))


def chi2_ppf(p: float, df: float) -> float:
    """The ``p`` quantile of χ²_df."""
    return float(2.0 * gammaincinv(0.5 * df, p))


def sup_chi2_sf(x: float, df: int, lkc: Sequence[float]) -> float:
    """P(sup_θ χ²_df(θ) > x) for a χ² process over a shape θ of one or two dimensions.

    The expected Euler characteristic of the excursion set (Worsley 1994; Adler & Taylor
    2007), which at the high levels of a test is its tail probability:

        P ≈ ρ₀(x) + L₁ ρ₁(x) + L₂ ρ₂(x)
        ρ₀ = P(χ²_df > x)
        ρ₁ = x^((df−1)/2) e^(−x/2) / (√(2π) 2^((df−2)/2) Γ(df/2))
        ρ₂ = x^((df−2)/2) e^(−x/2) (x − (df − 1)) / (2π 2^((df−2)/2) Γ(df/2))

    ``lkc`` = (L₁,) or (L₁, L₂): the Lipschitz–Killing curvatures of the shape's range in
    the metric of the process (a curve's length; half a surface's perimeter and its area).
    With one dimension this is Davies's (1987) upper bound
    P(χ²_df > x) + V x^((df−1)/2) e^(−x/2) 2^(−df/2) / Γ(df/2) with the total variation
    V of √LR at its expectation √(2/π)·L₁. Capped at 1.
    """
    if not x > 0:
        return 1.0
    p = chi2_sf(x, df)
    # log of x^((df−2)/2) e^(−x/2) / (2^((df−2)/2) Γ(df/2)), shared by ρ₁ and ρ₂
    a = 0.5 * (df - 2) * (math.log(x) - math.log(2.0)) - 0.5 * x - math.lgamma(0.5 * df)
    if len(lkc) >= 1:
        p += lkc[0] * math.exp(a + 0.5 * math.log(x)) / math.sqrt(2 * math.pi)
    if len(lkc) >= 2:
        p += lkc[1] * math.exp(a) * (x - (df - 1)) / (2 * math.pi)
    if len(lkc) > 2:
        raise ValueError(f"sup_chi2_sf: a shape of {len(lkc)} dimensions (at most 2)")
    return float(min(max(p, 0.0), 1.0))


def ljung_box(z: np.ndarray, lags: int) -> tuple[float, float]:
    """Ljung–Box Q statistic of ``z`` (NaN skipped) for ``lags`` lags, and its p-value.

    Q = n(n+2) Σ_{k=1..h} ρ_k² / (n − k),  Q ~ χ²(h) for white noise.
    """
    z = z[np.isfinite(z)]
    n = z.size
    z = z - z.mean()
    d = float(z @ z)
    if n <= lags + 1 or d == 0:
        return 0.0, 1.0
    rho = np.array([float(z[k:] @ z[:-k]) / d for k in range(1, lags + 1)])
    q = float(n * (n + 2) * np.sum(rho**2 / (n - np.arange(1, lags + 1))))
    return q, chi2_sf(q, lags)
