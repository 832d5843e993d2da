"""Speed of gyrostand's exact ML fit against statsmodels' state-space MLE (issue 2).

What it measures, on one simulated 6-hour run (21,601 one-second samples, the chamber
profile, model ``markov,temp,bias`` + white noise, truth ``TRUTH`` below, seed 1):

* ``gyrostand.core.ml.fit.ml`` — our exact Gaussian ML (numba Kalman filter, γ and b
  concentrated out by GLS, the noise scale concentrated out, multi-start L-BFGS-B seeded by
  least squares, standard errors from the observed information);
* a custom ``statsmodels.tsa.statespace.mlemodel.MLEModel`` of the SAME model:

      y_k = γ x_k(β) + b + ε_k + v_k,   v_k ~ N(0, σ_v²)
      x_0 = T_0/β,  x_k = φ x_{k−1} + a0 T_{k−1} + a1 T_k    (exact, T linear between samples)
      ε_0 ~ N(0, σ²),  ε_k = φ ε_{k−1} + w_k,  var w_k = σ²(1 − φ²),  φ = exp(−βΔt)

  with state [ε] (stationary initialization), the deterministic part γ x_k(β) + b as a
  time-varying observation intercept, and all five parameters (β, σ, γ, σ_v, b) searched by
  ``fit(method='lbfgs')`` with statsmodels' defaults otherwise (finite-difference gradient).
  Transforms: log for β, σ, σ_v; γ is divided by |γ_LSQ| (without that rescaling
  statsmodels' L-BFGS stops at its start point: the curvature of ln L in γ is 1e4–1e6
  times that in the other unconstrained parameters; the script shows this once, untimed).

Start information: statsmodels starts from the least-squares estimates of all five
parameters (our ``lsq``; ``white.sigma`` floored at 1e-3·σ) — more than our ``ml`` takes
(it uses the LSQ β only and builds its own grid of noise ratios) — and the LSQ time is not
charged to statsmodels.

Checks and anchors (issue 2, "What it must show"):

* at identical parameters the two log-likelihoods agree to 1e-9 relative (both exact);
* our fit time < 0.5 s on this machine;
* statsmodels time / our time >= 5;
* the two maximized log-likelihoods agree to 1e-3 relative.

Timing: ``time.perf_counter``, best (and median) of 3 after one untimed warm-up fit of
each library (so numba compilation / cache loading and statsmodels' first-call set-up are
excluded). Comparisons: (A) full fits with standard errors from the observed information on
both sides (ours: numerical Hessian of ln L; statsmodels ``cov_type='approx'``) — the
headline; (B) estimates only (``std_errors=False`` / ``cov_type='none'``); (C) as B with
the fastest statsmodels set-up found (BFGS with its complex-step score). The machine's
load average is printed: the timings are wall-clock on a shared machine.

Wall time (``perf_counter``) is the measure; the process CPU time (``process_time``) is
printed beside it (wall > CPU: the machine is busy; spinning OpenBLAS threads inflate CPU
too). ``--blas-threads N`` re-runs the script with ``OPENBLAS_NUM_THREADS=N`` (and
``OMP_NUM_THREADS``): both libraries call OpenBLAS on tiny matrices (our ``lstsq``, scipy's
L-BFGS-B; statsmodels' filter via scipy's BLAS), where its thread pool costs more than it
gives, most of all on a loaded machine.

Run: ``python benchmarks/ml_speed.py [--blas-threads 1]`` (one to two minutes). Exit
status 1 if the likelihood parity check fails (the comparison would be meaningless); missed
targets are reported only.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
import warnings

import numpy as np
import statsmodels
from scipy.signal import lfilter
from statsmodels.tsa.statespace.mlemodel import MLEModel

from gyrostand.core.lsq.fit import lsq
from gyrostand.core.ml.fit import ml
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate

TRUTH = {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.001,
         "white.sigma": 0.05, "bias.b": 0.5}
HOURS = 6.0
SEED = 1
REPEATS = 3
TARGET_TIME = 0.5     # s, our fit
TARGET_RATIO = 5.0    # statsmodels time / our time
TARGET_LL_REL = 1e-3  # maximized log-likelihoods, relative
PARITY_REL = 1e-9     # log-likelihoods at identical parameters, relative

#: statsmodels parameter order = our model's param_names order
NAMES = ("markov.beta", "markov.sigma", "temp.gamma", "white.sigma", "bias.b")
POSITIVE = np.array([True, True, False, True, False])
GAMMA = NAMES.index("temp.gamma")


def foh_weights(beta, dt: float):
    """(φ, a0, a1) of x_k = φ x_{k−1} + a0 T_{k−1} + a1 T_k, as ``kalman.foh_weights``.

    Numpy ufuncs only, so that a complex β works too (statsmodels' complex-step
    derivatives); same formulas and the same small-βΔt branch as ``gyrostand.core.kalman``.
    """
    x = beta * dt
    phi = np.exp(-x)
    total = dt * (-np.expm1(-x) / x)
    if abs(np.real(x)) < 1e-3:
        a0 = dt * (0.5 - x / 3.0 + x * x / 8.0 - x**3 / 30.0)
    else:
        a0 = (1.0 - phi * (1.0 + x)) / (beta * x)
    return phi, a0, total - a0


class DriftMLE(MLEModel):
    """Model (1) with temperature input, bias and white measurement noise, for statsmodels.

    State ε_k (1-D, stationary start); observation y_k = ε_k + d_k + v_k with the
    time-varying intercept d_k = γ x_k(β) + b recomputed from the parameters in
    :meth:`update`. Unconstrained parameters: log β, log σ, γ/``gamma_scale``, log σ_v, b.
    """

    def __init__(self, endog: np.ndarray, temp: np.ndarray, dt: float,
                 gamma_scale: float = 1.0):
        super().__init__(endog, k_states=1, k_posdef=1)
        self.temp = np.asarray(temp, dtype=float)
        self.dt = float(dt)
        self.gamma_scale = float(gamma_scale)
        self["design", 0, 0] = 1.0
        self["selection", 0, 0] = 1.0
        self["obs_intercept"] = np.zeros((1, self.nobs))
        self.initialize_stationary()

    @property
    def param_names(self) -> list[str]:
        return list(NAMES)

    def transform_params(self, unconstrained):
        c = np.array(unconstrained, copy=True)
        c[POSITIVE] = np.exp(c[POSITIVE])
        c[GAMMA] = c[GAMMA] * self.gamma_scale
        return c

    def untransform_params(self, constrained):
        u = np.array(constrained, copy=True)
        u[POSITIVE] = np.log(u[POSITIVE])
        u[GAMMA] = u[GAMMA] / self.gamma_scale
        return u

    def temperature_response(self, beta):
        """x_k(β): x_0 = T_0/β, x_k = φ x_{k−1} + a0 T_{k−1} + a1 T_k (lfilter, complex-safe)."""
        phi, a0, a1 = foh_weights(beta, self.dt)
        T = self.temp
        # transposed direct form II: x_0 = a1 T_0 + zi, so zi = T_0/β − a1 T_0
        zi = np.array([T[0] / beta - a1 * T[0]])
        x, _ = lfilter(np.array([a1, a0]), np.array([1.0, -phi]), T, zi=zi)
        return x

    def update(self, params, **kwargs):
        params = super().update(params, **kwargs)
        beta, sigma, gamma, sigma_v, b = params
        # ε_k = φ ε_{k−1} + w_k, var w = σ²(1 − φ²) = σ²(−expm1(−2βΔt))  (as terms.Markov)
        self["transition", 0, 0] = np.exp(-beta * self.dt)
        self["state_cov", 0, 0] = sigma * sigma * -np.expm1(-2.0 * beta * self.dt)
        self["obs_cov", 0, 0] = sigma_v * sigma_v
        # y_k = ε_k + γ x_k(β) + b + v_k
        self["obs_intercept"] = (gamma * self.temperature_response(beta) + b)[None, :]


def as_vector(p) -> np.ndarray:
    return np.array([p[n] for n in NAMES], dtype=float)


def rel(a: float, b: float) -> float:
    return abs(a - b) / max(abs(a), abs(b))


def timed(fn, repeats: int = REPEATS):
    """(best wall s, median wall s, CPU s of the best run, last result) of ``repeats`` calls."""
    times, out = [], None
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        out = fn()
        times.append((time.perf_counter() - t0, time.process_time() - c0))
    best = min(times)
    return best[0], float(np.median([w for w, _ in times])), best[1], out


def per_call(fn, min_time: float = 0.3) -> float:
    """Mean time of one call (s), over enough calls (>= 5) to last ``min_time``."""
    fn()
    n, t0 = 0, time.perf_counter()
    while True:
        fn()
        n += 1
        el = time.perf_counter() - t0
        if el > min_time and n >= 5:
            return el / n


def verdict(ok: bool) -> str:
    return "PASS" if ok else "MISS"


def load() -> str:
    try:
        return "load average " + ", ".join(f"{v:.2f}" for v in os.getloadavg())
    except OSError:
        return "load average n/a"


def sm_fit(mod: DriftMLE, start: np.ndarray, cov_type: str, method: str = "lbfgs"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # ConvergenceWarning: mle_retvals is reported instead
        return mod.fit(start_params=start, method=method, maxiter=1000, disp=False,
                       cov_type=cov_type)


def sm_info(r) -> str:
    ret = r.mle_retvals
    it = ret.get("iterations")
    it = f"{it} iterations, " if it is not None else ""
    return (f"{it}{ret.get('fcalls')} objective calls, warnflag {ret.get('warnflag')}, "
            f"converged={ret.get('converged')}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--blas-threads", type=int, default=None,
                    help="re-run with OPENBLAS_NUM_THREADS / OMP_NUM_THREADS set to this")
    args = ap.parse_args()
    if args.blas_threads is not None and \
            os.environ.get("OPENBLAS_NUM_THREADS") != str(args.blas_threads):
        env = dict(os.environ, OPENBLAS_NUM_THREADS=str(args.blas_threads),
                   OMP_NUM_THREADS=str(args.blas_threads))
        os.execve(sys.executable, [sys.executable, *sys.argv], env)

    m = Model.parse("markov,temp,bias")
    assert m.param_names == NAMES, m.param_names
    s = simulate(m, TRUTH, chamber_profile(HOURS), dt=1.0, seed=SEED)
    print(f"gyrostand ML speed benchmark: {platform.machine()}, {os.cpu_count()} CPUs, "
          f"python {platform.python_version()}, numpy {np.__version__}, "
          f"statsmodels {statsmodels.__version__}; OPENBLAS_NUM_THREADS="
          f"{os.environ.get('OPENBLAS_NUM_THREADS', '(unset)')}; {load()}")
    print(f"data: simulate({m}, chamber_profile({HOURS:g} h), dt=1 s, seed={SEED}): "
          f"{len(s)} samples")
    print("truth: " + ", ".join(f"{k}={v:g}" for k, v in TRUTH.items()))

    start_fit = lsq(s, m)
    start = {n: start_fit.value(n) for n in NAMES}
    start["white.sigma"] = max(start["white.sigma"], 1e-3 * start["markov.sigma"])
    x0 = as_vector(start)
    sm_mod = DriftMLE(s.drift, s.temp, s.dt, gamma_scale=abs(start["temp.gamma"]))

    # --- [1] same model: log-likelihoods at identical parameters -----------------------
    print(f"\n[1] log-likelihood at identical parameters (both exact; must agree to "
          f"{PARITY_REL:g} relative)")
    parity_ok = True
    for label, p in (("truth", TRUTH), ("LSQ start", start)):
        ours = m.loglik(p, s)
        theirs = float(sm_mod.loglike(as_vector(p)))
        r = rel(ours, theirs)
        parity_ok &= r <= PARITY_REL
        print(f"    at {label:<9}: gyrostand {ours:.10f}   statsmodels {theirs:.10f}   "
              f"rel diff {r:.1e}  {verdict(r <= PARITY_REL)}")
    if not parity_ok:
        print("error: the statsmodels model is not the same model; comparison aborted")
        return 1

    # --- [2] one likelihood evaluation -------------------------------------------------
    print("\n[2] one log-likelihood evaluation at the truth (mean over repeated calls)")
    p_true = as_vector(TRUTH)
    t_ll_ours = per_call(lambda: m.loglik(TRUTH, s))
    t_ll_sm = per_call(lambda: sm_mod.loglike(p_true))
    print(f"    gyrostand Model.loglik        {1e3 * t_ll_ours:7.3f} ms")
    print(f"    statsmodels MLEModel.loglike  {1e3 * t_ll_sm:7.3f} ms   "
          f"(statsmodels/gyrostand {t_ll_sm / t_ll_ours:.1f}x)")

    # --- [3] fits ----------------------------------------------------------------------
    print(f"\n[3] fits: wall time, best of {REPEATS} after one untimed warm-up of each library "
          "(numba compilation excluded)")
    print("    statsmodels start = LSQ estimates: "
          + ", ".join(f"{n}={v:.4g}" for n, v in start.items()))
    unscaled = sm_fit(DriftMLE(s.drift, s.temp, s.dt), x0, "none")
    ll_start = float(sm_mod.loglike(x0))
    stuck = abs(unscaled.llf - ll_start) < 1e-6 * abs(ll_start)
    print(f"    (untimed) without the γ rescaling, statsmodels' L-BFGS ends at ln L = "
          f"{unscaled.llf:.3f} (start {ll_start:.3f}; {sm_info(unscaled)})"
          + (": it never leaves its start point" if stuck else ""))

    ml(s, m)
    sm_fit(sm_mod, x0, "approx")
    cases = (
        ("A", "full fit with standard errors", True, "approx", "lbfgs"),
        ("B", "estimates only", False, "none", "lbfgs"),
        ("C", "estimates only, statsmodels BFGS + complex-step score", False, "none", "bfgs"),
    )
    fits = {}
    for key, label, se, cov_type, method in cases:
        b_o, med_o, cpu_o, r_o = timed(lambda se=se: ml(s, m, std_errors=se))
        b_s, med_s, cpu_s, r_s = timed(lambda c=cov_type, mt=method: sm_fit(sm_mod, x0, c, mt))
        fits[key] = (r_o, r_s)
        ratio = b_s / b_o
        ll_o, ll_s = r_o.loglik, float(r_s.llf)
        ll_rel = rel(ll_o, ll_s)
        print(f"\n    ({key}) {label}: ml(std_errors={se}) vs "
              f"fit(method='{method}', cov_type='{cov_type}')")
        print(f"    gyrostand   {b_o:7.3f} s (median {med_o:.3f}, CPU {cpu_o:.3f})  = "
              f"{b_o / TARGET_TIME:.2f} x the {TARGET_TIME:g}-s target  "
              f"{verdict(b_o < TARGET_TIME)}   [{r_o.info['evaluations']} concentrated-"
              f"likelihood evaluations in the search, {r_o.info['start_points']} start points]")
        print(f"    statsmodels {b_s:7.3f} s (median {med_s:.3f}, CPU {cpu_s:.3f})   "
              f"[{sm_info(r_s)}]")
        print(f"    speed ratio statsmodels/gyrostand {ratio:5.1f}x   (target >= "
              f"{TARGET_RATIO:g})  {verdict(ratio >= TARGET_RATIO)}")
        print(f"    max ln L: gyrostand {ll_o:.6f}   statsmodels {ll_s:.6f}   rel diff "
              f"{ll_rel:.1e} (target <= {TARGET_LL_REL:g})  {verdict(ll_rel <= TARGET_LL_REL)}"
              f"   [ours − theirs = {ll_o - ll_s:+.2e}]")
        if r_o.warnings:
            print("    gyrostand warnings: " + "; ".join(r_o.warnings))

    # --- [4] estimates side by side -----------------------------------------------------
    r_o, r_s = fits["A"]
    sm_p = dict(zip(NAMES, np.asarray(r_s.params), strict=True))
    sm_se = dict(zip(NAMES, np.asarray(r_s.bse), strict=True))
    print("\n[4] estimates from the fits (A), ± standard errors from the observed information")
    print(f"    {'parameter':<13}{'truth':>10}{'gyrostand':>15}{'± std':>10}"
          f"{'statsmodels':>15}{'± std':>10}{'rel diff':>10}{'std ratio':>10}")
    for n in NAMES:
        o, t = r_o.value(n), sm_p[n]
        print(f"    {n:<13}{TRUTH[n]:>10.4g}{o:>15.8g}{r_o.std(n):>10.3g}"
              f"{t:>15.8g}{sm_se[n]:>10.3g}{rel(o, t):>10.1e}"
              f"{r_o.std(n) / sm_se[n]:>10.3f}")
    print(f"\n{load()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
