"""The saturated reference (issue 23): its lack-of-fit test on clean runs and on runs with
a hidden effect, in and outside the vocabulary, and its cost.

Each run is a seeded chamber cycle (tests/workbench/test_hidden_effects.chamber_run: soaks,
ramps of 0.5–2 °C/min, the sensor quantised to 0.05 °C with 0.01 °C of noise); the model
is ``markov,temp,bias``. For clean runs the test's null distribution: the mean LR against
its χ²(df) mean times ``FREE_LR_SCALE``, and how often p < 1 % and < 0.1 % (the verdict's
level). For hidden effects: the share of runs whose lack of fit is significant at the
verdict's level and at 1 %, with the group the reference names; a cubic in T and an offset
step above 40 °C stand for effects outside the vocabulary.

Run: ``.venv/bin/python benchmarks/reference_fit.py [N_CLEAN [N_HIDDEN]]`` (default 30, 5)
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gyrostand.core.data import Samples  # noqa: E402
from gyrostand.core.diagnose.reference import (  # noqa: E402
    FREE_LR_SCALE,
    LACK_OF_FIT_ALPHA,
    REPORT_ALPHA,
    reference_fit,
)
from gyrostand.core.ml.fit import ml  # noqa: E402
from gyrostand.core.model import Model  # noqa: E402
from gyrostand.core.profiles import chamber_profile  # noqa: E402
from gyrostand.core.simulation import simulate  # noqa: E402
from tests.workbench.test_hidden_effects import BASE  # noqa: E402

HIDDEN = {
    "temp_rate": (["temp_rate"], {"temp_rate.k": 5.0}),
    "temp2": (["temp2"], {"temp2.gamma2": 5e-6}),
    "warmup": (["warmup"], {"warmup.A": 0.5, "warmup.tau": 900.0}),
    "trend": (["trend"], {"trend.c": 1e-5}),
    "hysteresis": (["hysteresis"], {"hysteresis.h": 0.05}),
    "temp_lag": (["temp_lag"], {"temp_lag.tau": 600.0}),
    "cubic in T (outside)": ([], {}),
    "step above 40 °C (outside)": ([], {}),
}


def run(kind: str, seed: int, hours: float, tmp: Path) -> Samples:
    terms, extra = HIDDEN.get(kind, ([], {}))
    m = Model.parse(["markov", "temp", "bias", *terms])
    s = simulate(m, {**BASE, **extra}, chamber_profile(hours), seed=seed)
    drift = s.drift.copy()
    if kind.startswith("cubic"):
        drift += 2e-5 * (s.temp - 32.0) ** 3
    elif kind.startswith("step"):
        drift += 0.15 * (s.temp > 40.0)
    rng = np.random.default_rng(seed + 1000)
    temp = np.round((s.temp + 0.01 * rng.standard_normal(len(s))) / 0.05) * 0.05
    path = tmp / f"{seed}.csv"
    Samples.from_arrays(s.t, drift, temp).to_csv(path)
    return Samples.read_csv(path)


def main() -> None:
    n_clean = int(sys.argv[1]) if len(sys.argv) > 1 else 30
    n_hidden = int(sys.argv[2]) if len(sys.argv) > 2 else 5
    model = Model.parse("markov,temp,bias")
    with tempfile.TemporaryDirectory() as tmp:
        for hours in (2.0, 6.0):
            lr, p, df, sec = [], [], 0, []
            for i in range(n_clean):
                s = run("clean", 9000 + i, hours, Path(tmp))
                f = ml(s, model)
                r = reference_fit(s, model, f)
                lr.append(r.lr)
                p.append(r.p_value)
                df = r.df
                sec.append(r.seconds)
            lr_a, p_a = np.array(lr), np.array(p)
            print(f"clean {hours:g}-h runs ({n_clean}): mean LR {lr_a.mean():.1f} on {df} df "
                  f"(null mean {FREE_LR_SCALE * df:.1f}), p < {REPORT_ALPHA:g} in "
                  f"{int(np.sum(p_a < REPORT_ALPHA))}, p < {LACK_OF_FIT_ALPHA:g} in "
                  f"{int(np.sum(p_a < LACK_OF_FIT_ALPHA))}; reference {np.mean(sec):.2f} s")
        for kind in HIDDEN if n_hidden else ():
            hit = hit1 = 0
            groups: dict[str, int] = {}
            t0 = time.perf_counter()
            for i in range(n_hidden):
                s = run(kind, 100 + i, 4.0, Path(tmp))
                f = ml(s, model)
                r = reference_fit(s, model, f)
                hit += int(r.p_value < LACK_OF_FIT_ALPHA)
                hit1 += int(r.p_value < REPORT_ALPHA)
                for q in r.missing()[:1]:
                    groups[q.group] = groups.get(q.group, 0) + 1
            print(f"hidden {kind:<28} lack of fit p < {LACK_OF_FIT_ALPHA:g}: {hit}/{n_hidden}"
                  f", p < {REPORT_ALPHA:g}: {hit1}/{n_hidden}; group named first: {groups} "
                  f"({(time.perf_counter() - t0) / n_hidden:.1f} s a run)")


if __name__ == "__main__":
    main()
