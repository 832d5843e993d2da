"""``Binner.add_arrays`` (the array path's samples, as arrays) gives what ``add_many`` gives
for the same samples as tuples: the same bins (sums to the bit), counters and open state,
on streams with late samples, gaps, refused jumps, a rebase, a resumed series, several
gyros interleaved, batches cut anywhere, integer values and a grid set by the first
sample."""

from __future__ import annotations

import random

import numpy as np
import pytest

from gyrostand.can.binning import Binner


def _stream(rng: random.Random, n: int, gyros: int) -> list[tuple[int, int, float, float]]:
    out = []
    t = rng.uniform(-5.0, 1e5)
    for _ in range(n):
        r = rng.random()
        if r < 0.01:
            dt = -rng.uniform(0.5, 3.0)  # late (a bin already closed)
        elif r < 0.015:
            dt = rng.uniform(2.0, 8.0)  # gap bins
        elif r < 0.0165:
            dt = rng.uniform(15.0, 40.0)  # a jump beyond max_gap (refused until a rebase)
        else:
            dt = rng.expovariate(400.0)
        t += dt
        v: float = rng.gauss(0.0, 10.0) * 10 ** rng.uniform(-6, 6)
        if rng.random() < 0.05:
            v = float(rng.randint(-1000, 1000))
        out.append((rng.randrange(gyros), 0 if rng.random() < 0.9 else 1, t, v))
    return out


def _state(b: Binner):
    return (b.stats(), b.t0, [None if o is None else (o.k, o.s0, o.n0, o.s1, o.n1)
                              for o in b._open], list(b._floor), list(b._rebase))


@pytest.mark.parametrize("seed", range(12))
def test_add_arrays_equals_add_many(seed):
    rng = random.Random(seed)
    gyros = rng.choice([1, 2, 3])
    samples = _stream(rng, 6000, gyros)
    names = [f"g{i}" for i in range(gyros)]
    dt = rng.choice([1.0, 0.5, 0.1])
    epoch = rng.choice([None, 0.0, -3.25])
    max_gap = rng.choice([10.0, 10.0, 3600.0])
    a, b = Binner(names, dt, epoch, max_gap), Binner(names, dt, epoch, max_gap)
    if seed % 3 == 0:  # a resumed series
        for x in (a, b):
            x.resume_after(0.0 if epoch is None else epoch,
                           {"g0": int((samples[50][2] - (epoch or 0.0)) / dt)})
    got, want = [], []
    i = 0
    while i < len(samples):
        j = min(len(samples), i + rng.choice([1, 2, 7, 100, 1024, 3000]))
        part = samples[i:j]
        if rng.random() < 0.2:
            a.rebase()
            b.rebase()
        want += a.add_many(part)
        ints = rng.random() < 0.2 and all(float(v).is_integer() for _, _, _, v in part)
        g = np.array([s[0] for s in part], np.int64)
        c = np.array([s[1] for s in part], np.int64)
        t = np.array([s[2] for s in part])
        v = np.array([s[3] for s in part], np.int64 if ints else np.float64)
        got += b.add_arrays(g, c, t, v)
        assert _state(a) == _state(b)
        i = j
    assert repr(got) == repr(want)
    assert repr(b.flush()) == repr(a.flush())
