"""The level shift test (gyrostand.core.diagnose.shift, issue 23): how small a bias jump it
finds, how well it places and sizes it, and what it costs.

Each run: a seeded 4-h chamber cycle built from frames (tests/workbench/framelike.py: 10-Hz
frames with jitter, 1 % drops, a log that starts and ends inside a bin, 0.05-°C quantised
temperature), model markov,temp,bias with the white noise 0.02 deg/h at 1 s and the Markov
process's σ 0.05 deg/h, plus a jump of the drift of the given size at a time drawn uniformly
over the middle 80 % of the run. The current model is fitted by ML, its saturated reference
beside it, and the test run at the reference (what ``diagnose`` does). Per size: the share
of runs where it is significant at the verdict's level (0.001), the error of the instant
found and the step's estimate against its std (a z-score), and the test's CPU seconds. Size
0 is the clean run (the false-alarm rate of the test alone).

Run: ``.venv/bin/python benchmarks/level_shift.py [SEEDS [SIZE ...]]`` (default 10; sizes
0 0.06 0.08 0.1 0.15 0.2 0.3 deg/h)
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
from gyrostand.core.diagnose.reference import reference_fit  # noqa: E402
from gyrostand.core.diagnose.shift import level_shift  # noqa: E402
from gyrostand.core.ml.fit import ml  # noqa: E402
from gyrostand.core.model import Model  # noqa: E402
from tests.workbench.framelike import frame_run  # noqa: E402

HOURS = 4.0
SIZES = (0.0, 0.06, 0.08, 0.1, 0.15, 0.2, 0.3)


def main() -> None:
    seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    sizes = [float(x) for x in sys.argv[2:]] or list(SIZES)
    m = Model.parse("markov,temp,bias")
    with tempfile.TemporaryDirectory() as tmp:
        for size in sizes:
            found, dt_err, z, cpu = 0, [], [], []
            for i in range(seeds):
                rng = np.random.default_rng(900 + i)
                at = float(rng.uniform(0.1, 0.9) * HOURS * 3600.0)
                path = frame_run(Path(tmp) / f"j{i}.csv", seed=700 + i, drop=0.01,
                                 hours=HOURS, event=lambda t, a=at, h=size: h * (t > a))
                s = Samples.read_csv(path)
                fit = ml(s, m)
                ref = reference_fit(s, m, fit)
                c0 = time.process_time()
                r = level_shift(s, ref)
                cpu.append(time.process_time() - c0)
                if r is None or not r.significant:
                    continue
                found += 1
                if size:
                    # the instant in s from the first bin (the log starts 0.93 s into
                    # the simulation, inside its first bin): within a second of the jump
                    dt_err.append(r.t - at)
                    z.append((r.step - size) / r.std)
            line = f"jump {size:5.3f} deg/h: significant (p < 0.001) on {found}/{seeds}"
            if dt_err:
                line += (f"; instant off by {min(dt_err):+.1f}..{max(dt_err):+.1f} s; step "
                         f"z-score {min(z):+.1f}..{max(z):+.1f}")
            line += f"; test CPU {np.median(cpu):.3f} s median"
            print(line, flush=True)


if __name__ == "__main__":
    main()
