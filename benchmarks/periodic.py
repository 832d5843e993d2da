"""The periodic disturbance test (gyrostand.core.diagnose.periodic, issue 23): how small a
sinusoid of the drift it finds, how well it places its period and sizes it, what it costs.

Each run: a seeded 4-h chamber cycle built from frames (tests/workbench/framelike.py: 10-Hz
frames with jitter, 1 % drops, a log that starts and ends inside a bin, 0.05-°C quantised
temperature), model markov,temp,bias with the white noise 0.02 deg/h at 1 s and the Markov
process's σ 0.05 deg/h (β 0.01/s), plus a sinusoid of the given amplitude at a period drawn
log-uniformly from 300 to 1800 s with a uniform phase. The current model is fitted by ML,
its saturated reference beside it, and the test run at the reference (what ``diagnose``
does). Per amplitude: the share of runs where it is significant at the verdict's level
(0.001), the relative error of the period found, the amplitude's z-score, the CPU seconds.
Amplitude 0 is the clean run (the test's false-alarm rate alone).

Run: ``.venv/bin/python benchmarks/periodic.py [SEEDS [AMPLITUDE ...]]`` (default 10;
amplitudes 0 0.03 0.05 0.08 0.1 deg/h)
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
from gyrostand.core.diagnose.periodic import periodic  # noqa: E402
from gyrostand.core.diagnose.reference import reference_fit  # noqa: E402
from gyrostand.core.ml.fit import ml  # noqa: E402
from gyrostand.core.model import Model  # noqa: E402
from tests.workbench.framelike import frame_run  # noqa: E402

HOURS = 4.0
AMPLITUDES = (0.0, 0.03, 0.05, 0.08, 0.1)


def main() -> None:
    seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    amps = [float(x) for x in sys.argv[2:]] or list(AMPLITUDES)
    m = Model.parse("markov,temp,bias")
    with tempfile.TemporaryDirectory() as tmp:
        for amp in amps:
            found, err, z, cpu = 0, [], [], []
            for i in range(seeds):
                rng = np.random.default_rng(950 + i)
                period = float(np.exp(rng.uniform(np.log(300.0), np.log(1800.0))))
                phase = float(rng.uniform(0.0, 2 * np.pi))
                path = frame_run(Path(tmp) / f"p{i}.csv", seed=800 + i, drop=0.01,
                                 hours=HOURS, event=lambda t, a=amp, p=period, f=phase:
                                 a * np.sin(2 * np.pi * t / p + f))
                s = Samples.read_csv(path)
                fit = ml(s, m)
                ref = reference_fit(s, m, fit)
                c0 = time.process_time()
                r = periodic(s, ref)
                cpu.append(time.process_time() - c0)
                if r is None or not r.significant:
                    continue
                found += 1
                if amp:
                    err.append(r.period / period - 1.0)
                    z.append((r.amplitude - amp) / r.std)
            line = f"amplitude {amp:5.3f} deg/h: significant (p < 0.001) on {found}/{seeds}"
            if err:
                line += (f"; period off by {100 * min(err):+.2f}..{100 * max(err):+.2f} %; "
                         f"amplitude z-score {min(z):+.1f}..{max(z):+.1f}")
            line += f"; test CPU {np.median(cpu):.3f} s median"
            print(line, flush=True)


if __name__ == "__main__":
    main()
