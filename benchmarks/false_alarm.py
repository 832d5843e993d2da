"""Monte Carlo: how often ``diagnose`` calls a clean run NOT ADEQUATE (false-alarm rate).

Each run is a seeded 6-hour chamber cycle (the project's standard run; ``HOURS`` sets it) built from frames the way a real log arrives
(tests/workbench/framelike.py: 10-Hz drift and temperature frames with jitter, 1 % drops,
a log that starts and ends inside a bin, 0.05-degC quantized temperature), whose drift
follows the configured model ``markov,temp,bias`` exactly. The verdict's nominal level:
5 % for the candidates (Bonferroni) plus 1 % for the Ljung–Box whiteness test plus 1 % for
the open-loop error's floor check, so at most ~7 % by construction; the issue's target is
≤ 5 %. Prints the rate with its 95 % Clopper–Pearson interval, which parts raised the
alarms, and the time per run.

Run: ``.venv/bin/python benchmarks/false_alarm.py [N_RUNS [HOURS]]`` (default 100, 6)
"""

from __future__ import annotations

import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from scipy.stats import beta

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gyrostand.core.profiles import chamber_profile  # noqa: E402
from gyrostand.workbench import open_subject, run_diagnose  # noqa: E402
from tests.workbench.framelike import frame_run  # noqa: E402

NOMINAL = 0.05
TARGET = 0.05


#: record length (h); the issue's figure is at 6 h and at 2 h (``HOURS`` argument). Short
#: records stretch the supremum over a candidate's shape: with the shapes counted in
#: χ²(df), hysteresis's LR averaged ~3.9 on 2-h cycles against χ²(3)'s 3 and the 2-h
#: false-alarm rate was 7/100; the calibrated test (the supremum of a χ² process over the
#: shape, gyrostand.core.diagnose.candidates) refers it to its own tail
HOURS = 6.0


def false_alarms(n_runs: int, first_seed: int = 1000, hours: float = HOURS,
                 progress: bool = False, lrs: dict[str, list[tuple]] | None = None,
                 shifts: list[tuple[float, float]] | None = None,
                 lines: list[tuple[float, float]] | None = None):
    """(alarms, reasons Counter, seconds per run) over ``n_runs`` clean runs; ``lrs``, when
    given, collects each candidate's (LR, df, p, test) per run (under the null p is
    uniform: P(p < a) = a); ``shifts`` the level shift's (score, p) per run, ``lines`` the
    periodic line's (Fisher's g, p)."""
    alarms = 0
    why: Counter[str] = Counter()
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(n_runs):
            path = frame_run(Path(tmp) / f"clean{i}.csv", seed=first_seed + i, drop=0.01,
                             start_offset=0.37 + 0.5 * (i % 2), end_cut=0.4,
                             profile=chamber_profile(hours))
            rep = run_diagnose(open_subject(path), record=False)
            if lrs is not None:
                for c in rep.candidates:
                    lrs.setdefault(c.term, []).append((c.lr_stat, c.df, c.p_value,
                                                       c.test))
            if shifts is not None and rep.level_shift is not None:
                shifts.append((rep.level_shift.stat, rep.level_shift.p_value))
            if lines is not None and rep.periodic is not None:
                lines.append((rep.periodic.g, rep.periodic.p_value))
            if not rep.adequate:
                alarms += 1
                for r in rep.reasons:
                    why[r.split(" (")[0].split(" significant")[0][:60]] += 1
            if progress and (i + 1) % 10 == 0:
                means = "".join(f", {t} mean LR {sum(x[0] for x in v) / len(v):.2f} "
                                f"(df {v[0][1]}, {v[0][3]})" for t, v in (lrs or {}).items()
                                if t in ("hysteresis", "temp_rate"))
                print(f"  after {i + 1} runs: {alarms} false alarms{means}", flush=True)
    return alarms, why, (time.perf_counter() - t0) / max(n_runs, 1)


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    a = (1 - level) / 2
    lo = float(beta.ppf(a, k, n - k + 1)) if k else 0.0
    hi = float(beta.ppf(1 - a, k + 1, n - k)) if k < n else 1.0
    return lo, hi


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 100
    hours = float(sys.argv[2]) if len(sys.argv) > 2 else HOURS
    lrs: dict[str, list[tuple]] = {}
    shifts: list[tuple[float, float]] = []
    lines: list[tuple[float, float]] = []
    k, why, per = false_alarms(n, hours=hours, progress=True, lrs=lrs, shifts=shifts,
                               lines=lines)
    lo, hi = clopper_pearson(k, n)
    print(f"clean runs: {n} ({hours:g}-h chamber cycles from frames), false alarms: {k} = "
          f"{100 * k / n:.1f} % (95 % CI {100 * lo:.1f}–{100 * hi:.1f} %), nominal level of "
          f"the candidate tests {100 * NOMINAL:.0f} %, target ≤ {100 * TARGET:.0f} % "
          f"({'PASS' if k / n <= TARGET else 'MISS'})")
    for reason, c in why.most_common():
        print(f"    {c:3d} x {reason}")
    m = max(len(lrs), 1)
    print(f"each candidate's test on the clean runs (under the null P(p < a) = a; "
          f"significant: p < 0.05/{m}):")
    for term, v in lrs.items():
        lr = [x[0] for x in v]
        p = [x[2] for x in v]
        print(f"    {term:<12} mean LR {sum(lr) / len(lr):5.2f}  df {v[0][1]}  "
              f"max {max(lr):6.2f}  p < 0.05: {sum(x < 0.05 for x in p):3d}/{len(p)}  "
              f"p < 0.05/{m}: {sum(x < 0.05 / m for x in p):2d}  ({v[0][3]})")
    if shifts:
        print(f"    level shift  max score {max(x[0] for x in shifts):5.1f} (Bonferroni over "
              f"the break times)  p < 0.05: {sum(x[1] < 0.05 for x in shifts):3d}/"
              f"{len(shifts)}  p < 0.001 (the verdict's): "
              f"{sum(x[1] < 0.001 for x in shifts)}")
    if lines:
        print(f"    periodic     min p {min(x[1] for x in lines):.2g} (Fisher's g)  p < 0.05: "
              f"{sum(x[1] < 0.05 for x in lines):3d}/{len(lines)}  p < 0.001 (the "
              f"verdict's): {sum(x[1] < 0.001 for x in lines)}")
    print(f"{per:.2f} s per run (diagnose with every candidate)")


if __name__ == "__main__":
    main()
