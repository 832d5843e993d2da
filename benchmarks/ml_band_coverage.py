"""Exact ML's own ±3 std (Wald) band on the 6-h chamber scenario of ``lkf_accuracy.py``
(table 2: markov,temp,bias,white,temp_rate, β = 1/600 s), on prefixes of each run — the
reference the online LKF's band among ``ok`` statuses is judged beside (issue 24, item 6).

Prints, per prefix, the share of runs whose band covers every coefficient and each one,
the mean and spread of z = (estimate − truth)/std per coefficient (a calibrated band: mean
0, spread 1), and the runs that miss.

Run: ``.venv/bin/python benchmarks/ml_band_coverage.py [RUNS]`` (default 100; seeds 0..RUNS-1,
the seeds of lkf_accuracy.py's table 2)
"""

from __future__ import annotations

import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import lkf_accuracy as LA  # noqa: E402

from gyrostand.core.data import Samples  # noqa: E402
from gyrostand.core.ml.fit import ml  # noqa: E402
from gyrostand.core.simulation import simulate  # noqa: E402

#: prefixes (s) of the 6-h runs: where the LKF turns ok (from ~11,000 s) to the end
PREFIXES = (11000, 14000, 17000, 21600)


def task(seed: int) -> tuple[int, dict[int, dict[str, float]]]:
    s = simulate(LA.CHAMBER_MODEL, LA.CHAMBER_TRUTH, LA.CHAMBER_PROFILE, seed=seed)
    names = ("markov.beta",) + LA.CHAMBER_MODEL.names_of_kind("linear")
    out = {}
    for k in PREFIXES:
        r = ml(Samples.from_arrays(s.t[:k], s.drift[:k], s.temp[:k], dt=s.dt,
                                   source=f"seed {seed}, first {k} s"), LA.CHAMBER_MODEL)
        out[k] = {n: (r.value(n) - LA.CHAMBER_TRUTH[n]) / r.std(n) for n in names}
    return seed, out


def main() -> None:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 100
    with ProcessPoolExecutor(2) as ex:
        res = list(ex.map(task, range(runs)))
    print(f"exact ML's +-3 std band, 6-h chamber scenario, {runs} runs (seeds 0..{runs - 1})")
    for k in PREFIXES:
        names = list(res[0][1][k])
        z = np.array([[o[k][n] for n in names] for _, o in res])
        every = float(np.mean(np.all(np.abs(z) <= 3, axis=1)))
        per = "; ".join(f"{n} {np.mean(np.abs(z[:, i]) <= 3):.3f} (z mean {z[:, i].mean():+.2f}, "
                        f"sd {z[:, i].std():.2f})" for i, n in enumerate(names))
        print(f"  first {k} s: every coefficient covered {every:.3f}; {per}")
        miss = [f"#{seed} " + ", ".join(f"{n} {v:+.1f}" for n, v in o[k].items() if abs(v) > 3)
                for seed, o in res if any(abs(v) > 3 for v in o[k].values())]
        print("    misses: " + ("; ".join(miss) or "none"))


if __name__ == "__main__":
    main()
