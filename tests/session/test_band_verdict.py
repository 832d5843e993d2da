"""The rule benchmarks/lkf_accuracy.py judges the online band's coverage among `ok` by
(issue 24 item 6): no checkpoint's coverage of any coefficient below 0.98 beyond chance,
and each coefficient's coverage pooled over the ok run-checkpoints at least 0.98. It must
pass a band that covers as it says and fail one that does not, on records shaped as the
benchmark's (one ``{checkpoint: (ok, {coefficient: covered})}`` per run)."""

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def _rule():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from lkf_accuracy import ok_coverage, ok_summary
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    return ok_coverage, ok_summary


def _records(runs, cover, seed, ok_from=5, checkpoints=30, names=("beta", "gamma", "b")):
    """``runs`` runs, ok from checkpoint ``ok_from`` on; each coefficient's band holds the
    truth with probability ``cover`` at each ok checkpoint, a run's misses persisting (a
    run off at one checkpoint is off at the next few: real runs miss that way)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(runs):
        off = {n: rng.random() > cover for n in names}
        rec = {}
        for k in range(checkpoints):
            if rng.random() < 0.2:  # a new draw now and then, else the same state
                off = {n: rng.random() > cover for n in names}
            rec[100 * (k + 1)] = (k >= ok_from, {n: not off[n] for n in names})
        out.append(rec)
    return out


def test_a_calibrated_band_passes_though_one_checkpoint_reads_below_target():
    ok_coverage, ok_summary = _rule()
    ats = _records(100, 0.995, seed=1)
    # a checkpoint where few runs say ok and one of them misses: 1 of 15 = 0.933
    for i, a in enumerate(ats):
        a[500] = (i < 15, {"beta": i != 3, "gamma": True, "b": True})
    txt, ok = ok_summary(ok_coverage(ats), ats)
    assert "min 0.933 (beta, 15 ok) @500" in txt, txt
    assert ok, txt


def test_a_band_that_covers_095_fails():
    ok_coverage, ok_summary = _rule()
    ats = _records(100, 0.95, seed=2)
    txt, ok = ok_summary(ok_coverage(ats), ats)
    assert not ok, txt


def test_one_coefficient_below_target_pooled_fails_though_no_checkpoint_is_short():
    """Pooled 0.97 on one coefficient (3 runs in 100 off at every ok checkpoint): each
    checkpoint's 3 misses among 100 are not beyond chance at 0.98, the pool is."""
    ok_coverage, ok_summary = _rule()
    ats = _records(100, 1.0, seed=3)
    for i in (10, 40, 70):
        for k, (ok, cov) in ats[i].items():
            ats[i][k] = (ok, {**cov, "gamma": False})
    txt, ok = ok_summary(ok_coverage(ats), ats)
    assert "checkpoints below 0.98 beyond chance (one-sided binomial p < 0.01): 0 of" in txt
    assert "gamma 0.9700" in txt, txt
    assert not ok, txt
