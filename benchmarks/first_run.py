"""Benchmark: the first run after install (issue 25 item 3) — a command with an empty numba
cache against the same command with a warm one, side by side.

Each pair runs the command twice in fresh processes, in turn: once with ``NUMBA_CACHE_DIR``
pointed at a new empty folder (every kernel it calls compiles), once at a folder an
earlier run filled (every kernel loads). The ratio is taken pair by pair, so a shared,
noisy machine moves both alike; the median ratio is the figure.

Anchors: ``diagnose`` of a 6-h run (21,600 samples, a hidden temp_rate) empty <= 1.5x
warm; ``demo`` (the loop on the virtual bus) empty <= 2x warm.

Since session 28 an install compiles the kernels ahead of time (``gyrostand.core.aot``):
both runs of a pair then load them from the extension module, and ``--jit`` adds the pairs
of numba's path (``GYROSTAND_KERNELS=jit``), what an install without a C compiler runs.

Run: ``.venv/bin/python benchmarks/first_run.py [--pairs 3] [--tree PATH] [--jit]``
(``--tree``: the checkout whose gyrostand is timed, default this one).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


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


def timed(argv: list[str], tree: Path, cache: Path, cwd: Path,
          kernels: str = "") -> tuple[float, float]:
    """Wall and CPU (user + sys of the child) seconds of one run (``kernels``: the value
    of ``GYROSTAND_KERNELS``, ``jit`` for numba's path without the kernels compiled at
    install)."""
    env = dict(os.environ, PYTHONPATH=str(tree), NUMBA_CACHE_DIR=str(cache),
               GYROSTAND_KERNELS=kernels)
    before = os.times()
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "gyrostand", "-q", *argv], env=env, cwd=cwd,
                       capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = os.times()
    # a run's fault is timed too: 1 before the sysexits statuses (older --tree), 69/74 now
    if p.returncode not in (0, 1, 69, 74):
        raise SystemExit(f"{argv} failed ({p.returncode}):\n{p.stderr[-2000:]}")
    cpu = (after.children_user - before.children_user
           + after.children_system - before.children_system)
    return wall, cpu


def pairs(name: str, argv: list[str], tree: Path, work: Path, n: int, anchor: float,
          kernels: str = "") -> None:
    key = name.split()[0] + kernels
    warm = work / f"warm-{key}"
    timed(argv, tree, warm, work, kernels)  # fills the warm cache
    rows = []
    for k in range(n):
        empty = Path(tempfile.mkdtemp(prefix=f"empty-{key}-", dir=work))
        cold_w, cold_c = timed(argv, tree, empty, work, kernels)
        warm_w, warm_c = timed(argv, tree, warm, work, kernels)
        rows.append((cold_w, warm_w, cold_c, warm_c))
        print(f"  pair {k + 1}: empty cache {cold_w:6.1f} s wall ({cold_c:5.1f} s CPU), "
              f"warm {warm_w:6.1f} s wall ({warm_c:5.1f} s CPU): {cold_w / warm_w:.2f}x",
              flush=True)
    ratio = statistics.median(r[0] / r[1] for r in rows)
    cpu_ratio = statistics.median(r[2] / r[3] for r in rows)
    print(f"{name}: median empty/warm {ratio:.2f}x wall ({cpu_ratio:.2f}x CPU); medians "
          f"{statistics.median(r[0] for r in rows):.1f} s vs "
          f"{statistics.median(r[1] for r in rows):.1f} s; anchor <= {anchor:g}x: "
          f"{'PASS' if ratio <= anchor else 'MISS'}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--tree", type=Path, default=ROOT)
    ap.add_argument("--only", choices=("diagnose", "demo"), default=None)
    ap.add_argument("--jit", action="store_true",
                    help="also numba's path (GYROSTAND_KERNELS=jit): an install without "
                         "the kernels compiled ahead of time (no C compiler)")
    a = ap.parse_args()
    sys.path.insert(0, str(a.tree))
    try:
        from gyrostand.core import aot

        built = "yes" if aot.built() is not None else "no"
    except ImportError:  # a tree from before them
        built = "no (this tree has none)"
    print(f"kernels compiled at install (gyrostand.core._kernels): {built}")
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"first run vs warm, {a.pairs} pairs each, tree {a.tree}; load average {load}")
    with tempfile.TemporaryDirectory(prefix="first_run-") as tmp:
        work = Path(tmp)
        if a.only in (None, "diagnose"):
            csv = work / "run6h.csv"
            six_hour_csv(csv)
            pairs("diagnose (6-h run)", ["diagnose", str(csv), "--unit", "deg/h"], a.tree,
                  work, a.pairs, 1.5)
            if a.jit:
                pairs("diagnose (6-h run), numba's path", ["diagnose", str(csv), "--unit",
                                                          "deg/h"], a.tree, work, a.pairs,
                      1.5, "jit")
        if a.only in (None, "demo"):
            pairs("demo", ["demo", "--out", str(work / "demo")], a.tree, work, a.pairs, 2.0)
            if a.jit:
                pairs("demo, numba's path", ["demo", "--out", str(work / "demo-jit")], a.tree,
                      work, a.pairs, 2.0, "jit")


if __name__ == "__main__":
    main()
