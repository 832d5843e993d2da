"""Benchmark: whether an effect repeats across runs (gyrostand.core.diagnose.repeats).

Pairs of 4-h runs of one gyro (benchmarks/advice_sequence.py's data: seeds 500+i and
600+i, drops, partial end bins, quantised sensor). Each run is fitted alone and the
coefficients compared by Cochran's Q, as ``diagnose RUN1 RUN2`` does:

* **calibration**: runs fitted with their true model (clean, a temp_rate, a random walk,
  a warm-up + T², a trend, temp_rate + trend): each shared term's Q-test p. Under one
  effect of the gyro P(p < a) = a; the verdict's level is 0.001;
* **power**: a trend fitted where the truth is a random walk (alone, and beside a lagged
  temperature with temp_lag in the model): how often the trend does not repeat (p < 0.001).

Prints each kind's smallest p and counts below 0.05 and 0.001.

Run: ``.venv/bin/python benchmarks/repeats.py [PAIRS]`` (default 20)
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.advice_sequence import data  # noqa: E402
from gyrostand.core.diagnose.repeats import (  # noqa: E402
    REPEAT_ALPHA,
    linear_coefficients,
    per_run_fits,
    q_of,
    shared_effect,
)
from gyrostand.core.model import Model  # noqa: E402

#: (kind, the model fitted to each run, whether the kind's shared terms are the truth)
CASES = [
    ("clean", "markov,temp,bias", True),
    ("temp_rate", "markov,temp,bias,temp_rate", True),
    ("random_walk", "markov,temp,bias,random_walk", True),
    ("warmup+temp2", "markov,temp,bias,warmup,temp2", True),
    ("trend", "markov,temp,bias,trend", True),
    ("temp_rate+trend", "markov,temp,bias,temp_rate,trend", True),
    ("random_walk", "markov,temp,bias,trend", False),
    ("temp_lag+random_walk", "markov,temp,bias,temp_lag,trend", False),
]


def main() -> None:
    pairs = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    with tempfile.TemporaryDirectory() as tmp:
        for kind, model, truth in CASES:
            m = Model.parse(model)
            terms = [t for t in m.names if shared_effect(t) and linear_coefficients(m, t)]
            if not truth:
                terms = ["trend"]
            ps: dict[str, list[float]] = {t: [] for t in terms}
            t0 = time.perf_counter()
            for i in range(pairs):
                runs = [data(kind, 500 + i, Path(tmp)), data(kind, 600 + i, Path(tmp))]
                fits = per_run_fits(runs, m, None)
                if fits is None:
                    continue
                for t in terms:
                    rep = q_of(t, linear_coefficients(m, t), fits)
                    if rep is not None:
                        ps[t].append(rep.p_value)
            what = "true model" if truth else "trend in place of the walk"
            for t, v in ps.items():
                print(f"{kind:<22} {model:<34} {what:<26} {t:<10} pairs {len(v):2d}  min p "
                      f"{min(v):.2g}  p < 0.05: {sum(p < 0.05 for p in v):2d}  "
                      f"p < {REPEAT_ALPHA:g}: {sum(p < REPEAT_ALPHA for p in v):2d}", flush=True)
            print(f"    ({(time.perf_counter() - t0) / pairs:.1f} s a pair)", flush=True)


if __name__ == "__main__":
    main()
