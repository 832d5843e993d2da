"""What a design will realise (#24 item 7): the gain a simulated verify measures, with its
interval, as the headline; an expected-LR ratio only where its denominator can carry one.

* :func:`expected_gain` — the ratio of two expected likelihood ratios, or None when the
  denominator is below :data:`MIN_EXPECTED_LR`: a design that lifts an expected LR of 0.3
  to 60 has not made the run "200x better" (both are near the noise floor of a 1-dof LR
  test; verify realised 42x on the case measured), so the two are quoted side by side.
* :func:`bootstrap_ratio` — a statistic's ratio between two sets of simulated runs and
  its percentile bootstrap interval, each set resampled with replacement (Efron &
  Tibshirani 1993, ch. 13), seeded: the same runs give the same interval.
* :func:`realised_lr_gain` — design ``--separate``'s realised gain: the mean LR of the
  right model over the wrong one summed over both directions, designed program over
  reference, from ``verify``'s per-run LRs.
* :func:`realised_std_gain` — an information design's realised gain: the worst relative
  std among the parameters in doubt, reference over designed, from verify's estimates.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

__all__ = ["MIN_EXPECTED_LR", "expected_gain", "gain_words", "bootstrap_ratio", "ratio",
           "realised_lr_gain", "realised_std_gain"]

#: the smallest expected LR a ratio of expected LRs is quoted over (a 1-dof χ² test's LR
#: has mean 1 under the null)
MIN_EXPECTED_LR = 1.0
#: bootstrap resamples and the interval's level
N_BOOT, LEVEL = 2000, 0.95


def expected_gain(num: float, den: float) -> float | None:
    """``num / den`` when ``den`` can carry a ratio (>= :data:`MIN_EXPECTED_LR`), else None."""
    return float(num / den) if den >= MIN_EXPECTED_LR else None


def gain_words(num: float, den: float, what: str = "expected LR") -> str:
    """``"gain 5.40x (expected LR 51.2 vs 9.49)"``, or without the gain when the
    denominator cannot carry one: ``"expected LR 60.1 vs 0.315"``."""
    both = f"{what} {num:.3g} vs {den:.3g}"
    g = expected_gain(num, den)
    return both if g is None else f"gain {g:.2f}x ({both})"


Groups = Sequence[np.ndarray]


def bootstrap_ratio(stat: Callable[[Groups], float], num: Groups, den: Groups, *,
                    n_boot: int = N_BOOT, level: float = LEVEL, seed: int = 0
                    ) -> tuple[float, float, float]:
    """``stat(num) / stat(den)`` and its percentile interval at ``level``: each group (an
    array whose rows are runs) resampled with replacement, ``n_boot`` times."""
    rng = np.random.default_rng(seed)
    value = ratio(stat(num), stat(den))

    def resample(groups: Groups) -> list[np.ndarray]:
        return [g[rng.integers(0, len(g), len(g))] for g in groups]

    boot = np.array([ratio(stat(resample(num)), stat(resample(den))) for _ in range(n_boot)])
    boot = boot[~np.isnan(boot)]
    if boot.size == 0:
        return value, float("nan"), float("nan")
    q = [(1 - level) / 2, (1 + level) / 2]
    if np.isinf(boot).any():
        # a resample of a few runs can repeat one run: its spread is 0 and the ratio
        # infinite; quantiles then pick order statistics (no inf - inf interpolation)
        lo, hi = np.quantile(boot, q, method="inverted_cdf")
    else:
        lo, hi = np.quantile(boot, q)
    return value, float(lo), float(hi)


def ratio(a: float, b: float) -> float:
    """a / b, +-inf for a nonzero a over 0 and nan for 0 / 0 (a bootstrap resample of a
    few runs can have no spread at all)."""
    if b != 0:
        return float(a) / float(b)
    return float("nan") if a == 0 or np.isnan(a) else float(np.copysign(np.inf, a))


def _interval(value: float, lo: float, hi: float, runs: int) -> dict[str, Any]:
    return {"ratio": value, "interval": [lo, hi], "level": LEVEL, "runs": runs,
            "method": f"percentile bootstrap, {N_BOOT} resamples of the runs"}


def realised_lr_gain(verify: Mapping[str, Any], truths: Sequence[str],
                     num: str = "designed", den: str = "reference") -> dict[str, Any] | None:
    """Design ``--separate``'s realised gain from ``verify`` (label → truth → its tally
    with the per-run ``lrs``): Σ_truth mean LR on ``num`` over that on ``den``; None when a
    direction has too few runs or the reference's sum is not positive."""
    try:
        a = [np.asarray(verify[num][t]["lrs"], dtype=float) for t in truths]
        b = [np.asarray(verify[den][t]["lrs"], dtype=float) for t in truths]
    except KeyError:
        return None
    if min(len(g) for g in a + b) < 2:
        return None

    def total(groups: Groups) -> float:
        return float(sum(np.mean(g) for g in groups))

    if total(b) <= 0:
        return None
    return _interval(*bootstrap_ratio(total, a, b), runs=min(len(g) for g in a + b))


def realised_std_gain(designed: Mapping[str, Sequence[float]],
                      reference: Mapping[str, Sequence[float]], doubt: Sequence[str],
                      params: Mapping[str, float]) -> dict[str, Any] | None:
    """An information design's realised gain: max over ``doubt`` of (realised std /
    |value|) on the reference over that on the designed program, from verify's per-run
    estimates (name → values); None with fewer than 3 runs on either."""
    names = [n for n in doubt if params.get(n)]
    if not names:
        return None
    a = [np.column_stack([designed[n] for n in names])] if all(
        len(designed[n]) >= 3 for n in names) else []
    b = [np.column_stack([reference[n] for n in names])] if all(
        len(reference[n]) >= 3 for n in names) else []
    if not a or not b or len({len(designed[n]) for n in names}) != 1 or len(
            {len(reference[n]) for n in names}) != 1:
        return None
    scale = np.array([abs(params[n]) for n in names])

    def worst(groups: Groups) -> float:
        return float(np.max(np.std(groups[0], axis=0, ddof=1) / scale))

    # reference over designed: how many times smaller the designed run's worst std is
    value, lo, hi = bootstrap_ratio(worst, b, a)
    return _interval(value, lo, hi, runs=min(len(a[0]), len(b[0])))
