"""The demo's loop as a newcomer runs it (issue 24): whole-process wall time against the
30-s target (warm: numba's kernels cached), and what the loop shows.

Runs ``python -m gyrostand demo`` ``--runs`` times (default 3) side by side in this
process's shell, each into its own temporary folder, and prints per run the wall time and
its ratio to the anchor (30 s), then from the last run's output: the hidden effect ranked
first, the open-loop model error before -> after ``fit --add`` (and the fall in %), the
verdicts, and the adopted model's online LKF estimate of the hidden coefficient against
its truth. The first run may compile kernels (its line says so: numba prints it).

    .venv/bin/python benchmarks/demo_loop.py [--runs N]
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time

ANCHOR_S = 30.0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    out = ""
    for k in range(args.runs):
        with tempfile.TemporaryDirectory() as d:
            t0 = time.perf_counter()
            r = subprocess.run([sys.executable, "-m", "gyrostand", "demo", "--out", d],
                               capture_output=True, text=True, timeout=600)
            wall = time.perf_counter() - t0
        if r.returncode != 0:
            print(r.stdout[-3000:], r.stderr[-3000:])
            return 1
        out = r.stdout
        numba = re.search(r"numba: (.*?);", out)
        print(f"run {k + 1}: demo {wall:.1f} s wall = {wall / ANCHOR_S:.2f} x the 30-s anchor "
              f"({numba.group(1) if numba else '?'})")
    first = re.search(r"^\* (\w+)\s+([\d.]+)\s+(\d+)\s+(\S+)", out, re.M)
    fall = re.search(r"open-loop model error ([\d.]+) -> ([\d.]+) (\S+) \((\d+) % less\)", out)
    verdicts = re.findall(r"^verdict  (.*)$", out, re.M)
    lkf = re.search(r"^temp2\.gamma2\s+(\S+)\s+(\S+) ± (\S+)", out.split("=== 5.")[1], re.M)
    if first:
        print(f"diagnose ranks first: {first.group(1)} (LR {first.group(2)}, df "
              f"{first.group(3)}, p {first.group(4)})")
    if fall:
        print(f"open-loop model error: {fall.group(1)} -> {fall.group(2)} {fall.group(3)} "
              f"({fall.group(4)} % less)")
    print(f"verdicts: {' -> '.join(verdicts)}")
    if lkf:
        truth, value, std = (float(x) for x in lkf.groups())
        print(f"run 2 online LKF: temp2.gamma2 = {value:g} ± {std:.2g} (truth {truth:g}, "
              f"{abs(value - truth) / std:.2f} std off)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
