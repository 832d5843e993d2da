"""Benchmark: the documented ``design`` examples as whole commands with ``--verify 20``
(issue 25 item 4: each <= 3 min on 2 cores), wall and CPU of each in a fresh process.

* ``worst``: docs/design.md's first example (6 h, the doubt temp_rate.k, hysteresis.h);
* ``run``: a 6-h run (a CSV with a hidden temp_rate) and ``--goal std:temp_rate.k``;
* ``separate``: ``--separate temp_lag markov2`` on the same chamber (issue 15's pair).

Run: ``.venv/bin/python benchmarks/design_speed.py [--only NAME] [--tree PATH]``
(``--tree``: the checkout whose gyrostand is timed, default this one).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
ANCHOR_S = 180.0
PARAMS = ["--param", "markov.beta=0.0015", "--param", "markov.sigma=0.05",
          "--param", "temp.gamma=-0.0002", "--param", "bias.b=0.1",
          "--param", "white.sigma=0.01"]
CHAMBER = ["--hours", "6", "--t-min", "0", "--t-max", "50", "--max-rate", "1",
           "--min-soak", "10", "--legs", "6"]


def examples(work: Path) -> dict[str, list[str]]:
    return {
        "worst": ["design", "--model", "markov,temp,bias,temp_rate,hysteresis,white", *PARAMS,
                  "--param", "temp_rate.k=5", "--param", "hysteresis.h=0.05", *CHAMBER,
                  "--goal", "worst", "--doubt", "temp_rate.k,hysteresis.h"],
        "run": ["design", str(work / "run6h.csv"), "--model", "markov,temp,bias,temp_rate",
                "--goal", "std:temp_rate.k"],
        "separate": ["design", "--separate", "temp_lag", "markov2", "--model",
                     "markov,temp,bias", *PARAMS, "--param", "temp_lag.tau=120", *CHAMBER],
    }


def six_hour_csv(path: Path) -> None:
    from gyrostand.core.model import Model
    from gyrostand.core.profiles import chamber_profile
    from gyrostand.core.simulation import simulate

    truth = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
             "white.sigma": 0.02, "bias.b": 0.3, "temp_rate.k": 5.0}
    s = simulate(Model.parse("markov,temp,bias,temp_rate"), truth, chamber_profile(6.0),
                 seed=1)
    np.savetxt(path, np.column_stack([s.t, s.drift, s.temp]), delimiter=",",
               header="t,drift,temp", comments="", fmt="%.9g")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", default=None)
    ap.add_argument("--tree", type=Path, default=ROOT)
    ap.add_argument("--verify", type=int, default=20)
    a = ap.parse_args()
    print(f"design examples with --verify {a.verify}, tree {a.tree}; load average "
          f"{', '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    with tempfile.TemporaryDirectory(prefix="design_speed-") as tmp:
        work = Path(tmp)
        six_hour_csv(work / "run6h.csv")
        env = dict(os.environ, PYTHONPATH=str(a.tree))
        for name, argv in examples(work).items():
            if a.only and name != a.only:
                continue
            cmd = [sys.executable, "-m", "gyrostand", "-q", *argv, "--verify", str(a.verify),
                   "--out", str(work / name)]
            before = os.times()
            t0 = time.perf_counter()
            # run in the tree: ``-m`` puts the working folder first on sys.path, before
            # PYTHONPATH (from elsewhere, --tree timed the caller's checkout)
            p = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=a.tree)
            wall = time.perf_counter() - t0
            after = os.times()
            cpu = (after.children_user - before.children_user
                   + after.children_system - before.children_system)
            if p.returncode != 0:
                print(f"{name}: exit {p.returncode}\n{p.stderr[-1500:]}", flush=True)
                continue
            print(f"{name:<9} {wall:7.1f} s wall {cpu:7.1f} s CPU  ({wall / ANCHOR_S:.2f}x the "
                  f"{ANCHOR_S:.0f}-s anchor: {'PASS' if wall <= ANCHOR_S else 'MISS'}; "
                  f"CPU/wall {cpu / wall:.2f})", flush=True)
            # the quality beside the time: the designed program's criterion (the worst
            # relative std in doubt, predicted) and what --verify realised
            doc = json.loads((work / name / "design.json").read_text())
            quality = {"criterion": doc.get("worst") or doc.get("gain"),
                       "realised": (doc.get("verify") or {}).get("realised_gain")}
            print(f"{'':<9} {json.dumps(quality)[:300]}", flush=True)


if __name__ == "__main__":
    main()
