"""Monte Carlo: five runs of one gyro identified jointly (issue 15, item 3).

Each set is five 2-h chamber cycles of one simulated gyro (tests/multirun/sets.py: shared
β, σ, γ, white noise; per-run turn-on biases drawn with spread 0.1; every run from its own
stationary initial state). Each run is fitted alone by ML and the five jointly
(gyrostand.core.multirun.joint_ml). Printed:

* the std of γ: the joint fit's (empirical over the sets, and the mean reported one) beside
  the anchor, one run's std / √5 (empirical over all single runs, and mean reported); the
  ratio must lie within 20 % of 1;
* the repeatability interval's coverage of the true spread 0.1 (95 % Q-profile interval),
  with its 95 % Clopper–Pearson interval; the target is ≥ 90 %;
* CPU time per set.

Run: ``.venv/bin/python benchmarks/multirun.py [N_SETS [HOURS]]`` (default 100, 2)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from scipy.stats import beta

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gyrostand.core.ml import ml  # noqa: E402
from gyrostand.core.multirun import joint_ml  # noqa: E402
from tests.multirun.sets import PHYSICS, SPREAD, run_set  # noqa: E402

N_RUNS = 5
TARGET_RATIO = 0.2
TARGET_COVERAGE = 0.90


def main(n_sets: int = 100, hours: float = 2.0) -> int:
    single_g, single_sd, joint_g, joint_sd, hits, spreads = [], [], [], [], 0, []
    cpu0 = time.process_time()
    for k in range(n_sets):
        m, runs, _ = run_set(1000 + k, n_runs=N_RUNS, hours=hours)
        for s in runs:
            r = ml(s, m)
            single_g.append(r.value("temp.gamma"))
            single_sd.append(r.std("temp.gamma"))
        j = joint_ml(runs, m)
        joint_g.append(j.value("temp.gamma"))
        joint_sd.append(j.std("temp.gamma"))
        rep = j.repeatability
        assert rep is not None
        spreads.append(rep.spread)
        hits += rep.interval[0] <= SPREAD <= rep.interval[1]
        if (k + 1) % 10 == 0:
            print(f"  {k + 1}/{n_sets} sets, coverage so far {hits}/{k + 1}", flush=True)
    cpu = time.process_time() - cpu0
    g = PHYSICS["temp.gamma"]
    emp_one = float(np.std(single_g, ddof=1)) / np.sqrt(N_RUNS)
    emp_joint = float(np.std(joint_g, ddof=1))
    rep_one = float(np.mean(single_sd)) / np.sqrt(N_RUNS)
    rep_joint = float(np.mean(joint_sd))
    lo = beta.ppf(0.025, hits, n_sets - hits + 1) if hits else 0.0
    hi = beta.ppf(0.975, hits + 1, n_sets - hits) if hits < n_sets else 1.0
    print(f"{n_sets} sets of {N_RUNS} runs of {hours:g} h; true gamma {g:g}, spread {SPREAD:g}")
    print(f"{'std of gamma':<28} {'joint':>11} {'one run/sqrt5':>14} {'ratio':>7}")
    print(f"{'empirical (over the sets)':<28} {emp_joint:11.4g} {emp_one:14.4g} "
          f"{emp_joint / emp_one:7.3f}")
    print(f"{'reported (mean)':<28} {rep_joint:11.4g} {rep_one:14.4g} "
          f"{rep_joint / rep_one:7.3f}")
    print(f"joint gamma: mean {np.mean(joint_g):.5g} (bias {np.mean(joint_g) - g:+.2g}); "
          f"realized/reported std {emp_joint / rep_joint:.3f}")
    print(f"repeatability: mean spread estimate {np.mean(spreads):.4f} (median "
          f"{np.median(spreads):.4f}); 95 % interval covers {SPREAD:g} in {hits}/{n_sets} "
          f"= {hits / n_sets:.0%} (Clopper-Pearson {lo:.0%}..{hi:.0%}); target >= "
          f"{TARGET_COVERAGE:.0%}")
    print(f"CPU {cpu / n_sets:.2f} s per set ({N_RUNS} single fits + 1 joint)")
    ok = abs(emp_joint / emp_one - 1) <= TARGET_RATIO and hits / n_sets >= TARGET_COVERAGE
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    args = sys.argv[1:]
    sys.exit(main(int(args[0]) if args else 100, float(args[1]) if len(args) > 1 else 2.0))
