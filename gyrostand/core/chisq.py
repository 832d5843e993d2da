"""The χ² distribution's tail and quantile, from scipy.special (not scipy.stats).

scipy.stats costs ~0.6–1 s to import (its whole distribution zoo); the tests of the core
need only two functions of one distribution. They are the ones scipy.stats' ``chi2`` calls
(``chi2.sf(x, k) = chdtrc(k, x)``, ``chi2.ppf(p, k) = 2 P⁻¹(k/2, p)`` with P the regularised
lower incomplete gamma function), so the numbers are identical:

    sf(x; k)  = Q(k/2, x/2) = 1 − P(k/2, x/2)
    ppf(p; k) = 2 P⁻¹(k/2, p)
"""

from __future__ import annotations

from scipy.special import chdtrc, gammaincinv


def chi2_sf(x: float, df: float) -> float:
    """P(χ²_df > x), the p-value of a likelihood-ratio or portmanteau statistic ``x``."""
    return float(chdtrc(df, x))


def chi2_ppf(p: float, df: float) -> float:
    """The ``p`` quantile of χ²_df."""
    return float(2.0 * gammaincinv(0.5 * df, p))
