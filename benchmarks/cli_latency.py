"""Whole-command latency of the ``gyrostand`` command line (issue 13), against a plain script.

What it measures, each as a whole process (``subprocess.run``, wall clock from spawn to
exit, median of ``--repeats`` runs after one untimed warm-up run that leaves the numba
cache written):

* ``gyrostand --help``                                   (target <= 0.3 s);
* ``gyrostand identify 6h.csv --method ml --json``        (target <= 1.5 s, and <= 0.5 x
  the anchor);
* ``gyrostand diagnose 6h.csv --model markov,temp,bias``  (target <= 5 s);
* the anchor: a minimal independent script doing the same ML fit in-process — it reads
  the CSV with numpy, runs its own numba Kalman filter of the same model

      y_k = γ x_k(β) + b + ε_k + v_k,   x_0 = T_0/β,  x_k = φ x_{k−1} + a0 T_{k−1} + a1 T_k,
      ε_0 ~ N(0, σ²),  ε_k = φ ε_{k−1} + w_k,  var w_k = σ²(1 − φ²),  v_k ~ N(0, σ_v²)

  and maximizes ln L over (log β, log σ, γ, log σ_v, b) with scipy's Nelder–Mead from an
  OLS start at β = 0.05 /s (its numba kernels cached too, so warm runs load them like ours).
  Its maximized ln L is printed beside ours: the same likelihood, so the same fit.
  It is timed twice: with its kernels cached (``@njit(cache=True)``, loaded like ours),
  and as a plain script is usually written (``@njit``, compiled in every run: how the
  issue's independent script was measured at 3.3 s);
* the floor under both: a script that only imports numpy and numba and calls one cached
  ``@njit(cache=True)`` kernel (numba's first cached kernel builds its typing and target
  registries and, through its BLAS check, imports scipy.linalg), and the same plus
  ``import scipy.optimize`` (the optimizer both fits use). What ``identify`` spends above
  the floor is printed, with the 0.5 x anchor target beside it;
* where ``identify``'s time goes, in one process: imports, reading the CSV, the first
  kernel load, the fit and the JSON output (medians over the runs).

The CSV: ``gyrostand.core.simulation`` of ``markov,temp,bias`` on ``chamber_profile(6 h)``
(21,601 one-second samples, seed 1), in a temporary folder.

``--python PY`` times the ``gyrostand`` installed for another interpreter (e.g. a checkout
of an older version) with the same CSV and anchor. The machine's load average is printed:
the timings are wall-clock on a shared machine.

Run: ``python benchmarks/cli_latency.py [--repeats 5] [--python PY]`` (about a minute).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate

TRUTH = {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.001,
         "white.sigma": 0.05, "bias.b": 0.5}
HOURS = 6.0
SEED = 1
TARGET_HELP = 0.3       # s, whole process
TARGET_IDENTIFY = 1.5   # s, whole process
TARGET_VS_ANCHOR = 0.5  # identify / anchor
TARGET_DIAGNOSE = 5.0   # s, whole process

ANCHOR = r'''
"""The same ML fit as ``gyrostand identify --method ml``, written plainly: numba + scipy."""
import json, math, sys

import numpy as np
from numba import njit
from scipy.optimize import minimize


@njit(cache=True)
def temperature_response(temp, beta, dt):
    x = beta * dt
    phi = math.exp(-x)
    total = dt * (-math.expm1(-x) / x)
    if x < 1e-3:
        a0 = dt * (0.5 - x / 3.0 + x * x / 8.0 - x ** 3 / 30.0)
    else:
        a0 = (1.0 - phi * (1.0 + x)) / (beta * x)
    a1 = total - a0
    out = np.empty(temp.size)
    out[0] = temp[0] / beta
    for k in range(1, temp.size):
        out[k] = phi * out[k - 1] + a0 * temp[k - 1] + a1 * temp[k]
    return out


@njit(cache=True)
def loglik(y, d, phi, s2, r):
    q = s2 * (1.0 - phi * phi)
    m, p, ll = 0.0, s2, 0.0
    for k in range(y.size):
        if k > 0:
            m = phi * m
            p = phi * phi * p + q
        f = p + r
        e = y[k] - d[k] - m
        ll -= 0.5 * (math.log(2.0 * math.pi * f) + e * e / f)
        g = p / f
        m += g * e
        p -= g * p
    return ll


data = np.genfromtxt(sys.argv[1], delimiter=",", names=True)
t, y, temp = data["t"], data["drift"], data["temp"]
dt = float(np.median(np.diff(t)))


def negll(u):
    beta, sigma, gamma, sv, b = math.exp(u[0]), math.exp(u[1]), u[2], math.exp(u[3]), u[4]
    d = gamma * temperature_response(temp, beta, dt) + b
    return -loglik(y, d, math.exp(-beta * dt), sigma * sigma, sv * sv)


beta0 = 0.05
X = np.column_stack([temperature_response(temp, beta0, dt), np.ones_like(y)])
(gamma0, b0), *_ = np.linalg.lstsq(X, y, rcond=None)
s0 = float(np.std(y - X @ np.array([gamma0, b0])))
u0 = np.array([math.log(beta0), math.log(s0), gamma0, math.log(0.3 * s0), b0])
res = minimize(negll, u0, method="Nelder-Mead",
               options={"maxiter": 4000, "maxfev": 4000, "xatol": 1e-6, "fatol": 1e-6})
u = res.x
print(json.dumps({"loglik": -float(res.fun), "nfev": int(res.nfev),
                  "markov.beta": math.exp(u[0]), "markov.sigma": math.exp(u[1]),
                  "temp.gamma": float(u[2]), "white.sigma": math.exp(u[3]),
                  "bias.b": float(u[4])}))
'''


FLOOR = r'''
"""The floor of any numba command: interpreter, numpy, numba, one cached kernel."""
import numpy as np
from numba import njit


@njit(cache=True)
def total(x):
    s = 0.0
    for v in x:
        s += v
    return s


print(total(np.ones(3)))
'''

#: ``identify``'s phases in one process (seconds as JSON), in the order the command meets
#: them: its parser, numpy, numba, scipy.linalg (numba's BLAS check) and scipy.optimize
#: (L-BFGS-B), the package's core modules, the CSV, the first cached kernel, the fit and
#: the JSON output
PHASES = r'''
import json, os, sys, time
for v in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS"):
    os.environ.setdefault(v, "1")
marks, t0 = {}, time.perf_counter()


def mark(name):
    global t0
    t = time.perf_counter()
    marks[name] = t - t0
    t0 = t


import gyrostand.cli
args = gyrostand.cli.build_parser("identify").parse_args(["identify", sys.argv[1], "--json"])
mark("gyrostand.cli (identify's parser)")
import numpy as np
mark("numpy")
import numba
mark("numba")
import scipy.linalg
mark("scipy.linalg (numba's BLAS check)")
import scipy.optimize
mark("scipy.optimize")
from gyrostand.core import ml as _ml, model as _model, registry as _registry
from gyrostand.report import render
mark("gyrostand core modules")
from gyrostand.core.data import Samples
s = Samples.read_csv(sys.argv[1])
mark("read the CSV")
from gyrostand.core.kalman import first_order_response
first_order_response(np.ones(3), 0.5, 0.25, 0.25, 0.0)
mark("first cached kernel (numba registries)")
fit = _registry.get("ml").fit(s, _model.Model.parse("markov,temp,bias"),
                               _registry.get("ml").options())
mark("ML fit (second kernel included)")
text = render(fit, "json")
mark("JSON output")
print(json.dumps(marks))
'''


def load() -> str:
    try:
        return "load average " + ", ".join(f"{v:.2f}" for v in os.getloadavg())
    except OSError:
        return "load average n/a"


def whole_process(argv: list[str], repeats: int, cwd: Path) -> tuple[float, list[float], str]:
    """(median s, all s, stdout of the last run) of ``argv`` as a whole process, after one
    untimed warm-up run."""
    subprocess.run(argv, cwd=cwd, check=True, capture_output=True, text=True)
    times, out = [], ""
    for _ in range(repeats):
        t0 = time.perf_counter()
        proc = subprocess.run(argv, cwd=cwd, check=True, capture_output=True,
                              text=True)
        times.append(time.perf_counter() - t0)
        out = proc.stdout
    return statistics.median(times), times, out


def verdict(ok: bool) -> str:
    return "PASS" if ok else "MISS"


def line(label: str, med: float, times: list[float], target: str = "",
         ok: bool | None = None) -> str:
    spread = f"{min(times):.2f}–{max(times):.2f}"
    tail = f"   target {target}  {verdict(ok)}" if ok is not None else ""
    return f"    {label:<44} {med:6.2f} s  (runs {spread} s){tail}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5, help="timed runs of each (default 5)")
    ap.add_argument("--python", default=sys.executable,
                    help="interpreter whose gyrostand is timed (default this one)")
    args = ap.parse_args()
    py = args.python
    where = subprocess.run([py, "-c", "import gyrostand; print(gyrostand.__file__)"],
                           check=True, capture_output=True, text=True).stdout.strip()
    print(f"gyrostand CLI latency benchmark: {platform.machine()}, {os.cpu_count()} CPUs, "
          f"python {platform.python_version()}; gyrostand {where} run by {py}; {load()}")
    with tempfile.TemporaryDirectory(prefix="cli-latency-") as tmp:
        folder = Path(tmp)
        model = Model.parse("markov,temp,bias")
        s = simulate(model, TRUTH, chamber_profile(HOURS), seed=SEED)
        csv = folder / "run6h.csv"
        s.to_csv(csv)
        anchor = folder / "anchor_ml.py"
        anchor.write_text(ANCHOR)
        # the same script as a plain script is usually written: @njit without a cache,
        # compiled in every run (the 3.3-s measurement of an independent script)
        fresh = folder / "anchor_ml_nocache.py"
        fresh.write_text(ANCHOR.replace("@njit(cache=True)", "@njit"))
        floor = folder / "floor.py"
        floor.write_text(FLOOR)
        floor_opt = folder / "floor_optimize.py"
        floor_opt.write_text("import scipy.optimize\n" + FLOOR)
        phases = folder / "phases.py"
        phases.write_text(PHASES)
        print(f"data: simulate(markov,temp,white,bias, chamber_profile({HOURS:g} h), dt=1 s, "
              f"seed={SEED}): {len(s)} samples -> {csv.name}")
        print(f"whole processes, wall clock from spawn to exit: median of {args.repeats} "
              f"after one untimed warm-up run (numba caches written)\n")
        gyro = [py, "-m", "gyrostand"]
        h_med, h_t, _ = whole_process(gyro + ["--help"], args.repeats, folder)
        i_med, i_t, i_out = whole_process(
            gyro + ["identify", str(csv), "--method", "ml", "--json"], args.repeats, folder)
        d_med, d_t, _ = whole_process(
            gyro + ["diagnose", str(csv), "--model", "markov,temp,bias"], args.repeats, folder)
        a_med, a_t, a_out = whole_process([py, str(anchor), str(csv)], args.repeats, folder)
        f_med, f_t, _ = whole_process([py, str(fresh), str(csv)], args.repeats, folder)
        n_med, n_t, _ = whole_process([py, str(floor)], args.repeats, folder)
        o_med, o_t, _ = whole_process([py, str(floor_opt)], args.repeats, folder)
        runs = [json.loads(whole_process([py, str(phases), str(csv)], 1, folder)[2])
                for _ in range(args.repeats)]
        ours, theirs = json.loads(i_out), json.loads(a_out)
        ratio = i_med / a_med
        print(line("gyrostand --help", h_med, h_t, f"<= {TARGET_HELP:g} s",
                   h_med <= TARGET_HELP))
        print(line("gyrostand identify 6h.csv --method ml --json", i_med, i_t,
                   f"<= {TARGET_IDENTIFY:g} s", i_med <= TARGET_IDENTIFY))
        print(line("gyrostand diagnose 6h.csv", d_med, d_t, f"<= {TARGET_DIAGNOSE:g} s",
                   d_med <= TARGET_DIAGNOSE))
        print(line("anchor: plain numba KF + Nelder-Mead script", a_med, a_t))
        print(line("anchor, its kernels compiled per run (no cache)", f_med, f_t))
        print(line("floor: numpy + numba + one cached kernel", n_med, n_t))
        print(line("floor + import scipy.optimize", o_med, o_t))
        print(f"\n    identify / anchor = {ratio:.2f}   (target <= {TARGET_VS_ANCHOR:g})  "
              f"{verdict(ratio <= TARGET_VS_ANCHOR)}")
        print(f"    identify / anchor compiled per run = {i_med / f_med:.2f}   (target <= "
              f"{TARGET_VS_ANCHOR:g})  {verdict(i_med / f_med <= TARGET_VS_ANCHOR)}")
        print(f"    max ln L: gyrostand {ours['loglik']:.4f}   anchor {theirs['loglik']:.4f} "
              f"({theirs['nfev']} Nelder-Mead evaluations)   ours − anchor = "
              f"{ours['loglik'] - theirs['loglik']:+.3g}")
        print("    estimates (gyrostand / anchor): " + ", ".join(
            f"{k} {ours['parameters'][k]['value']:.4g} / {theirs[k]:.4g}" for k in TRUTH))
        half = TARGET_VS_ANCHOR * a_med
        print(f"    {TARGET_VS_ANCHOR:g} x anchor = {half:.2f} s against the floor "
              f"{n_med:.2f} s (numpy + numba + one cached kernel; {o_med:.2f} s with "
              f"scipy.optimize): {'below' if half < n_med else 'above'} the floor; "
              f"identify spends {i_med - n_med:.2f} s above it, the anchor "
              f"{a_med - n_med:.2f} s")
        print(f"\n    where identify's time goes, in one process (median of {len(runs)}):")
        total = 0.0
        for k in runs[0]:
            v = statistics.median(r[k] for r in runs)
            total += v
            print(f"      {v:6.3f} s  {k}")
        print(f"      {total:6.3f} s  in all, after the interpreter's start")
    print(f"\n{load()} at the end")
    return 0


if __name__ == "__main__":
    sys.exit(main())
