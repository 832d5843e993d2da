"""The smoother's forward pass with the states alone (the model error's h-step predictions,
``kalman.kf_filtered_states``): it holds the covariance's steady state, and its filtered
states are the full pass's to the bit, on records with gaps and per-sample weights."""

from __future__ import annotations

import numpy as np
import pytest

from gyrostand.core import kalman, rts


@pytest.mark.parametrize("seed", range(12))
def test_the_states_alone_are_the_full_passs_to_the_bit(seed):
    rng = np.random.default_rng(seed)
    n, N = 1 + seed % 3, int(rng.integers(50, 4000))
    phi = rng.choice([0.9, 0.99, 0.999, 1.0], n)
    q, p0 = rng.uniform(1e-5, 0.1, n), rng.uniform(0.1, 3.0, n)
    r = [0.0, 0.01, 0.3][seed % 3]
    y = rng.normal(size=N)
    if seed % 2:
        y[rng.choice(N, max(1, N // 15), replace=False)] = np.nan  # dropped bins
        y[N // 3: N // 3 + 20] = np.nan  # an outage
    rw = [rng.uniform(0.7, 1.4, N),  # every bin its own frame count
          np.where(rng.random(N) < 0.02, 2.0, 1.0),  # a few half-filled bins
          kalman.NO_WEIGHTS][seed % 3]
    full = rts.rts_forward(phi, q, p0, r, rw, y, *rts.forward_work(n, N))
    alone = rts.rts_forward(phi, q, p0, r, rw, y, *rts.forward_work(n, N, covariances=False))
    assert np.array_equal(full[0], alone[0]) and np.array_equal(full[2], alone[2])
    assert alone[1].shape == (0, n, n) and alone[3].shape == (0, n, n)
    assert np.array_equal(kalman.kf_filtered_states(phi, q, p0, r, rw, y), full[2])
    assert np.isfinite(full[2]).all()


def test_a_markov_process_reaches_its_steady_state():
    """The point of the states alone: a Markov process with white noise settles within
    a few hundred samples, after which the pass updates the states only (5x faster on a
    6-h run); here, the settled gain gives the same states as recomputing it."""
    N = 21_600
    phi, q = np.array([np.exp(-0.01)]), np.array([0.05**2 * (1 - np.exp(-0.02))])
    y = np.random.default_rng(1).normal(size=N)
    work = rts.forward_work(1, N, covariances=False)
    rts.rts_forward(phi, q, np.array([0.05**2]), 0.02**2, kalman.NO_WEIGHTS, y, *work)
    full = rts.rts_forward(phi, q, np.array([0.05**2]), 0.02**2, kalman.NO_WEIGHTS, y,
                           *rts.forward_work(1, N))
    # the predicted covariance is bit-for-bit constant from a few hundred samples on (the
    # premise of holding it), and the pass held it there: its last P is that one
    Pp = full[1][:, 0, 0]
    assert (Pp[300:] == Pp[-1]).all() and not (Pp[:10] == Pp[-1]).any()
    assert work[-1][0, 0] == Pp[-1]
    assert np.array_equal(work[2], full[2])
