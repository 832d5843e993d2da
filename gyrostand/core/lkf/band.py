"""When the online LKF's ±3σ band means what it says, coefficient by coefficient.

The converging filter (:class:`~gyrostand.core.lkf.relin.RelinLKF`) reports each estimated
coefficient with a std from its covariance: a linearisation at the point, exact for the
linear part given β. It is a calibrated band (its ±3σ holding the truth in ≥ 98 % of runs,
``benchmarks/lkf_accuracy.py``) only where that linearisation holds over the band. Each
rule below names the coefficient it is about; :func:`band_warnings` returns one line per
rule that fails, and the online status is ``ok`` only when none does.

* **the point has settled**: a re-linearisation that did not reach its fixed point leaves
  the point, and so every band, off (reported once, with the bin where it began:
  :class:`~gyrostand.core.lkf.schedule.RelinSchedule`);
* **the data, not the prior**: a coefficient whose std is still more than
  ``PRIOR_SHARE`` of its prior's is not identified yet (e.g. ``temp.gamma`` before the
  temperature has moved);
* **the estimate near its point**: between re-linearisations the filter runs at the last
  point; an estimate that has moved more than ``POINT_SIGMA`` of its std from there is
  off the linearisation it is reported from;
* **1/β nearly linear over β's band**: the bias enters as c = βb (its rate into the
  drift) and is reported as b = c/β with the delta method, which holds while β's relative
  std is small: measured on two 1-h scenarios of ``benchmarks/lkf_accuracy.py`` (40 runs
  each, every 100-s checkpoint, whatever the status), b's band held the truth in
  0.99-1.00 of the checkpoints with σ_β/β in 0.15-0.2, 0.94-0.97 at 0.2-0.25 and
  0.83-0.89 at 0.25-0.33 (β and γ: ≥ 0.97 throughout). So b's band counts as calibrated
  once σ_β/β ≤ ``REL_BETA_MAX``. (A gate on σ_β/β̂ prefers runs whose β̂ came out high:
  β's estimate is skewed up in short records, and ML's own band misses with it.)
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .relin import RelinLKF

__all__ = ["PRIOR_SHARE", "POINT_SIGMA", "REL_BETA_MAX", "band_warnings"]

#: a coefficient whose std is above this share of its prior std is not identified yet
PRIOR_SHARE = 0.5
#: an estimate this many of its stds from the linearisation point: off its linearisation
POINT_SIGMA = 1.0
#: b = c/β by the delta method: calibrated while σ_β/β is at most this
REL_BETA_MAX = 0.2


def band_warnings(f: RelinLKF) -> list[str]:
    """Why the filter's band is not calibrated yet, one line per coefficient concerned
    (empty: every band is)."""
    out: list[str] = []
    sched = f.schedule
    if sched.unsettled_since is not None:
        out.append(f"the re-linearisation has not settled since bin {sched.unsettled_since} "
                   f"({sched.unsettled_passes} passes there; later ones capped): every band "
                   "is off its fixed point")
    v, sd = f.values, f.stds
    prior = f.prior_sd
    weak = [f.params[i] for i in range(len(f.names))
            if math.isfinite(prior[i]) and prior[i] > 0 and sd[i] > PRIOR_SHARE * prior[i]]
    if weak:
        out.append(f"{', '.join(weak)} not identified yet: std above {PRIOR_SHARE:.0%} of "
                   "the prior's")
    if f.last is not None:
        move = np.abs(v - f.point) / np.where(sd > 0, sd, np.inf)
        i = int(np.argmax(move))
        if move[i] > POINT_SIGMA:
            out.append(f"{f.params[i]} moved {move[i]:.1f} std from its linearisation "
                       f"point (bin {f.last.bins}): the bands are the next "
                       "re-linearisation's")
    off = f.offset_key
    if off is not None:
        b, sb = float(v[0]), float(sd[0])
        rel = sb / b if b > 0 else math.inf
        if rel > REL_BETA_MAX:
            name = f.params[f.names.index(off)]
            out.append(f"{name}'s band (b = c/β) holds once σ_β/β ≤ {REL_BETA_MAX:g} "
                       f"(now {rel:.2f})")
    return out
