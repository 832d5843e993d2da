"""Trend or random walk, decided by whether the effect repeats (issue 23 item 4: "where
several runs of the gyro are given, by whether the effect repeats across runs").

On one 4-h record a trend of 1e-5 deg/h/s and a rate random walk tie: neither is
significant given the other on any of 20 seeds of the trend kind
(benchmarks/results/advice_oracle.txt), so one record's advice is a coin toss weighted by
held-out blocks. Two runs of the same gyro break the tie the way an engineer would: a
trend (ageing, settling) keeps its rate from run to run — ``trend.c`` is the gyro's, one
parameter for both runs — while a random walk wanders anew in each.

Each case: two runs of the kind (:mod:`benchmarks.advice_sequence`'s data, seeds 500+i and
600+i: drops, partial end bins, quantised sensor), the joint diagnosis followed as a user
follows ``gyrostand diagnose RUN1 RUN2`` and ``gyrostand fit RUN1 RUN2 --add TERM``
(:func:`~gyrostand.core.diagnose.joint.joint_diagnose`): add the first significant
candidate while the verdict is NOT ADEQUATE. Right: exactly the true terms, ADEQUATE.

Run: ``.venv/bin/python benchmarks/advice_two_runs.py [SEEDS [KIND ...]]`` (default 20;
kinds trend, random_walk, temp_rate+trend, temp_lag+random_walk)
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.advice_sequence import KINDS, MAX_STEPS, data  # noqa: E402
from gyrostand.core.diagnose.joint import joint_diagnose  # noqa: E402
from gyrostand.core.model import Model  # noqa: E402

DEFAULT_KINDS = ["trend", "random_walk", "temp_rate+trend", "temp_lag+random_walk"]


def joint_sequence(runs) -> tuple[list[str], bool, list[str]]:
    """The joint advice followed from markov,temp,bias: (terms added, verdict, the
    candidates proposed first at each step with their LR)."""
    model = Model.parse("markov,temp,bias")
    added: list[str] = []
    steps: list[str] = []
    for _ in range(MAX_STEPS):
        rep = joint_diagnose(runs, model)
        sig = rep.significant
        if rep.adequate or not sig:
            return added, rep.adequate, steps
        first = sig[0]
        steps.append(f"{first.term} LR {first.lr_stat:.1f}" + "".join(
            f", {c.term} {c.lr_stat:.1f}" for c in sig[1:3]))
        added.append(first.term)
        model = model.add(first.term)
    return added, False, steps


def main() -> None:
    seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    kinds = sys.argv[2:] or DEFAULT_KINDS
    with tempfile.TemporaryDirectory() as tmp:
        for kind in kinds:
            truth = sorted(KINDS[kind][0])
            right = 0
            t0 = time.perf_counter()
            for i in range(seeds):
                runs = [data(kind, 500 + i, Path(tmp)), data(kind, 600 + i, Path(tmp))]
                added, adequate, steps = joint_sequence(runs)
                ok = adequate and sorted(added) == truth
                right += ok
                print(f"{kind:<22} seeds {500 + i}+{600 + i}: +{','.join(added) or '-'} "
                      f"{'ADEQUATE' if adequate else 'NOT ADEQUATE'}: "
                      f"{'right' if ok else 'wrong'} ({'; '.join(steps)})", flush=True)
            print(f"{kind}: two runs, right {right}/{seeds} "
                  f"({(time.perf_counter() - t0) / seeds:.0f} s a pair)\n", flush=True)


if __name__ == "__main__":
    main()
