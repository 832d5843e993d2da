"""A first run's kernels compiled in a second process (issue 25 item 3,
gyrostand.core.prewarm): with an empty numba cache the child compiles ML's score and the
smoother with the argument types the command calls them with, so the command loads them
from the cache instead of compiling them; with a full cache no process starts."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: a command's path through the kernels: an ML fit (the score), then the smoother
SCRIPT = """
import json, numpy as np
from gyrostand.core import jit, prewarm
heard = []
jit.listen()
jit.watch(lambda kernel, started: started and heard.append(kernel))
started = prewarm.start(["score_run", "rts"])
from gyrostand.core.model import Model
from gyrostand.core.profiles import paper_profile
from gyrostand.core.simulation import simulate
from gyrostand.core.ml.fit import ml
from gyrostand.core.rts import kf_smooth
m = Model.parse("markov,temp")
s = simulate(m, {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.01,
                 "white.sigma": 0.0}, paper_profile(), seed=1)
fit = ml(s, m)
ss = m.state_space(fit.values, s.dt)
sm, var = kf_smooth(ss.phi, ss.q, ss.p0, ss.r, s.noise_weights, s.drift)
print(json.dumps({"started": started, "heard": heard,
                  "beta": round(fit.value("markov.beta"), 6), "finite": bool(np.isfinite(sm).all())}))
"""


def _run(cache: Path) -> dict:
    # numba's path: the kernels compiled at install (gyrostand.core.aot) need no child
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT),
               GYROSTAND_KERNELS="jit")
    out = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True,
                         text=True, timeout=300, check=True, cwd=ROOT)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_an_empty_cache_gets_the_score_and_smoother_from_the_second_process(tmp_path):
    first = _run(tmp_path / "numba")
    assert first["started"] == ["score_run", "rts"]
    # the command compiled its own filter kernels, and loaded the child's
    assert "kf_run" in first["heard"]
    assert not {"score_run", "rts_forward", "rts_backward"} & set(first["heard"])
    assert first["finite"]
    again = _run(tmp_path / "numba")
    assert again["started"] == [] and again["heard"] == []  # all cached: no process
    assert again["beta"] == first["beta"]
