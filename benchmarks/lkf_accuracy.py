"""Accuracy, honesty and cost of the daemon's online LKF, against exact ML (issue 9).

Prints three tables:

1. Monte Carlo of the paper's scenario (2000 s, 20 -> 45 -> 45 -> 35 degC, sigma = 0.1),
   cases C1, C2, C3, sigma_v in {0, sigma/2}: for beta and gamma, the RMSE and bias (% of
   the truth) of the online LKF at stop and of ML on the same record, their ratio, the
   coverage of the truth by the online +-3 std band at every 100-s checkpoint after the
   warm-up (the minimum over checkpoints), and spread / mean reported std at the end.
   Targets: RMSE <= 1.1 x ML (C1, C2), <= 1.2 x (C3); bias within 2 pp of ML; coverage
   >= 0.98; spread / std in 0.9-1.15.
2. A 6-h chamber-style run (markov, temp, bias, white, temp_rate; ramps and soaks):
   RMSE of every linear coefficient, online LKF vs ML (target <= 1.2 x), and the
   coverage among ``ok`` statuses at every 100-s checkpoint.
3. 1-h runs (issue 24, item 6), three scenarios of ``HOUR``: at every 100-s checkpoint
   after the warm-up, how many runs say ``ok`` and the +-3 std coverage of every reported
   coefficient among them (target >= 0.98 at every checkpoint, for every coefficient;
   the same target holds in tables 1 and 2, judged in all three as :func:`ok_summary`
   says: no checkpoint below it beyond chance, and pooled), and how often ``ok`` stands where ML on the
   whole hour calls the likelihood flat (target 0); ML's own +-3 std coverage of the truth
   on the whole hour and the RMS of its errors in its stds.
4. Cost: a 24-h record (86,400 bins) through the online LKF, per bin, re-linearisations
   included (target <= 0.3 ms), and the number of re-linearisations and passes.

The online LKF is the daemon's: :class:`gyrostand.session.online.LkfTrack` with the default
``lkf:`` section (warm-up of 300 bins, then re-linearised every 100 bins, noise levels
re-estimated), fed bin by bin, then ``finish()`` at stop.

    .venv/bin/python benchmarks/lkf_accuracy.py [--runs 200] [--chamber-runs 40]
        [--hour-runs 100] [--jobs 2] [--skip paper,chamber,hour,cost]
"""

from __future__ import annotations

import argparse
import math
import multiprocessing as mp
import os
import time

import numpy as np
from scipy.stats import binom

from gyrostand.config import LkfConfig
from gyrostand.core.data import Samples
from gyrostand.core.ml.fit import ml
from gyrostand.core.model import Model
from gyrostand.core.profiles import TemperatureProfile, chamber_profile, paper_profile
from gyrostand.core.simulation import simulate
from gyrostand.session.online import LkfTrack

CASES = {"C1": (0.0333, -0.01), "C2": (0.0333, -0.001), "C3": (0.00055, -0.001)}
SIGMA = 0.1
WARMUP = 300
CHECK_EVERY = 100
#: checkpoints where ML's band on the record so far is checked too (the early ones)
ML_CHECKS = (400, 500)
PAPER_MODEL = Model.parse("markov,temp")
CHAMBER_MODEL = Model.parse("markov,temp,bias,white,temp_rate")
CHAMBER_TRUTH = {"markov.beta": 1 / 600, "markov.sigma": 0.05, "temp.gamma": 2e-5,
                 "white.sigma": 0.02, "bias.b": 0.3, "temp_rate.k": 20.0}
CHAMBER_PROFILE = TemperatureProfile.from_breakpoints(
    [(0, 20), (3600, 50), (7200, 50), (9000, 30), (12600, 30), (16200, 60), (18000, 60),
     (21600, 25)])
#: 1-h runs: (model, simulated truth's model, truth, temperature profile)
HOUR = {
    # gyro x of configs/three-gyros.yaml: 20 -> 60 degC in 30 min, then a soak
    "three-gyro x": ("markov,temp,bias", "markov,temp,bias,white",
                     {"markov.beta": 0.002, "markov.sigma": 0.05, "temp.gamma": -0.0001,
                      "bias.b": 0.3, "white.sigma": 0.01},
                     TemperatureProfile.from_breakpoints([(0, 20), (1800, 60), (3600, 60)])),
    # the hidden-effect tests' gyro on the first hour of the chamber cycle
    "chamber 1 h": ("markov,temp,bias,white", "markov,temp,bias,white",
                    {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
                     "white.sigma": 0.02, "bias.b": 0.3}, chamber_profile(1.0)),
    # the paper's C2 scenario held at 35 degC to the hour
    "paper C2 1 h": ("markov,temp", "markov,temp,white",
                     {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.001,
                      "white.sigma": 0.05},
                     TemperatureProfile.from_breakpoints([(0, 20), (500, 45), (1000, 45),
                                                          (2000, 35), (3600, 35)])),
}
OK_COVER = 0.98
#: a checkpoint's coverage among ok is below OK_COVER beyond chance at this binomial p
BINOM_ALPHA = 0.01


def online_run(model: Model, samples, checkpoints=()):
    """The daemon's online LKF over ``samples``: estimates at ``checkpoints`` (bin
    counts) and at stop, as ``{name: (value, std)}``; also the tracker."""
    track = LkfTrack(model, LkfConfig(), samples.dt)
    at = {}
    cps = set(checkpoints)
    for k, (y, T) in enumerate(zip(samples.drift, samples.temp, strict=True), start=1):
        track.update(float(y), float(T))
        if k in cps and track.filter is not None:
            e = track.estimate()
            at[k] = (dict(e.values), e.status)
    track.finish()
    e = track.estimate()
    return at, (dict(e.values), e.status), track


def paper_task(task):
    case, sv, seed = task
    beta, gamma = CASES[case]
    truth = {"markov.beta": beta, "markov.sigma": SIGMA, "temp.gamma": gamma,
             "white.sigma": sv}
    s = simulate(PAPER_MODEL, truth, paper_profile(), seed=seed)
    cps = list(range(WARMUP + CHECK_EVERY, len(s) + 1, CHECK_EVERY))
    at, (final, status), _ = online_run(PAPER_MODEL, s, cps)
    r = ml(s, PAPER_MODEL)
    names = ("markov.beta", "temp.gamma")
    ml_cover = {}
    for k in ML_CHECKS:  # ML's own ±3 std band on the first k bins, for comparison
        rk = ml(Samples.from_arrays(s.t[:k], s.drift[:k], s.temp[:k], dt=s.dt,
                                    source="prefix"), PAPER_MODEL)
        ml_cover[k] = {n: abs(rk.value(n) - truth[n]) <= 3 * rk.std(n) for n in names}
    return {"case": case, "sv": sv, "ml_cover": ml_cover,
            "lkf": {n: final[n] for n in names}, "status": status,
            "ml": {n: (r.value(n), r.std(n)) for n in names},
            "cover": {k: {n: abs(v[0][n][0] - truth[n]) <= 3 * v[0][n][1] for n in names}
                      for k, v in at.items()},
            "ok_at": {k: v[1] == "ok" for k, v in at.items()}}


def chamber_task(seed):
    s = simulate(CHAMBER_MODEL, CHAMBER_TRUTH, CHAMBER_PROFILE, seed=seed)
    cps = list(range(WARMUP + CHECK_EVERY, len(s) + 1, CHECK_EVERY))
    at, (final, status), _ = online_run(CHAMBER_MODEL, s, cps)
    r = ml(s, CHAMBER_MODEL)
    lin = ("markov.beta",) + CHAMBER_MODEL.names_of_kind("linear")
    return {"lkf": {n: final[n] for n in lin}, "status": status,
            "ml": {n: (r.value(n), r.std(n)) for n in lin},
            "at": {k: (v[1] == "ok", {n: abs(v[0][n][0] - CHAMBER_TRUTH[n]) <= 3 * v[0][n][1]
                                      for n in lin}) for k, v in at.items()}}


def hour_task(task):
    """One 1-h run of a ``HOUR`` scenario: per checkpoint (ok?, covered per coefficient),
    the status at stop and whether ML on the hour calls the likelihood flat."""
    name, seed = task
    mstr, tstr, truth, prof = HOUR[name]
    model = Model.parse(mstr)
    s = simulate(Model.parse(tstr), truth, prof, duration=3600.0, seed=seed)
    cps = list(range(WARMUP + CHECK_EVERY, len(s) + 1, CHECK_EVERY))
    at, (final, status), _ = online_run(model, s, cps)
    est = ("markov.beta",) + model.names_of_kind("linear")
    r = ml(s, model)
    return {"name": name, "status": status,
            "flat": any("likelihood is flat" in w for w in r.warnings),
            "ml_z": {n: (r.values[n] - truth[n]) / r.std(n) if r.std(n) > 0 else math.inf
                     for n in est},
            "at": {k: (v[1] == "ok", {n: abs(v[0][n][0] - truth[n]) <= 3 * v[0][n][1]
                                      for n in est}) for k, v in at.items()}}


def ok_coverage(ats):
    """Per checkpoint of ``ats`` (one ``{k: (ok, {name: covered})}`` per run): (runs ok,
    the smallest coverage over the coefficients among them, its coefficient)."""
    out = {}
    for k in sorted(ats[0]):
        oks = [a[k][1] for a in ats if a[k][0]]
        if not oks:
            out[k] = (0, math.nan, "")
            continue
        cov = {n: float(np.mean([c[n] for c in oks])) for n in oks[0]}
        worst = min(cov, key=cov.get)
        out[k] = (len(oks), cov[worst], worst)
    return out


#: checkpoints with at least this many ``ok`` runs get their own minimum in the summary
MANY_OK = 20


def ok_summary(cov, ats) -> tuple[str, bool]:
    """The worst checkpoint of :func:`ok_coverage`'s output ``cov`` (and the worst among
    those with at least ``MANY_OK`` runs ok), the coverage pooled over every ``ok`` run
    and checkpoint of ``ats``, and whether the bands meet ``OK_COVER``.

    The target (issue 24 item 6: ±3σ coverage ≥ 0.98 at every checkpoint among ok, for
    every coefficient) is judged as a test can judge it: no checkpoint's coverage of any
    coefficient below ``OK_COVER`` beyond chance (one-sided binomial, p < ``BINOM_ALPHA``
    at each checkpoint, no correction for the many checkpoints: the stricter way), and
    each coefficient's coverage pooled over every ok run-checkpoint at least ``OK_COVER``.
    The smallest point estimate at a checkpoint is printed but not the verdict: at a
    checkpoint with 15 runs ok one miss reads 0.933, and a band of exactly 0.99 misses
    there with probability 0.14 (0.12 for two misses among 60) — over ~100 checkpoints
    the minimum of the point estimates fails a calibrated band (session 23)."""
    have = {k: v for k, v in cov.items() if v[0]}
    if not have:
        return "no ok status at any checkpoint", True
    k = min(have, key=lambda j: (have[j][1], -have[j][0]))
    n, c, name = have[k]
    many = {j: v for j, v in have.items() if v[0] >= MANY_OK}
    txt = f"min {c:.3f} ({name}, {n} ok) @{k}"
    if many:
        j = min(many, key=lambda i: (many[i][1], -many[i][0]))
        txt += f", with >= {MANY_OK} ok {many[j][1]:.3f} ({many[j][2]}, {many[j][0]} ok) @{j}"
    at_ok = [v[1] for a in ats for v in a.values() if v[0]]  # {coefficient: covered}
    oks = [c for cov_k in at_ok for c in cov_k.values()]
    pooled = [all(cov_k.values()) for cov_k in at_ok]
    txt += (f"; pooled over {len(pooled)} ok run-checkpoints: every coefficient covered "
            f"{np.mean(pooled):.4f}, per coefficient {np.mean(oks):.4f}; first ok @{min(have)}")
    # where the misses come from, and which checkpoints fall short of OK_COVER beyond
    # chance: with n runs ok a band of exactly OK_COVER misses once in 20 ok runs with
    # probability 0.33, so one miss among few ok runs says little about calibration
    missing = sorted({i for i, a in enumerate(ats) for v in a.values()
                      if v[0] and not all(v[1].values())})
    short = [k for k, (n, c, _) in have.items()
             if binom.sf(round(n * (1 - c)) - 1, n, 1 - OK_COVER) < BINOM_ALPHA]
    txt += (f"; the misses among ok come from {len(missing)} run(s) (#{', #'.join(map(str, missing))})"
            if missing else "; no miss among ok")
    txt += (f"; checkpoints below {OK_COVER} beyond chance (one-sided binomial p < {BINOM_ALPHA}): "
            f"{len(short)} of {len(have)}" + (f" (@{', @'.join(map(str, short))})" if short else ""))
    # each coefficient's band, pooled over every ok run-checkpoint
    each = {n: float(np.mean([cov_k[n] for cov_k in at_ok])) for n in at_ok[0]}
    txt += "; pooled by coefficient " + ", ".join(f"{n} {c:.4f}" for n, c in each.items())
    return txt, not short and min(each.values()) >= OK_COVER


def cells(ats, runs, per_line=9, indent="      "):
    """Lines of ``s:ok fraction/smallest coverage among ok over the coefficients`` at every
    checkpoint of ``ats`` (``runs`` runs)."""
    out = []
    cs = [f"{k}:{n / runs:.2f}/{c:.2f}" if n else f"{k}:0"
          for k, (n, c, _) in ok_coverage(ats).items()]
    for i in range(0, len(cs), per_line):
        out.append(indent + "  ".join(cs[i: i + per_line]))
    return out


def hour_table(recs):
    out = []
    passed = True
    for name in HOUR:
        rr = [r for r in recs if r["name"] == name]
        if not rr:
            continue
        ats = [r["at"] for r in rr]
        summ, ok = ok_summary(ok_coverage(ats), ats)
        flat_ok = sum(r["flat"] and r["status"] == "ok" for r in rr)
        passed &= ok and flat_ok == 0
        st = [r["status"] for r in rr]
        out.append(f"  {name} ({HOUR[name][0]}; {len(rr)} runs): coverage among ok {summ}; "
                   f"status at stop ok/warning/failed {st.count('ok')}/{st.count('warning')}/"
                   f"{st.count('failed')}; ML flat {sum(r['flat'] for r in rr)}, of them "
                   f"ok {flat_ok}" + ("" if ok and flat_ok == 0 else "  <-- target missed"))
        out.append("      ML on the hour, +-3 std coverage / RMS of (estimate - truth) / std: " +
                   ", ".join(f"{n} {np.mean([abs(r['ml_z'][n]) <= 3 for r in rr]):.2f}/"
                             f"{math.sqrt(np.mean([r['ml_z'][n] ** 2 for r in rr])):.2f}"
                             for n in rr[0]["ml_z"]))
        out += cells(ats, len(rr))
    return "\n".join(out), passed


def stats(vals, true):
    e = (np.asarray(vals) - true) / abs(true) * 100
    return float(np.sqrt(np.mean(e * e))), float(np.mean(e))


def paper_table(recs):
    head = ("case", "σv", "param", "LKF RMSE%", "ML RMSE%", "ratio", "LKF bias%", "ML bias%",
            "min cover", "ML cover", "ok cover", "spread/std (ML)", "ok/warn/fail")
    rows = []
    passed = True
    for case in CASES:
        beta, gamma = CASES[case]
        for sv in (0.0, SIGMA / 2):
            rr = [r for r in recs if r["case"] == case and r["sv"] == sv]
            if not rr:
                continue
            st = [r["status"] for r in rr]
            counts = f"{st.count('ok')}/{st.count('warning')}/{st.count('failed')}"
            for n, true in (("markov.beta", beta), ("temp.gamma", gamma)):
                lv = [r["lkf"][n][0] for r in rr]
                ls = [r["lkf"][n][1] for r in rr]
                mv = [r["ml"][n][0] for r in rr]
                lr, lb = stats(lv, true)
                mr, mb = stats(mv, true)
                cps = sorted(rr[0]["cover"])
                cov = [float(np.mean([r["cover"][k][n] for r in rr])) for k in cps]
                worst = cps[int(np.argmin(cov))]
                spread = float(np.std(lv) / np.mean(ls))
                mls = float(np.std(mv) / np.mean([r["ml"][n][1] for r in rr]))
                mlc = min(float(np.mean([r["ml_cover"][k][n] for r in rr])) for k in ML_CHECKS)
                ats_n = [{k: (r["ok_at"][k], {n: r["cover"][k][n]}) for k in cps}
                         for r in rr]
                okc = ok_coverage(ats_n)
                have = [(v[1], k, v[0]) for k, v in okc.items() if v[0]]
                oc = min(have) if have else (math.nan, 0, 0)
                lim = 1.2 if case == "C3" else 1.1
                # the band among ok judged as tables 2 and 3 judge it (ok_summary: no
                # checkpoint below OK_COVER beyond chance, pooled >= OK_COVER); the
                # smallest point estimate is printed (session 25: this table still failed
                # C2 σv 0.05 on 2 misses among 14 ok at 400 s, binomial p 0.03)
                ok = (lr <= lim * mr and abs(lb - mb) <= 2.0 and min(cov) >= 0.98
                      and 0.9 <= spread <= 1.15 and ok_summary(okc, ats_n)[1])
                passed &= ok
                rows.append((case, f"{sv:g}", n, f"{lr:.2f}", f"{mr:.2f}", f"{lr / mr:.3f}",
                             f"{lb:+.2f}", f"{mb:+.2f}", f"{min(cov):.3f} @{worst}",
                             f"{mlc:.3f}", f"{oc[0]:.3f} @{oc[1]} ({oc[2]} ok)",
                             f"{spread:.3f} ({mls:.3f})",
                             counts + ("" if ok else "  <-- target missed")))
    lines = []
    for case in CASES:
        for sv in (0.0, SIGMA / 2):
            rr = [r for r in recs if r["case"] == case and r["sv"] == sv]
            if rr:
                ats = [{k: (r["ok_at"][k], r["cover"][k]) for k in r["cover"]} for r in rr]
                lines.append(f"  {case} σv={sv:g}: s:ok fraction/smallest coverage among ok over β, γ")
                lines += cells(ats, len(rr))
    return _fmt(head, rows) + "\n" + "\n".join(lines), passed


def chamber_table(recs):
    head = ("param", "truth", "LKF RMSE%", "ML RMSE%", "ratio", "LKF bias%", "ML bias%")
    rows = []
    passed = True
    for n, true in CHAMBER_TRUTH.items():
        if n not in recs[0]["lkf"]:
            continue
        lr, lb = stats([r["lkf"][n][0] for r in recs], true)
        mr, mb = stats([r["ml"][n][0] for r in recs], true)
        passed &= lr <= 1.2 * mr
        rows.append((n, f"{true:g}", f"{lr:.2f}", f"{mr:.2f}", f"{lr / mr:.3f}",
                     f"{lb:+.2f}", f"{mb:+.2f}"))
    st = [r["status"] for r in recs]
    ats = [r["at"] for r in recs]
    summ, ok = ok_summary(ok_coverage(ats), ats)
    passed &= ok
    return _fmt(head, rows) + (f"\n  status at stop ok/warning/failed: {st.count('ok')}/"
                               f"{st.count('warning')}/{st.count('failed')}"
                               f"\n  coverage among ok at the 100-s checkpoints: {summ}"
                               + ("" if ok else "  <-- target missed")
                               + "\n  per checkpoint s:ok fraction/smallest coverage among ok over the coefficients\n"
                               + "\n".join(cells(ats, len(recs), 10, "    "))), passed


def cost(hours: float = 24.0):
    prof = TemperatureProfile.from_breakpoints(
        [(0, 20), (3 * 3600, 50), (6 * 3600, 50), (9 * 3600, 30), (12 * 3600, 30),
         (15 * 3600, 60), (18 * 3600, 60), (hours * 3600, 25)])
    truth = {"markov.beta": 1 / 600, "markov.sigma": 0.05, "temp.gamma": 2e-5,
             "white.sigma": 0.02}
    s = simulate(PAPER_MODEL, truth, prof, duration=hours * 3600, seed=7)
    online_run(PAPER_MODEL, simulate(PAPER_MODEL, truth, paper_profile(), seed=1))  # JIT
    t = time.perf_counter()
    _, _, track = online_run(PAPER_MODEL, s)
    el = time.perf_counter() - t
    f = track.filter
    return len(s), el, f.relinearizations, f.total_passes


def _fmt(head, rows):
    w = [max(len(str(x)) for x in col) for col in zip(head, *rows, strict=True)]
    line = "  " + "  ".join(h.ljust(a) for h, a in zip(head, w, strict=True))
    out = [line, "  " + "-" * (len(line) - 2)]
    out += ["  " + "  ".join(str(x).ljust(a) for x, a in zip(r, w, strict=True)) for r in rows]
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--chamber-runs", type=int, default=40)
    ap.add_argument("--hour-runs", type=int, default=100)
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--cases", default="C1,C2,C3")
    ap.add_argument("--skip", default="", help="comma list of: paper, chamber, hour, cost")
    a = ap.parse_args()
    skip = set(a.skip.split(","))
    load = os.getloadavg()[0]
    print(f"lkf_accuracy: {a.runs} runs per cell, {a.chamber_runs} chamber runs, "
          f"{a.jobs} jobs, load average {load:.2f} on {os.cpu_count()} CPUs")
    ctx = mp.get_context("fork")
    ok_all = True
    with ctx.Pool(a.jobs) as pool:
        if "paper" not in skip:
            tasks = [(c, sv, 1000 * i + j) for c in a.cases.split(",") for j, sv in
                     enumerate((0.0, SIGMA / 2)) for i in range(a.runs)]
            t = time.perf_counter()
            recs = pool.map(paper_task, tasks, chunksize=4)
            txt, ok = paper_table(recs)
            ok_all &= ok
            print(f"\n1. paper scenario, online LKF at stop vs ML ({time.perf_counter() - t:.0f} s)"
                  f"\n   cover = fraction of runs whose +-3 std band holds the truth, minimum "
                  f"over the checkpoints {WARMUP + CHECK_EVERY}, {WARMUP + 2 * CHECK_EVERY}, "
                  f"... s; ML cover: ML's own band on the first "
                  f"{', '.join(map(str, ML_CHECKS))} s (minimum)\n{txt}")
        if "chamber" not in skip:
            t = time.perf_counter()
            recs = pool.map(chamber_task, range(a.chamber_runs), chunksize=2)
            txt, ok = chamber_table(recs)
            ok_all &= ok
            print(f"\n2. 6-h chamber run, {CHAMBER_MODEL} ({time.perf_counter() - t:.0f} s)"
                  f"\n{txt}")
        if "hour" not in skip:
            t = time.perf_counter()
            recs = pool.map(hour_task, [(nm, 5000 + i) for nm in HOUR
                                        for i in range(a.hour_runs)], chunksize=2)
            txt, ok = hour_table(recs)
            ok_all &= ok
            print(f"\n3. 1-h runs ({time.perf_counter() - t:.0f} s): per checkpoint "
                  f"s:fraction of runs ok/smallest coverage among them over the coefficients "
                  f"(target >= {OK_COVER})\n{txt}")
    if "cost" not in skip:
        n, el, relins, passes = cost()
        per = el / n * 1e3
        ok_all &= per <= 0.3
        print(f"\n4. cost: {n} bins (24 h) in {el:.2f} s = {per:.3f} ms per bin "
              f"(target 0.3 ms: ratio {per / 0.3:.2f}); {relins} re-linearisations, "
              f"{passes} passes ({passes / max(relins, 1):.1f} per re-linearisation)")
    print(f"\nall targets met: {ok_all}" + ("" if math.isfinite(load) else ""))


if __name__ == "__main__":
    main()
