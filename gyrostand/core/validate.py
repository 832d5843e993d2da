"""Checks and repairs shared by the identifiers."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import DataError, IdentificationError
from .data import Samples

#: a spike is a sample whose jumps to and from its neighbours both exceed this many robust
#: standard deviations of the first difference (a Gaussian series never does: P < 1e-190)
SPIKE_THRESHOLD = 30.0


def require_samples(samples: Samples, n_usable: int, n_needed: int, method: str) -> None:
    """Raise :class:`DataError` when there are fewer usable samples than the fit needs."""
    if n_usable < n_needed:
        raise DataError(
            f"{samples.source}: {method} needs at least {n_needed} usable samples for this "
            f"model, got {n_usable}"
        )


def find_spikes(y: np.ndarray, threshold: float = SPIKE_THRESHOLD) -> np.ndarray:
    """Indices of isolated spikes of one or two samples in ``y`` (NaN = gap).

    Sample k is a spike when y_k − y_{k−1} and y_{k+1} − y_k both exceed ``threshold``
    robust standard deviations (1.4826 · MAD of the first difference), have opposite signs
    and nearly cancel (the series returns to where it was): a glitch, not a step. Two
    consecutive samples k, k+1 are a burst (a jolt: one swing and its rebound) when each
    lies more than ``threshold`` robust σ from the mean of y_{k−1} and y_{k+2}, and those
    two agree to within half the smaller excursion. The neighbours are the nearest
    *observed* samples, so a spike next to a gap is caught.
    """
    obs = np.flatnonzero(np.isfinite(y))
    return obs[_spikes_dense(y[obs], threshold)]


def robust_std(values: np.ndarray | Sequence[float]) -> float:
    """1.4826 × the median absolute deviation: the std of a normal sample, unmoved by a
    few values far out."""
    v = np.asarray(values, dtype=float)
    return float(1.4826 * np.median(np.abs(v - np.median(v))))


def _spikes_dense(y: np.ndarray, threshold: float) -> np.ndarray:
    d = np.diff(y)
    if d.size < 10:
        return np.zeros(0, dtype=int)
    med = np.median(d)
    scale = robust_std(d)
    if scale == 0:
        scale = float(np.mean(np.abs(d - med)))
    if scale == 0:
        return np.zeros(0, dtype=int)
    lim = threshold * scale
    a, b = d[:-1], d[1:]  # jump into sample k = 1..N-2, and out of it
    big = (np.abs(a) > lim) & (np.abs(b) > lim)
    back = (np.sign(a) != np.sign(b)) & (np.abs(a + b) < 0.5 * np.maximum(np.abs(a),
                                                                          np.abs(b)))
    one = np.flatnonzero(big & back) + 1
    # bursts of two: samples k, k+1 (k = 1..N-3) against y_{k-1} and y_{k+2}
    ref = 0.5 * (y[:-3] + y[3:])
    e1 = np.abs(y[1:-2] - ref)
    e2 = np.abs(y[2:-1] - ref)
    agree = np.abs(y[3:] - y[:-3]) < 0.5 * np.minimum(e1, e2)
    k = np.flatnonzero((e1 > lim) & (e2 > lim) & agree) + 1
    return np.unique(np.concatenate([one, k, k + 1])).astype(int)


def prepare(samples: Samples, method: str) -> Samples:
    """What every identifier does first: refuse a drift with nothing to identify, and
    turn isolated spikes (glitches of the sensor or the bus) into gaps, with a warning."""
    y = samples.drift
    obs = y[np.isfinite(y)]
    if obs.size and np.ptp(obs) == 0:
        raise IdentificationError(
            f"{samples.source}: {method}: the drift is constant (all {obs.size} observed "
            f"samples = {obs[0]:g}): nothing to identify — a stuck or saturated sensor?"
        )
    spikes = find_spikes(y)
    if spikes.size == 0:
        return samples
    y = y.copy()
    y[spikes] = np.nan
    more = " ..." if spikes.size > 5 else ""
    t0 = float(samples.t[0])
    at = ", ".join(f"{samples.t[k]:.10g}" for k in spikes[:5]) + more
    if t0 != 0.0:  # epoch times: say where in the record, too
        at += " (" + ", ".join(f"{samples.t[k] - t0:.6g}" for k in spikes[:5]) + more + \
            " s from the first sample)"
    w = (f"{spikes.size} isolated spike(s) > {SPIKE_THRESHOLD:g} robust σ removed from the "
         f"drift (treated as gaps) at t = {at} s")
    y.setflags(write=False)
    return samples.replace(drift=y, warnings=(*samples.warnings, w))
