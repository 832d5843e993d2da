#!/usr/bin/env python
"""Reproduce the paper's Tables 1-2 and measure every identifier against the Cramér–Rao bound.

Issue 2, item 5. For the paper's four cases (MODEL.md, "The paper's test": Δt = 1 s, 2000 s,
the built-in 20 → 45 → 45 → 35 °C profile)

    C1 β = 0.0333, γ = −0.01     C2 β = 0.0333, γ = −0.001
    C3 β = 0.00055, γ = −0.001   C4 β = 0.00055, γ = −0.00001

it prints, beside the paper's Table 1 (LSQ) and Table 2 (LKF) values,

* one realization (Monte Carlo run 0, the same seed for every method) fitted by
  least squares (standard regressor Y[k−1] and the text's literal Y[k]), the single-pass
  linearized Kalman filter (variant paper, at the paper's point 10⁻⁴ and at 0.7×, 1.0×,
  1.3× the truth), the iterated LKF (paper), the converging LKF (variant relin, what the
  daemon runs: feedback, re-linearised to its fixed point, noise levels not known
  re-estimated) and exact maximum likelihood;
* a Monte Carlo (``--runs``, default 200, seeded) of the same fits: mean, bias
  (mean − true)/true, RMSE, relative RMSE, √CRLB, efficiency RMSE/√CRLB (± its Monte Carlo
  standard error), the mean reported std over the RMSE (is the method's own error bar
  honest?), and the fraction of fits with warnings or failures;
* the single-pass LKF's dependence on its linearization point (a sweep);
* a PASS/FAIL line per (case, scenario) for issue 2's criterion: ML's RMSE of β and γ
  within 1.15 √CRLB wherever √CRLB is below 20 % of the true value.

Scenarios (the data of a and b are the same simulations, and those of c-known and c-est):

    a        σ_v = 0,   σ known (the paper's setting)        CRLB free: β, γ
    b        σ_v = 0,   σ estimated                          CRLB free: β, γ, σ
    c-known  σ_v = σ/2, σ known, σ_v estimated (ML)          CRLB free: β, γ, σ_v
    c-est    σ_v = σ/2, σ and σ_v estimated                  CRLB free: β, γ, σ_v, σ
    d-known  markov+temp+bias+random_walk, σ_v = σ/2, σ known CRLB free: β, γ, b, σ_v, q
    d-est    the same, every noise level estimated           CRLB free: β, γ, b, σ_v, q, σ

σ: the paper does not give it. Relative errors depend on σ/|γ| (and σ_v/σ), so no single σ
reproduces the paper's ~10 % in all four cases; the script prints the relative √CRLB over a
σ grid beside the paper's printed errors. We use σ = 0.1 (the drift's unit): it puts C2 —
and C1 with σ estimated — at the paper's ~10 % level, makes C4's β as poorly determined as
the paper's 42–64 %, and leaves C3 far more precise than the paper's 8–18 % (C3 would need
σ ≈ 1–3, which would make C4 unidentifiable). ``--sigma`` changes it.

Conventions. In scenarios a/b the ML fit still estimates σ_v (the product always does;
it is on its boundary, 0); the bound treats σ_v = 0 as known, because the Fisher
information of σ_v vanishes at σ_v = 0. The LKF holds its noise levels: at the truth when
"σ known", else at the estimates the LKF itself makes (least squares' moments for a single
process, ML for the sum of processes). The one-realization table uses the paper's relative
error (true − est)/true; the Monte Carlo tables use bias = (mean − true)/true.

The Monte Carlo tables also give robust figures, because a few wild fits can dominate an
RMSE: the median |error|, the fraction of gross errors (|error| > |true|), and for ML the
fraction of fits whose log-likelihood is below that of the true parameters (a feasible point):
those fits missed the maximum, whatever the optimiser reported.

Run:  python benchmarks/paper_tables.py [--runs 200] [--quick] [--out FILE.json]
The default run costs about 1,350 CPU seconds (≈ 11–12 minutes on 2 otherwise idle cores;
longer when other jobs share them); ``--quick`` (30 runs) is a CI smoke test of ~2 minutes.
Reference output: ``benchmarks/results/paper_tables.txt`` (and ``.json``).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")  # two worker processes, one thread each

import argparse  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import math  # noqa: E402
import multiprocessing as mp  # noqa: E402
import platform  # noqa: E402
import re  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections import Counter, defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from gyrostand.core.design.fisher import crlb  # noqa: E402
from gyrostand.core.lkf.filter import lkf  # noqa: E402

# the paper variant logs its loud warnings per fit (thousands here); the tables count them
# from each result's warnings instead
logging.getLogger("gyrostand.core.lkf.filter").setLevel(logging.ERROR)
from gyrostand.core.lsq.fit import lsq  # noqa: E402
from gyrostand.core.ml.fit import ml  # noqa: E402
from gyrostand.core.model import Model  # noqa: E402
from gyrostand.core.profiles import paper_profile  # noqa: E402
from gyrostand.core.simulation import simulate  # noqa: E402

# ---- the paper --------------------------------------------------------------------------
CASES = {"C1": (0.0333, -0.01), "C2": (0.0333, -0.001),
         "C3": (0.00055, -0.001), "C4": (0.00055, -0.00001)}
#: Table 1 (LSQ) and Table 2 (LKF): (β̂, printed β %, γ̂, printed γ %)
PAPER = {
    "C1": {"LSQ": (0.0300, 9.9, -0.00900, 10.9), "LKF": (0.0286, 9.9, -0.0085, 15.0)},
    "C2": {"LSQ": (0.0297, 10.9, -0.00088, 12.8), "LKF": (0.0363, 10.9, -0.0011, 10.0)},
    "C3": {"LSQ": (0.00067, 18.2, -0.00108, 7.7), "LKF": (0.00041, 18.2, -0.0011, 10.0)},
    "C4": {"LSQ": (0.00152, 63.9, -0.000009, 10.0), "LKF": (0.00032, 41.8, -0.000009, 10.0)},
}
PAPER_POINT = 1e-4
BETA, GAMMA, SIG, SV, BIAS, RW = ("markov.beta", "temp.gamma", "markov.sigma", "white.sigma",
                                  "bias.b", "random_walk.q")
SYM = {BETA: "β", GAMMA: "γ", SIG: "σ", SV: "σ_v", BIAS: "b", RW: "q"}

#: the converging LKF (variant relin, lkf's default): the paper's filter with feedback,
#: re-linearised to its fixed point; the single-pass / iterated rows are variant paper
RELIN = "LKF relin"

# ---- our choices ------------------------------------------------------------------------
SIGMA = 0.1          # see the module docstring
SV_RATIO = 0.5       # σ_v = σ/2 in scenarios c and d
SUM_TRUTH = {BIAS: 1.0, RW: 1e-3}   # q√2000 ≈ 0.045: the random walk reaches ≈ σ/2
SIGMA_GRID = (0.01, 0.03, 0.1, 0.3, 1.0)
#: single-pass LKF points: label -> ("rel", β0/β, γ0/γ) or ("abs", β0, γ0);
#: None = the paper's point β0 = γ0 = 1e-4 (lkf's default)
MAIN_POINTS = {"@1e-4": None, "@0.7x": ("rel", 0.7, 0.7), "@1.0x": ("rel", 1.0, 1.0),
               "@1.3x": ("rel", 1.3, 1.3)}
SWEEP_POINTS = {
    "β0=γ0=+1e-4 (paper)": ("abs", PAPER_POINT, PAPER_POINT),
    "β0=1e-4, γ0=−1e-4": ("abs", PAPER_POINT, -PAPER_POINT),
    "0.5× truth": ("rel", 0.5, 0.5), "0.7× truth": ("rel", 0.7, 0.7),
    "0.85× truth": ("rel", 0.85, 0.85), "1.0× truth": ("rel", 1.0, 1.0),
    "1.15× truth": ("rel", 1.15, 1.15), "1.3× truth": ("rel", 1.3, 1.3),
    "1.5× truth": ("rel", 1.5, 1.5), "2× truth": ("rel", 2.0, 2.0),
    "β0 0.7×, γ0 1.3×": ("rel", 0.7, 1.3), "β0 1.3×, γ0 0.7×": ("rel", 1.3, 0.7),
}
SETTINGS = {  # data: model and the truth beyond β, γ, σ
    "s0": ("markov,temp", lambda s: {SV: 0.0}),
    "sv": ("markov,temp", lambda s: {SV: SV_RATIO * s}),
    "sum": ("markov,temp,bias,random_walk", lambda s: {SV: SV_RATIO * s, **SUM_TRUTH}),
}
SCENARIOS = {  # name -> (setting, σ known?, CRLB free params, title)
    "a": ("s0", True, [BETA, GAMMA], "σ_v = 0, σ known (the paper's setting)"),
    "b": ("s0", False, [BETA, GAMMA, SIG], "σ_v = 0, σ estimated"),
    "c-known": ("sv", True, [BETA, GAMMA, SV], "σ_v = σ/2, σ known, σ_v estimated"),
    "c-est": ("sv", False, [BETA, GAMMA, SV, SIG], "σ_v = σ/2, σ and σ_v estimated"),
    "d-known": ("sum", True, [BETA, GAMMA, BIAS, SV, RW],
                "sum of processes markov+temp+bias+random_walk, σ_v = σ/2, σ known"),
    "d-est": ("sum", False, [BETA, GAMMA, BIAS, SV, RW, SIG],
              "sum of processes markov+temp+bias+random_walk, σ_v = σ/2, all noise estimated"),
}
ML_LIMIT, BOUND_LIMIT = 1.15, 0.20   # issue 2's acceptance criterion
MISSED_LL = 0.5                      # ML below ln L(truth) by more than this: a missed maximum
ML0 = "ML σ_v=0 known"               # scenarios a/b: ML with the measurement noise fixed at 0
#: where σ_v = 0 (a, b) the "nuisance" bound treats σ_v as unknown; its Fisher information
#: vanishes at σ_v = 0 in the σ_v parametrization, so it is evaluated at σ_v = 1e-3 σ
#: (checked: the same to 4 digits at 1e-2 σ)
SV_NUISANCE = 1e-3


def truth_of(setting: str, case: str, sigma: float) -> dict[str, float]:
    b, g = CASES[case]
    return {BETA: b, GAMMA: g, SIG: sigma, **SETTINGS[setting][1](sigma)}


def point_of(spec, truth: dict[str, float]) -> tuple[float, float]:
    if spec is None:
        return PAPER_POINT, PAPER_POINT
    if spec[0] == "abs":
        return spec[1], spec[2]
    return spec[1] * truth[BETA], spec[2] * truth[GAMMA]


# ---- one Monte Carlo run (in a worker) --------------------------------------------------
_NUM = re.compile(r"[-+]?\d+(\.\d+)?(e[-+]?\d+)?")


def _record(fn, check_ll=None) -> dict:
    """Run one fit; keep values, reported stds, (number-free) warnings, or the error.

    ``check_ll``: the log-likelihood at the true parameters; an ML estimate below it has
    missed the maximum (the truth is a feasible point), which is recorded as ``ll_gap``.
    """
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        r = fn()
    except Exception as exc:  # noqa: BLE001 - a failure is a result here: it is counted
        return {"err": f"{type(exc).__name__}: {exc}", "t": time.perf_counter() - t0,
                "cpu": time.process_time() - c0}
    rec = {"v": dict(r.values), "sd": {k: e.std for k, e in r.parameters.items()},
           "w": [_NUM.sub("#", w) for w in r.warnings], "t": time.perf_counter() - t0,
           "cpu": time.process_time() - c0}
    if "passes" in r.info:
        rec["passes"] = int(r.info["passes"])
    if check_ll is not None and r.loglik is not None:
        rec["ll_gap"] = float(r.loglik - check_ll)
    return rec


def fit_task(task: tuple) -> tuple:
    """Simulate one realization and fit every method in both modes (σ known / estimated)."""
    setting, case, run, seed, sigma = task
    model = Model.parse(SETTINGS[setting][0])
    truth = truth_of(setting, case, sigma)
    rng = np.random.default_rng(seed)
    s = simulate(model, truth, paper_profile(), dt=1.0, seed=rng)
    full = run == 0  # the one-realization table wants ML's standard errors too
    out: dict[str, dict] = {"known": {}, "est": {}}
    single = setting != "sum"
    if single:
        for label, reg in (("LSQ Y[k-1]", "previous"), ("LSQ Y[k] (text)", "current")):
            rec = _record(lambda reg=reg: lsq(s, model, regressor=reg))
            out["known"][label] = out["est"][label] = rec
    else:
        out["known"]["LSQ"] = out["est"]["LSQ"] = _record(lambda: lsq(s, model))
    # σ known: the LKF holds every noise level at the truth; ML fixes σ only
    held = {k: truth[k] for k in (SV, RW) if k in truth}
    ll_true = model.loglik(truth, s)
    out["known"]["ML"] = _record(lambda: ml(s, model, sigma=sigma, std_errors=full), ll_true)
    out["est"]["ML"] = _record(lambda: ml(s, model, std_errors=full), ll_true)
    if setting == "s0":  # σ_v = 0 known as well: like for like with the σ_v-known bound
        out["known"][ML0] = _record(lambda: ml(s, model, fixed={SIG: sigma, SV: 0.0},
                                               std_errors=full), ll_true)
        out["est"][ML0] = _record(lambda: ml(s, model, fixed={SV: 0.0}, std_errors=full),
                                  ll_true)
    if single:
        held_est = None  # lkf estimates its held noise levels itself (LSQ moments)
    else:
        # what lkf would do itself (ml with nothing fixed), without fitting ML twice
        v = out["est"]["ML"].get("v")
        held_est = {k: abs(v[k]) for k in (SIG, SV, RW)} if v else None
    lk = {"known": {"sigma": sigma, "held": held}, "est": {"held": held_est}}
    points = dict(MAIN_POINTS)
    if setting == "s0":  # the sweep is shown for scenario a
        points.update({"sweep:" + k: v for k, v in SWEEP_POINTS.items()})
    for mode, kw in lk.items():
        done: dict[tuple, dict] = {}
        for label, spec in points.items():
            if mode == "est" and label.startswith("sweep:"):
                continue
            b0, g0 = point_of(spec, truth)
            if (b0, g0) not in done:
                done[(b0, g0)] = _record(lambda b0=b0, g0=g0, kw=kw: lkf(
                    s, model, variant="paper", beta0=b0, gamma0=g0, **kw))
            name = label if label.startswith("sweep:") else f"LKF 1-pass {label}"
            out[mode][name] = done[(b0, g0)]
        out[mode]["LKF iterated"] = _record(lambda kw=kw: lkf(s, model, variant="paper",
                                                              iterate=True, **kw))
        # the converging filter (the default, what the daemon runs): to its fixed point,
        # the noise levels not known re-estimated
        out[mode][RELIN] = _record(lambda kw=kw, mode=mode: lkf(
            s, model, **(kw if mode == "known" else {})))
    return setting, case, run, out


def crlb_task(task: tuple) -> tuple:
    """√CRLB of one (scenario, case), and a second estimate with another seed (its accuracy)."""
    scen, case, sigma, n_mc = task
    setting, _, free, _ = SCENARIOS[scen]
    model = Model.parse(SETTINGS[setting][0])
    truth = truth_of(setting, case, sigma)
    t, T = paper_profile().grid(1.0)
    a = crlb(model, truth, t, T, dt=1.0, free=free, n_mc=n_mc, seed=12345)
    b = crlb(model, truth, t, T, dt=1.0, free=free, n_mc=n_mc, seed=54321)
    nuis = None
    if truth[SV] == 0:
        nuis = crlb(model, {**truth, SV: SV_NUISANCE * sigma}, t, T, dt=1.0, free=[*free, SV],
                    n_mc=n_mc, seed=12345)
        nuis.pop(SV)
    return scen, case, a, {k: abs(a[k] - b[k]) / a[k] for k in a}, nuis


def sweep_task(task: tuple) -> tuple:
    """Relative √CRLB of β and γ at one σ, σ known and σ estimated (σ_v = 0)."""
    case, sigma, n_mc = task
    model = Model.parse("markov,temp")
    truth = truth_of("s0", case, sigma)
    t, T = paper_profile().grid(1.0)
    k = crlb(model, truth, t, T, free=[BETA, GAMMA], n_mc=n_mc)
    e = crlb(model, truth, t, T, free=[BETA, GAMMA, SIG], n_mc=n_mc)
    b, g = CASES[case]
    return case, sigma, {"known": (k[BETA] / b, k[GAMMA] / abs(g)),
                         "est": (e[BETA] / b, e[GAMMA] / abs(g))}


# ---- statistics -------------------------------------------------------------------------
def mc_stats(recs: list[dict], name: str, true: float, bound: float | None) -> dict:
    ok = [r for r in recs if "err" not in r]
    n = len(recs)
    d = {"n": n, "fail": (n - len(ok)) / n if n else 0.0,
         "warn": sum(bool(r["w"]) for r in ok) / n if n else 0.0}
    x = np.array([r["v"][name] for r in ok])
    if x.size == 0:
        return d
    e = x - true
    mse = float(np.mean(e * e))
    rmse = math.sqrt(mse)
    # standard error of the RMSE: se(MSE) = std(e²)/√n, se(RMSE) = se(MSE)/(2 RMSE)
    se_rmse = float(np.std(e * e, ddof=1) / math.sqrt(x.size) / (2 * rmse)) if x.size > 1 else 0
    sd = np.array([r["sd"].get(name, 0.0) for r in ok])
    d.update({"med_abs_pct": 100 * float(np.median(np.abs(e))) / abs(true),
              "gross": float(np.sum(np.abs(e) > abs(true))) / n})
    gaps = [r["ll_gap"] for r in ok if "ll_gap" in r]
    if gaps:
        d["missed"] = float(np.sum(np.array(gaps) < -MISSED_LL)) / n
    d.update({"mean": float(np.mean(x)), "bias_pct": 100 * float(np.mean(e)) / true,
              "rmse": rmse, "rel_rmse_pct": 100 * rmse / abs(true), "se_rmse": se_rmse,
              "sd_over_rmse": float(np.mean(sd)) / rmse if np.all(sd > 0) and rmse > 0 else None})
    if bound:
        d.update({"crlb": bound, "eff": rmse / bound, "eff_se": se_rmse / bound})
    return d


def common_warnings(recs: list[dict], top: int = 2) -> list[tuple[str, float]]:
    c = Counter(w for r in recs for w in set(r.get("w", [])))
    c.update(r["err"][:160] for r in recs if "err" in r)
    return [(w, k / len(recs)) for w, k in c.most_common(top)]


# ---- formatting -------------------------------------------------------------------------
def g(x, nd=4) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    return f"{x:.{nd}g}"


def pct(x, nd=1) -> str:
    return "—" if x is None else f"{x:+.{nd}f}"


def table(rows: list[list[str]], head: list[str], indent: str = "  ") -> str:
    w = [max(len(str(r[i])) for r in [head, *rows]) for i in range(len(head))]
    line = lambda r: indent + "  ".join(  # noqa: E731
        str(c).ljust(w[i]) if i < 2 else str(c).rjust(w[i]) for i, c in enumerate(r))
    return "\n".join([line(head), indent + "-" * (sum(w) + 2 * len(w) - 2),
                      *map(line, rows)])


def params_shown(scen: str, method: str) -> list[str]:
    setting, known, free, _ = SCENARIOS[scen]
    base = [BETA, GAMMA]
    if setting == "sum":
        base = [BETA, GAMMA, BIAS]
    if method == "ML":
        return free + ([SV] if SV not in free else [])
    if method == ML0:
        return free
    return base


def method_order(scen: str) -> list[str]:
    setting = SCENARIOS[scen][0]
    lsq_rows = ["LSQ Y[k-1]", "LSQ Y[k] (text)"] if setting != "sum" else []
    return (lsq_rows + [f"LKF 1-pass {k}" for k in MAIN_POINTS]
            + ["LKF iterated", RELIN, "ML"]
            + ([ML0] if setting == "s0" else []))


def one_realization(scen: str, res: dict, sigma: float) -> tuple[str, dict]:
    setting, known, _, title = SCENARIOS[scen]
    mode = "known" if known else "est"
    rows, js = [], {}
    for case in CASES:
        truth = truth_of(setting, case, sigma)
        rec0 = res[setting][case][0][mode]
        tb, tg = truth[BETA], truth[GAMMA]
        if setting == "s0":
            for tab, m in (("1", "LSQ"), ("2", "LKF")):
                b, bp, gm, gp = PAPER[case][m]
                rows.append([case, f"paper Table {tab} ({m})", g(b), f"{100 * (tb - b) / tb:+.1f} [{bp}]",
                             g(gm), f"{100 * (tg - gm) / tg:+.1f} [{gp}]", ""])
        for meth in method_order(scen):
            r = rec0[meth]
            if "err" in r:
                rows.append([case, meth, "error", "", "", "", r["err"][:50]])
                continue
            v, sd = r["v"], r["sd"]
            note = ""
            if meth in ("ML", ML0) and mode == "est":
                note = f"σ̂={g(v[SIG], 3)}"
            if meth == "ML":
                note += f" σ̂_v={g(v[SV], 2)}"
            if setting == "sum" and meth == "ML":
                note += f" b̂={g(v[BIAS], 3)} q̂={g(v[RW], 2)}"
            if r["w"]:
                note += f" [{len(r['w'])} warning(s)]"
            rows.append([case, meth, f"{g(v[BETA])}±{g(sd[BETA], 2)}",
                         f"{100 * (tb - v[BETA]) / tb:+.1f}", f"{g(v[GAMMA])}±{g(sd[GAMMA], 2)}",
                         f"{100 * (tg - v[GAMMA]) / tg:+.1f}", note.strip()])
            js[f"{case}/{meth}"] = {"values": v, "std": sd, "warnings": r["w"]}
    head = ["case", "method", "β̂ ± std", "err β %", "γ̂ ± std", "err γ %", "notes"]
    txt = (f"One realization (Monte Carlo run 0), scenario {scen}: {title}\n"
           "  err % = (true − est)/true, the paper's definition; [printed %] = the paper's "
           "own percentages\n" + table(rows, head))
    return txt, js


def mc_table(scen: str, res: dict, bounds: dict, sigma: float,
             nuisance: dict) -> tuple[str, dict]:
    setting, known, _, title = SCENARIOS[scen]
    mode = "known" if known else "est"
    out, js = [], {}
    for case in CASES:
        truth = truth_of(setting, case, sigma)
        runs = res[setting][case]
        rows, cj = [], {}
        for meth in method_order(scen):
            recs = [runs[k][mode][meth] for k in sorted(runs)]
            for p in params_shown(scen, meth):
                if truth[p] == 0:
                    xs = [r["v"][p] for r in recs if "err" not in r]
                    rows.append([meth, SYM[p], g(float(np.mean(xs))), "(true 0)",
                                 g(float(np.sqrt(np.mean(np.square(xs))))), *[""] * 9])
                    continue
                st = mc_stats(recs, p, truth[p], bounds[case].get(p))
                cj[f"{meth}/{p}"] = st
                if "mean" not in st:
                    rows.append([meth, SYM[p], "all failed", *[""] * 8,
                                 f"{100 * st['warn']:.0f}", f"{100 * st['fail']:.0f}", ""])
                    continue
                rows.append([
                    meth, SYM[p], g(st["mean"]), pct(st["bias_pct"]), g(st["rmse"], 3),
                    f"{st['rel_rmse_pct']:.1f}", f"{st['med_abs_pct']:.1f}",
                    g(st.get("crlb"), 3),
                    f"{st['eff']:.2f}±{st['eff_se']:.2f}" if "eff" in st else "—",
                    "—" if st["sd_over_rmse"] is None else f"{st['sd_over_rmse']:.2f}",
                    f"{100 * st['gross']:.0f}", f"{100 * st['warn']:.0f}",
                    f"{100 * st['fail']:.0f}",
                    f"{100 * st['missed']:.1f}" if "missed" in st else "—"])
            cw = common_warnings(recs)
            if cw:
                cj[f"{meth}/warnings"] = cw
        b = bounds[case]
        hdr = (f"{case}: truth " + ", ".join(f"{SYM[k]}={g(v)}" for k, v in truth.items())
               + "; √CRLB " + ", ".join(f"{SYM[k]} {g(v, 3)} ({100 * v / abs(truth[k]):.1f}%)"
                                        for k, v in b.items()))
        if case in nuisance:
            hdr += ("\n  (√CRLB with σ_v as an unknown nuisance, at σ_v → 0: "
                    + ", ".join(f"{SYM[k]} {g(v, 3)} ({100 * v / abs(truth[k]):.1f}%)"
                                for k, v in nuisance[case].items())
                    + "; the table's √CRLB takes σ_v = 0 as known)")
        head = ["method", "par", "mean", "bias %", "RMSE", "rRMSE %", "med|e| %", "√CRLB",
                "RMSE/√CRLB", "sd/RMSE", "gross%", "warn%", "fail%", "missed%"]
        out.append(hdr + "\n" + table(rows, head))
        # the most frequent warnings / errors, per method
        notes = []
        for meth in method_order(scen):
            recs = [runs[k][mode][meth] for k in sorted(runs)]
            for w, f in common_warnings(recs):
                notes.append(f"    {meth}: {100 * f:.0f}% \"{w}\"")
        if notes:
            out.append("  most frequent warnings/errors (numbers replaced by #):\n"
                       + "\n".join(notes))
        js[case] = cj
    txt = (f"Monte Carlo, scenario {scen}: {title}; {len(res[setting]['C1'])} runs per case\n"
           "  bias % = (mean − true)/true; rRMSE = RMSE/|true|; RMSE/√CRLB ± its Monte Carlo "
           "standard error; med|e| = median |error|/|true|\n  (robust: RMSE ≫ med|e| means a few "
           "wild fits); sd/RMSE = mean reported std / RMSE (1 = honest error bars);\n  gross% = "
           "fits with |error| > |true| (sign wrong or more than double); warn%/fail% = fits with "
           "warnings / raising;\n  missed% (ML) = fits whose ln L is below ln L at the true "
           f"parameters by > {MISSED_LL:g}: the optimiser missed the maximum\n\n" + "\n\n".join(out))
    return txt, js


def sweep_table(scen: str, res: dict, bounds: dict, sigma: float) -> tuple[str, dict]:
    setting = SCENARIOS[scen][0]
    rows, js = [], {}
    for case in CASES:
        truth = truth_of(setting, case, sigma)
        runs = res[setting][case]
        for label in SWEEP_POINTS:
            recs = [runs[k]["known"]["sweep:" + label] for k in sorted(runs)]
            sb = mc_stats(recs, BETA, truth[BETA], bounds[case][BETA])
            sg = mc_stats(recs, GAMMA, truth[GAMMA], bounds[case][GAMMA])
            js[f"{case}/{label}"] = {"beta": sb, "gamma": sg}
            if "mean" not in sb:
                rows.append([case, label, "all failed", "", "", "", "", "", ""])
                continue
            rows.append([case, label, pct(sb["bias_pct"]), f"{sb['eff']:.2f}",
                         pct(sg["bias_pct"]), f"{sg['eff']:.2f}",
                         "—" if sb["sd_over_rmse"] is None else f"{sb['sd_over_rmse']:.2f}",
                         f"{100 * sb['warn']:.0f}", f"{100 * sb['fail']:.0f}"])
    head = ["case", "linearization point (β0, γ0)", "β bias %", "β RMSE/√CRLB", "γ bias %",
            "γ RMSE/√CRLB", "β sd/RMSE", "warn%", "fail%"]
    txt = (f"Single-pass LKF vs its linearization point, scenario {scen}: "
           f"{SCENARIOS[scen][3]}\n" + table(rows, head))
    return txt, js


def criterion(res: dict, bounds: dict, nuisance: dict, sigma: float,
              scens: list[str]) -> tuple[list[str], list[dict]]:
    """Issue 2's ML criterion, one line per (scenario, case, ML variant, bound)."""
    lines, js = [], []
    for scen in scens:
        setting, known, _, _ = SCENARIOS[scen]
        mode = "known" if known else "est"
        for case in CASES:
            truth = truth_of(setting, case, sigma)
            runs = res[setting][case]
            checks = [("ML", bounds[scen][case], "CRLB", True)]
            if case in nuisance[scen]:  # σ_v = 0: like for like, and ML as the product runs it
                checks = [(ML0, bounds[scen][case], "CRLB(σ_v known)", True),
                          ("ML", bounds[scen][case], "CRLB(σ_v known)", False),
                          ("ML", nuisance[scen][case], "CRLB(σ_v nuisance)", True)]
            for meth, bnds, blabel, like in checks:
                recs = [runs[k][mode][meth] for k in sorted(runs)]
                parts, verdicts = [], []
                for p in (BETA, GAMMA):
                    bnd = bnds[p]
                    st = mc_stats(recs, p, truth[p], bnd)
                    rel = bnd / abs(truth[p])
                    if "eff" not in st:
                        parts.append(f"{SYM[p]}: all fits failed")
                        verdicts.append("FAIL")
                        continue
                    v = "n/a" if rel >= BOUND_LIMIT else (
                        "PASS" if st["eff"] <= ML_LIMIT else "FAIL")
                    if v != "n/a":
                        verdicts.append(v)
                    parts.append(f"{SYM[p]} {st['eff']:.2f}±{st['eff_se']:.2f} "
                                 f"({100 * rel:.1f}%) {v}")
                    js.append({"scenario": scen, "case": case, "method": meth, "bound": blabel,
                               "like_for_like": like, "param": p, "eff": st["eff"],
                               "eff_se": st["eff_se"], "crlb_rel": rel, "verdict": v,
                               "fail": st["fail"], "warn": st["warn"]})
                overall = "FAIL" if "FAIL" in verdicts else "PASS" if verdicts else "n/a"
                tag = "" if like else "  [cross-check: estimator and bound differ in σ_v]"
                if setting == "sum":
                    tag += "  [beyond the issue's criterion]"
                lines.append(f"  {overall:<4}  {scen:<8} {case}  {meth:<15} vs {blabel:<19} "
                             + ";  ".join(parts) + tag)
    return lines, js


def git_commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, cwd=Path(__file__).parent, check=True).stdout.strip()
    except Exception:  # noqa: BLE001
        return "unknown"


# ---- main -------------------------------------------------------------------------------
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=None, help="Monte Carlo runs per case "
                    "(default 200; 30 with --quick)")
    ap.add_argument("--quick", action="store_true",
                    help="smoke test: 30 runs, smaller Fisher-information Monte Carlo")
    ap.add_argument("--sigma", type=float, default=SIGMA, help="the drift's σ (default 0.1)")
    ap.add_argument("--crlb-mc", type=int, default=None,
                    help="data sets averaged in the expected Fisher information (default 400)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=2024, help="base seed of the Monte Carlo")
    ap.add_argument("--scenarios", default=",".join(SCENARIOS),
                    help="comma-separated subset of " + ",".join(SCENARIOS))
    ap.add_argument("--out", type=Path, help="also write the tables as JSON to this file")
    args = ap.parse_args(argv)
    runs = args.runs or (30 if args.quick else 200)
    n_mc = args.crlb_mc or (100 if args.quick else 400)
    sigma = args.sigma
    scens = [s.strip() for s in args.scenarios.split(",") if s.strip()]
    bad = [s for s in scens if s not in SCENARIOS]
    if bad:
        ap.error(f"unknown scenario(s) {bad}; choose from {list(SCENARIOS)}")
    settings = sorted({SCENARIOS[s][0] for s in scens}, key=list(SETTINGS).index)
    t_start = time.perf_counter()
    print("gyrostand — reproduction of the paper's Tables 1–2 (issue 2, item 5)")
    print(f"commit {git_commit()}, python {platform.python_version()}, numpy {np.__version__}, "
          f"{os.cpu_count()} CPUs, {args.workers} worker processes")
    print(f"runs per case {runs}, base seed {args.seed}, Fisher-information Monte Carlo "
          f"n_mc {n_mc}, σ = {sigma:g}, σ_v = {SV_RATIO:g}σ in c/d, "
          f"sum-of-processes extras b = {SUM_TRUTH[BIAS]:g}, q = {SUM_TRUTH[RW]:g} y/√s")
    print("Paper's test: Δt = 1 s, 0–2000 s, T: 20→45 °C (0–500 s), 45 °C (500–1000 s), "
          "45→35 °C (1000–2000 s)\n")
    report: dict = {"meta": {"commit": git_commit(), "runs": runs, "seed": args.seed,
                             "crlb_n_mc": n_mc, "sigma": sigma, "sv_ratio": SV_RATIO,
                             "sum_truth": SUM_TRUTH, "workers": args.workers,
                             "ml_limit": ML_LIMIT, "bound_limit": BOUND_LIMIT}}
    ctx = mp.get_context("fork")
    with ctx.Pool(args.workers) as pool:
        # -- the σ question --------------------------------------------------------------
        t0 = time.perf_counter()
        sw = pool.map(sweep_task, [(c, s, max(20, n_mc // 8)) for c in CASES for s in SIGMA_GRID])
        rows = []
        for c in CASES:
            pl, pk = PAPER[c]["LSQ"], PAPER[c]["LKF"]
            r = [c, f"{pl[1]:g}/{pl[3]:g}  {pk[1]:g}/{pk[3]:g}"]
            for s in SIGMA_GRID:
                d = next(x[2] for x in sw if x[0] == c and x[1] == s)
                r.append(f"{100 * d['est'][0]:.1f}/{100 * d['est'][1]:.1f} "
                         f"({100 * d['known'][0]:.1f}/{100 * d['known'][1]:.1f})")
            rows.append(r)
        print("Which σ? Relative √CRLB of β/γ in % with σ estimated (σ known in brackets), "
              "σ_v = 0, against the paper's\nprinted relative errors β/γ (Table 1 LSQ, "
              "Table 2 LKF). Errors scale with σ/|γ|: C1 at σ equals C2 at σ/10.")
        print(table(rows, ["case", "paper % LSQ  LKF", *[f"σ = {s:g}" for s in SIGMA_GRID]]))
        print(f"→ σ = {sigma:g}: C2 (and C1 with σ estimated) at the paper's ~10 % level, C4's β "
              "as poor as the paper's 42–64 %; C3 is\n  then much more precise than the "
              "paper's 8–18 % (it would need σ ≈ 1–3, making C4 unidentifiable). No single σ\n"
              "  fits all four cases; the paper's single realizations cannot pin it down.  "
              f"[{time.perf_counter() - t0:.1f} s]\n")
        report["sigma_sweep"] = [{"case": c, "sigma": s, **d} for c, s, d in sw]

        # -- bounds ------------------------------------------------------------------------
        t0 = time.perf_counter()
        cr = pool.map(crlb_task, [(s, c, sigma, n_mc) for s in scens for c in CASES])
        bounds: dict = {s: {} for s in scens}
        nuisance: dict = {s: {} for s in scens}
        crlb_acc = {}
        for s, c, a, acc, nuis in cr:
            bounds[s][c] = a
            if nuis:
                nuisance[s][c] = nuis
            crlb_acc[(s, c)] = max(acc.values())
        t_crlb = time.perf_counter() - t0
        worst = max(crlb_acc.items(), key=lambda kv: kv[1])
        print(f"√CRLB: expected Fisher information of the exact likelihood, averaged over "
              f"{n_mc} simulated data sets;\n  a second estimate with another seed differs by "
              f"at most {100 * worst[1]:.1f}% ({worst[0][0]} {worst[0][1]}), median "
              f"{100 * float(np.median(list(crlb_acc.values()))):.1f}%  [{t_crlb:.1f} s]\n")
        report["crlb"] = {s: bounds[s] for s in scens}
        report["crlb_sv_nuisance"] = {s: v for s, v in nuisance.items() if v}
        report["crlb_seed_rel_diff"] = {f"{s}/{c}": v for (s, c), v in crlb_acc.items()}

        # -- Monte Carlo -------------------------------------------------------------------
        # seed of run k: (base seed, setting, case, k) -- independent of --scenarios
        tasks = [(st, c, k, [int(x) for x in np.random.SeedSequence(
            [args.seed, list(SETTINGS).index(st), list(CASES).index(c), k]).generate_state(2)],
            sigma) for st in settings for c in CASES for k in range(runs)]
        tasks.sort(key=lambda t: t[0] != "sum")  # slowest first, for load balance
        res: dict = {st: {c: {} for c in CASES} for st in settings}
        cpu: Counter = Counter()
        per_method: defaultdict = defaultdict(list)
        load0 = os.getloadavg()
        wall: dict[str, float] = {}
        t0 = time.perf_counter()
        done = 0
        for st, c, k, out in pool.imap_unordered(fit_task, tasks, chunksize=2):
            res[st][c][k] = out
            fits = {id(x): (name, x) for m in out.values() for name, x in m.items()}
            for name, r in fits.values():
                cpu[st] += r["cpu"]
                key = "LKF 1-pass (sweep point)" if name.startswith("sweep:") else name
                per_method[(st, key)].append(r["cpu"])
            wall[st] = time.perf_counter() - t0
            done += 1
            if done % max(1, len(tasks) // 20) == 0:
                print(f"  ... {done}/{len(tasks)} realizations fitted "
                      f"({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
        t_mc = time.perf_counter() - t0

    # -- tables -------------------------------------------------------------------------
    report["scenarios"] = {}
    for scen in scens:
        setting = SCENARIOS[scen][0]
        print("=" * 100)
        print(f"SCENARIO {scen}: {SCENARIOS[scen][3]}")
        print("=" * 100)
        if setting == "sum":
            err = res["sum"]["C1"][0]["known"]["LSQ"].get("err", "(no error!)")
            print(f"LSQ on markov,temp,bias,random_walk refuses, as it must:\n  {err}\n")
        one, one_js = one_realization(scen, res, sigma)
        print(one + "\n")
        mct, mc_js = mc_table(scen, res, bounds[scen], sigma, nuisance[scen])
        print(mct + "\n")
        entry = {"title": SCENARIOS[scen][3], "crlb": bounds[scen], "one_realization": one_js,
                 "monte_carlo": mc_js}
        if scen == "a":
            swt, sw_js = sweep_table(scen, res, bounds[scen], sigma)
            print(swt + "\n")
            entry["lkf_point_sweep"] = sw_js
        report["scenarios"][scen] = entry

    print("=" * 100)
    print(f"ACCEPTANCE (issue 2): ML's Monte Carlo RMSE of β and γ ≤ {ML_LIMIT} √CRLB wherever "
          f"√CRLB < {100 * BOUND_LIMIT:.0f}% of the true value")
    print(f"  (ratio ± its Monte Carlo standard error; with {runs} runs the RMSE itself is known "
          f"to about ±{100 / math.sqrt(2 * runs):.0f}%)")
    if runs < 200:
        print(f"  NOTE: {runs} runs is a smoke test; these verdicts are dominated by Monte Carlo "
              "noise (the issue asks for >= 200 runs)")
    lines, crit = criterion(res, bounds, nuisance, sigma, scens)
    print("  each: RMSE/√CRLB ± Monte Carlo s.e. (√CRLB as % of the truth); n/a = √CRLB ≥ "
          f"{100 * BOUND_LIMIT:.0f}% of the truth")
    print("\n".join(lines))
    issue = [c for c in crit if c["like_for_like"] and c["verdict"] != "n/a"
             and SCENARIOS[c["scenario"]][0] != "sum"]
    bad = [c for c in issue if c["verdict"] == "FAIL"]
    print(f"  issue-2 criterion (scenarios a–c, estimator and bound with the same knowledge): "
          f"{len(issue) - len(bad)}/{len(issue)} (case, parameter) checks pass"
          + (": FAIL " + ", ".join(f"{c['scenario']} {c['case']} {SYM[c['param']]} "
                                   f"{c['eff']:.2f}±{c['eff_se']:.2f}" for c in bad)
             if bad else ""))
    report["criterion"] = crit
    missed = []
    for scen in scens:
        setting, known, _, _ = SCENARIOS[scen]
        for case in CASES:
            for meth in ("ML", ML0):
                recs = [r[("known" if known else "est")].get(meth) for r in
                        res[setting][case].values()]
                gaps = np.array([r["ll_gap"] for r in recs if r and "ll_gap" in r])
                if gaps.size and np.any(gaps < -MISSED_LL):
                    bad_g = gaps[gaps < -MISSED_LL]
                    missed.append(f"    {scen:<8} {case} {meth}: {bad_g.size}/{gaps.size} fits, "
                                  f"ln L short of ln L(truth) by {-bad_g.max():.1f} … "
                                  f"{-bad_g.min():.1f}")
    print(f"  ML fits that missed the likelihood maximum (ln L below ln L at the true parameters "
          f"by > {MISSED_LL:g}, without a warning unless the table says so):")
    print("\n".join(missed) if missed else "    none")
    report["ml_missed_maximum"] = missed
    t_total = time.perf_counter() - t_start
    ru = [resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]
    cpu_all = sum(r.ru_utime + r.ru_stime for r in ru)
    print("\nTiming (this machine; CPU seconds are what the fits cost, wall clock depends on "
          "what else runs):")
    rows = []
    for (st, name), v in sorted(per_method.items(), key=lambda kv: (kv[0][0], kv[0][1])):
        rows.append([st, name, str(len(v)), f"{1000 * float(np.mean(v)):.0f}",
                     f"{1000 * float(np.max(v)):.0f}", f"{float(np.sum(v)):.0f}"])
    print(table(rows, ["setting", "fit (both modes where they differ)", "fits", "mean CPU ms",
                       "max CPU ms", "total CPU s"]))
    for st in settings:
        n = sum(1 for t in tasks if t[0] == st)
        print(f"  setting {st:<4}: {n} realizations, fit CPU {cpu[st]:.0f} s "
              f"({cpu[st] / n:.2f} s per realization, every method and mode)")
    print(f"  wall clock: Monte Carlo {t_mc:.0f} s on {args.workers} worker processes, bounds "
          f"{t_crlb:.0f} s, total {t_total:.0f} s; CPU time of all processes {cpu_all:.0f} s "
          f"(→ ≈ {cpu_all / args.workers:.0f} s wall on {args.workers} otherwise idle cores)")
    load1 = os.getloadavg()
    print(f"  load average (1 min) at the Monte Carlo's start {load0[0]:.1f}, at the end "
          f"{load1[0]:.1f} (other jobs shared the cores when it exceeds {args.workers})")
    report["timing"] = {"total_s": t_total, "monte_carlo_s": t_mc, "crlb_s": t_crlb,
                        "fit_cpu_s": dict(cpu), "cpu_all_s": cpu_all,
                        "load_avg_start_end": [load0[0], load1[0]]}
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1, default=_json_default))
        print(f"  JSON written to {args.out}")
    return 0


def _json_default(o):
    if isinstance(o, np.floating | np.integer):
        return o.item()
    if isinstance(o, tuple):
        return list(o)
    raise TypeError(type(o))


if __name__ == "__main__":
    sys.exit(main())
