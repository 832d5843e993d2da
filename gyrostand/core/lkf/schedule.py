"""When the online LKF re-linearises (:class:`~gyrostand.core.lkf.relin.RelinLKF`): a
geometric schedule whose total cost is linear in the record, whatever the data.

A re-linearisation at ``n`` bins re-filters the whole history (each pass O(n)). Spaced a
fixed ``every`` bins apart, a record of N bins costs Σ n ≈ N²/(2·every) bin-passes; spaced
geometrically, the next one ``max(every, ρ·n)`` bins later, it costs Σ n ≈ N(1 + ρ)/ρ: linear
in N. So:

* ρ = ``GROWTH``: the early ones, while ρ·n < ``every``, still come every ``every`` bins;
  the point then stays within a fraction of a std of the estimate (a sparser schedule let
  a 6-h chamber record's point drift onto a spurious fixed point along the γ/β ridge);
* **not settled** (a point that keeps moving: a misspecified model, a ridge): the passes
  of the next ones are capped at ``UNSETTLED_PASSES`` until one settles within them, so an
  unsettled point costs about what a settled one does. The first unsettled one, with its
  bin and passes, is what the status reports, once.

Re-filter work (Σ passes × bins) is then at most ``(1 + 1/ρ) · max_passes`` per bin, about
``(1 + 1/ρ) · UNSETTLED_PASSES`` when the point never settles (``benchmarks/lkf_cost.py``
measures it).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ["GROWTH", "UNSETTLED_PASSES", "RelinSchedule", "Relinearization"]

#: the next re-linearisation ``max(every, GROWTH·n)`` bins after the one at n
GROWTH = 0.1
#: not settled: the passes of the following re-linearisations, until one settles
UNSETTLED_PASSES = 3


@dataclass
class RelinSchedule:
    """The online re-linearisation schedule (module docstring): ``every`` the shortest
    spacing (bins; 0: never), ``due`` the bin count of the next one, ``unsettled_since``
    the bin count of the first of the current run of unsettled ones (None: the last one
    settled), ``unsettled_passes`` its passes."""

    every: int
    due: int = 0
    unsettled_since: int | None = None
    unsettled_passes: int = 0

    def __post_init__(self) -> None:
        self.due = self.every

    def is_due(self, n: int) -> bool:
        """Whether the periodic re-linearisation is due at ``n`` bins."""
        return self.every > 0 and n >= self.due

    def max_passes(self, default: int) -> int:
        """Passes allowed to the periodic one: ``default``, capped while not settled."""
        return default if self.unsettled_since is None else min(default, UNSETTLED_PASSES)

    def record(self, n: int, passes: int, settled: bool) -> None:
        """A re-linearisation at ``n`` bins ended (``settled`` or not) after ``passes``:
        the next one is due ``max(every, GROWTH·n)`` bins later."""
        if settled:
            self.unsettled_since = None
        elif self.unsettled_since is None:
            self.unsettled_since, self.unsettled_passes = n, passes
        self.due = n + max(self.every, int(round(GROWTH * n)))


@dataclass(frozen=True)
class Relinearization:
    """What the last re-linearisation did: ``passes`` filter passes, ``settled``, the
    largest move of a coefficient from the estimate before it (in its std), ``bins``."""

    bins: int
    passes: int
    settled: bool
    step_sigma: float
    noise: Mapping[str, float]
    noise_at_bound: bool = False  # the drift's noise vanished against σ_v (the search's
    # upper bound of σ_v/σ), or a single searched level at a bound
