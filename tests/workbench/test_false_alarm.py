"""Monte Carlo false-alarm rate of the verdict on clean runs (reduced; the full ≥ 100-run
figure comes from benchmarks/false_alarm.py, which shares this run recipe)."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_clean_runs_are_rarely_called_inadequate():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from false_alarm import clopper_pearson, false_alarms
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    n = 30
    k, why, per = false_alarms(n, first_seed=5000)
    lo, hi = clopper_pearson(k, n)
    print(f"false alarms {k}/{n} = {100 * k / n:.1f} % (95 % CI {100 * lo:.1f}–{100 * hi:.1f}"
          f" %; nominal 5 %), {dict(why)}, {per:.1f} s per run")
    # at a true rate of 5 %, 6 or more alarms in 30 runs has probability 1.6 %
    assert k <= 5
