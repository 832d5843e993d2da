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
* **β's likelihood closes**: β's profile likelihood (:mod:`~gyrostand.core.lkf.profile`,
  one β-held pass per grid point, computed once per re-linearisation) must drop by 9
  (the ±3σ level) within ±6σ_β of β̂ on both sides; where it does not the likelihood is
  flat or strongly skewed there (the online counterpart of ML's flatness test) and no
  band is calibrated.
* **β̂ at its likelihood's maximum**: the same profile's deviance at β̂ itself, D(β̂),
  must stay within ``OFF_MAXIMUM`` (9) of its highest point: a 6-h chamber run at
  4200 s had β̂ = 0.51 1/s with its own profile highest at 0.40 (D(β̂) = 38.5; ML on the
  same 4200 s: 0.0063 ± 0.0031, the truth 0.0017), and was ``ok`` with β 8.8 std off.

Where β's likelihood is skewed a symmetric band lies, and the delta method's band of
b = c/β most (it curves with β): :func:`calibrated_estimates` widens each reported std
to its profile-likelihood interval, max(σ, half-width / 3), the interval being the union
over β of the β-held estimates' bands (exact given β). Measured on 1-h chamber runs
(100 runs, ``ok`` checkpoints): b's interval 1.3-1.5 times the delta method's band, and
b's spread in its std 1.26 before, 0.89 after; β's and γ's mostly unchanged.
"""

from __future__ import annotations

import math
import weakref
from typing import TYPE_CHECKING

import numpy as np

from .profile import GRID, profile_check

if TYPE_CHECKING:
    from .relin import RelinLKF

__all__ = ["PRIOR_SHARE", "POINT_SIGMA", "REL_BETA_MAX", "OFF_MAXIMUM", "band_warnings",
           "calibrated_estimates"]

#: a coefficient whose std is above this share of its prior std is not identified yet
PRIOR_SHARE = 0.5
#: an estimate this many of its stds from the linearisation point: off its linearisation
POINT_SIGMA = 1.0
#: b = c/β by the delta method: calibrated while σ_β/β is at most this
REL_BETA_MAX = 0.2
#: β̂'s deviance from its own profile's highest point above which the point is off its
#: maximum (k² of the ±3σ band: the maximum lies outside β̂'s band)
OFF_MAXIMUM = 9.0


#: per filter: (its re-linearisation count, each parameter's profile half-width in its
#: std then (≥ 1: wider than the band), whether β's likelihood stays open, D(β̂))
_PROFILES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _profile(f: RelinLKF) -> tuple[np.ndarray, bool, float]:
    """β's profile of ``f`` (:func:`~gyrostand.core.lkf.profile.profile_check`) as the
    ratio of each parameter's half-width to its ±3σ band, whether it is open, and D(β̂);
    computed once per re-linearisation (the stored record's passes) and reused until the
    next."""
    got = _PROFILES.get(f)
    if got is None or got[0] != f.relinearizations:
        est = f.estimates
        v = np.array([est[n][0] for n in f.params])
        sd = np.array([est[n][1] for n in f.params])
        lo, hi, open_, d_hat = profile_check(f)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.maximum(v - lo, hi - v) / (3.0 * sd)
        ratio = np.where(np.isfinite(ratio), ratio, 1.0)
        got = (f.relinearizations, ratio, open_, d_hat)
        _PROFILES[f] = got
    return got[1], got[2], got[3]


def calibrated_estimates(f: RelinLKF) -> dict[str, tuple[float, float]]:
    """``f.estimates`` with each std widened to its profile-likelihood interval (module
    docstring): σ·max(1, r), r its half-width over its ±3σ band at the last
    re-linearisation."""
    est = f.estimates
    if f.n == 0:
        return est
    ratio, _, _ = _profile(f)
    return {n: (v, s * max(1.0, float(r))) for (n, (v, s)), r in
            zip(est.items(), ratio, strict=True)}


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
    if f.n:
        _, open_, off_max = _profile(f)
        if open_:
            out.append(f"markov.beta's likelihood does not drop by 9 within "
                       f"±{max(GRID):g}σ of its estimate: flat or strongly skewed, no band "
                       "is calibrated")
        if off_max > OFF_MAXIMUM:
            out.append(f"markov.beta's estimate is not its likelihood's maximum (deviance "
                       f"{off_max:.1f} from the highest point of its profile): the point "
                       "is off, no band is calibrated")
    off = f.offset_key
    if off is not None:
        b, sb = float(v[0]), float(sd[0])
        rel = sb / b if b > 0 else math.inf
        if rel > REL_BETA_MAX:
            name = f.params[f.names.index(off)]
            out.append(f"{name}'s band (b = c/β) holds once σ_β/β ≤ {REL_BETA_MAX:g} "
                       f"(now {rel:.2f})")
    return out
