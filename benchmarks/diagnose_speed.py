"""Benchmark: ``diagnose`` with every candidate on a 6-hour run (21,600 one-second samples).

Anchor (issue 4): the whole diagnosis — the ML fit of the current model, the residual
diagnostics, the saturated reference (issue 23) and a refit with each of the vocabulary's
candidate terms — under 10 s on this
machine. Prints the time of each part, each candidate's fit, and the ratio to the anchor.
The data hide a ``temp_rate`` effect so that the ranking has something to find.

Also (issue 25 item 2): the candidates with the score screen and without (``--no-screen``)
side by side, by CPU time of the process's threads; and the whole commands ``gyrostand
diagnose`` (screened and ``--no-screen``) against ``gyrostand identify --method ml`` on
the same 6-h CSV, by the CPU time of each child process (the acceptance: diagnose's CPU
<= 2.5 x identify's).

Run: ``.venv/bin/python benchmarks/diagnose_speed.py [--commands-only] [--before TREE]
[--rounds N]`` (``--commands-only``: the whole commands alone; ``--before TREE``: each
command also run from another checkout, e.g. ``git worktree add --detach ../before REV``,
pair by pair in the same rounds, so that both ratios are measured under the same load;
``--rounds``: how many rounds the best is taken of, default 2, 3 with ``--before``: on a
shared machine a command's CPU varies by 10-20 % from one run to the next — the same
diagnose read 3.84 and 4.47 s in one round of two — and more rounds steady the figure)
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from gyrostand.core.data import Samples
from gyrostand.core.diagnose.candidates import rank_candidates
from gyrostand.core.diagnose.diagnostics import diagnose_fit
from gyrostand.core.diagnose.reference import reference_fit, second_start
from gyrostand.core.diagnose.verdict import diagnose, fit_error
from gyrostand.core.ml.fit import ml
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate

ANCHOR_S = 10.0
#: the gyro (a clean run ignores temp_rate.k)
TRUTH = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
         "white.sigma": 0.02, "bias.b": 0.3, "temp_rate.k": 5.0}


ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    before = Path(sys.argv[sys.argv.index("--before") + 1]).resolve() \
        if "--before" in sys.argv else None
    rounds = int(sys.argv[sys.argv.index("--rounds") + 1]) if "--rounds" in sys.argv \
        else None
    if "--commands-only" in sys.argv:
        commands(data(), before, rounds)
        return
    s = data()
    m = Model.parse("markov,temp,bias")
    ml(s, m)  # warm-up: numba's compiled kernels are loaded from cache once per process
    stages(s, m)
    commands(s, before, rounds)


def data() -> Samples:
    """The 6-h run with a hidden temp_rate effect, its sensor quantised."""
    s = simulate(Model.parse("markov,temp,bias,temp_rate"), TRUTH, chamber_profile(6.0),
                 seed=1)
    rng = np.random.default_rng(2)
    temp = np.round((s.temp + 0.01 * rng.standard_normal(len(s))) / 0.05) * 0.05
    return Samples.from_arrays(s.t, s.drift, temp)


def stages(s: Samples, m: Model) -> None:
    """Each stage in process, the candidates with and without the screen."""
    print(f"data: {len(s)} samples (6-h chamber cycle), hidden temp_rate; model {m}; "
          f"load average {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    t0 = time.perf_counter()
    fit = ml(s, m)
    t1 = time.perf_counter()
    diag = diagnose_fit(fit, s)
    t2 = time.perf_counter()
    ref = reference_fit(s, m, fit)
    tr = time.perf_counter()
    cands = rank_candidates(s, m, fit, screen=False)
    t3 = time.perf_counter()
    err = fit_error(fit, s, reference=ref)
    t4 = time.perf_counter()
    total = t4 - t0
    print(f"ML fit of the current model   {t1 - t0:7.2f} s")
    print(f"residual diagnostics          {t2 - t1:7.2f} s  (Ljung-Box p {diag.ljung_box_p:.3g})")
    print(f"model error and its floor     {t4 - t3:7.2f} s  (open loop {err.rms:.4g}, floor "
          f"{err.floor:.4g})")
    print(f"saturated reference           {tr - t2:7.2f} s  (lack of fit LR {ref.lr:.1f} on "
          f"{ref.df} df, p {ref.p_value:.2g})")
    print(f"candidate refits ({len(cands)})         {t3 - tr:7.2f} s")
    for c in sorted(cands, key=lambda c: -c.seconds):
        print(f"    {c.term:<12} {c.seconds:6.2f} s   LR {c.lr_stat:8.2f}  p {c.p_value:.2g}")
    print(f"ranked first: {cands[0].term}")
    side_by_side(s, m, fit, "hidden temp_rate")
    clean = simulate(Model.parse("markov,temp,bias"), TRUTH, chamber_profile(6.0), seed=3)
    clean = Samples.from_arrays(clean.t, clean.drift, np.round(clean.temp / 0.05) * 0.05)
    cfit = ml(clean, m)
    side_by_side(clean, m, cfit, "clean 6-h run")
    t5 = time.perf_counter()
    rep = diagnose(s, m, base=fit)
    print(f"whole diagnose() from the fit (candidates, identification, competitors, model "
          f"error): {time.perf_counter() - t5:.2f} s; proposed first: "
          f"{rep.significant[0].term if rep.significant else 'nothing'}")
    print(f"total diagnose {total:.2f} s = {total / ANCHOR_S:.2f} x the {ANCHOR_S:.0f}-s anchor "
          f"({'PASS' if total < ANCHOR_S else 'MISS'}); "
          f"mean per candidate {(t3 - tr) / len(cands):.2f} s")


def side_by_side(s: Samples, m: Model, fit, what: str) -> None:
    """Candidates with and without the score screen, CPU seconds of all threads, started
    also from the reference's random part where it shows a lack of fit (as diagnose:
    then nothing is screened)."""
    ref = reference_fit(s, m, fit)
    also = second_start(ref)
    print(f"{what}: reference lack of fit p {ref.p_value:.2g}"
          f"{' (screen off)' if also else ''}")
    for screen in (False, True, False, True):
        c0, w0 = time.process_time(), time.perf_counter()
        cands = rank_candidates(s, m, fit, also=also, screen=screen)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        out = [c.term for c in cands if c.screened]
        print(f"  candidates {'screened ' if screen else '--no-screen'}  CPU {cpu:6.2f} s  wall "
              f"{wall:6.2f} s  refitted {len(cands) - len(out)}, screened out "
              f"{', '.join(out) or 'none'}; first {cands[0].term}")


def child_cpu(cmd: list[str], tree: Path = ROOT) -> float:
    """CPU seconds (user + system) of one child process run to its end, its ``gyrostand``
    the one of ``tree`` (``-m`` imports its working folder's package first)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   cwd=tree, env=dict(os.environ, PYTHONPATH=str(tree)))
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def commands(s: Samples, before: Path | None = None, rounds: int | None = None) -> None:
    """diagnose ÷ identify --method ml, CPU of whole processes on the same 6-h CSV, the
    best of ``rounds``; with ``before``, the same commands of that checkout in the same
    rounds."""
    gyro = [sys.executable, "-m", "gyrostand"]
    trees = {"": ROOT} if before is None else {"": ROOT, "before: ": before}
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "run6h.csv"
        s.to_csv(csv)
        ident = gyro + ["identify", str(csv), "--method", "ml", "--json"]
        diag = gyro + ["diagnose", str(csv), "--model", "markov,temp,bias"]
        rows = {"identify --method ml": ident, "diagnose --no-screen":
                diag + ["--no-screen"], "diagnose": diag}
        for tree in trees.values():  # warm: numba's cache, every kernel diagnose uses
            child_cpu(ident, tree)
            child_cpu(diag, tree)
        cpu: dict[tuple[str, str], list[float]] = {}
        for _ in range(rounds or (2 if before is None else 3)):
            for k, cmd in rows.items():
                for label, tree in trees.items():
                    cpu.setdefault((label, k), []).append(child_cpu(cmd, tree))
        for label, tree in trees.items():
            best = {k: min(cpu[(label, k)]) for k in rows}
            n = len(cpu[(label, "diagnose")])
            print(f"{label}{tree} ({_commit(tree)}); load average "
                  f"{', '.join(f'{x:.2f}' for x in os.getloadavg())}")
            for k, v in best.items():
                print(f"  {k:<22} CPU {v:6.2f} s (best of {n})  = "
                      f"{v / best['identify --method ml']:.2f} x identify")
            r = best["diagnose"] / best["identify --method ml"]
            print(f"{label}diagnose CPU / identify --method ml CPU = {r:.2f} (acceptance <= "
                  f"2.5: {'PASS' if r <= 2.5 else 'MISS'}); --no-screen "
                  f"{best['diagnose --no-screen'] / best['identify --method ml']:.2f}")


def _commit(tree: Path) -> str:
    """The checkout's commit (and '+ changes' when its tree differs from it)."""
    git = ["git", "-C", str(tree)]
    rev = subprocess.run(git + ["rev-parse", "--short", "HEAD"], capture_output=True,
                         text=True).stdout.strip() or "?"
    dirty = subprocess.run(git + ["status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True).stdout.strip()
    return rev + (" + changes" if dirty else "")


if __name__ == "__main__":
    main()
