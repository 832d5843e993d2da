"""Checks and repairs shared by the identifiers."""

from __future__ import annotations

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
    """Indices of isolated one-sample spikes in ``y`` (NaN = gap).

    Sample k is a spike when y_k − y_{k−1} and y_{k+1} − y_k both exceed ``threshold``
    robust standard deviations (1.4826 · MAD of the first difference), have opposite signs
    and nearly cancel (the series returns to where it was): a glitch, not a step. The
    neighbours are the nearest *observed* samples, so a spike next to a gap is caught.
    """
    obs = np.flatnonzero(np.isfinite(y))
    return obs[_spikes_dense(y[obs], threshold)]


def _spikes_dense(y: np.ndarray, threshold: float) -> np.ndarray:
    d = np.diff(y)
    ok = np.isfinite(d)
    if np.count_nonzero(ok) < 10:
        return np.zeros(0, dtype=int)
    med = np.median(d[ok])
    scale = 1.4826 * float(np.median(np.abs(d[ok] - med)))
    if scale == 0:
        scale = float(np.mean(np.abs(d[ok] - med)))
    if scale == 0:
        return np.zeros(0, dtype=int)
    a, b = d[:-1], d[1:]  # jump into sample k = 1..N-2, and out of it
    with np.errstate(invalid="ignore"):
        big = (np.abs(a) > threshold * scale) & (np.abs(b) > threshold * scale)
        back = (np.sign(a) != np.sign(b)) & (np.abs(a + b) < 0.5 * np.maximum(np.abs(a),
                                                                              np.abs(b)))
    return np.flatnonzero(big & back) + 1


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
    at = ", ".join(f"{samples.t[k]:g}" for k in spikes[:5]) + (" ..." if spikes.size > 5 else "")
    w = (f"{spikes.size} isolated spike(s) > {SPIKE_THRESHOLD:g} robust σ removed from the "
         f"drift (treated as gaps) at t = {at} s")
    y.setflags(write=False)
    return samples.replace(drift=y, warnings=(*samples.warnings, w))
