"""Test runs built the way a real log arrives: frames, then the project's 1-s binner.

A model is simulated on a 1-s grid *without* its white noise (the drift's slow part); each
drift frame (``drift_hz``) carries that value, interpolated linearly, plus its own frame
noise of std ``white.sigma · √drift_hz`` (so a full bin's mean has the model's
``white.sigma``); temperature frames (``temp_hz``) carry the chamber temperature with
0.01-degC noise quantized to 0.05 degC. Frame times have a uniform jitter, frames drop at
random, the log starts at an arbitrary instant inside a bin (a partial first bin) and ends
inside one (a partial last bin), and an optional outage removes every frame for a while.
The frames go through :class:`gyrostand.can.binning.Binner` (what ``run``/``replay`` use)
and are written as a ``samples.csv``-like CSV with ``n_drift``/``n_temp``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gyrostand.can.binning import Binner
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate

BASE = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
        "white.sigma": 0.02, "bias.b": 0.3}


def frame_run(path: Path, terms=(), extra=None, *, seed: int, hours: float = 4.0,
              drift_hz: float = 10.0, temp_hz: float = 10.0, drop: float = 0.0,
              jitter: float = 0.002, start_offset: float = 0.93, end_cut: float = 0.05,
              outage: tuple[float, float] | None = None, params=None,
              profile=None, response=None, event=None) -> Path:
    """Write the binned CSV of a frame-level simulation to ``path``; return it.
    ``response(T)``: a static response to the temperature added to the drift (a shape
    outside the vocabulary); ``event(t)``: a function of the time since the start added to
    it (a bias jump: the frames between the grid's seconds interpolate across it)."""
    p = {**BASE, **(params or {}), **(extra or {})}
    m = Model.parse(["markov", "temp", "bias", *terms])
    prof = profile if profile is not None else chamber_profile(hours)
    clean = simulate(m, {**p, "white.sigma": 0.0}, prof, seed=seed)
    if response is not None:
        clean = type(clean).from_arrays(clean.t, clean.drift + response(clean.temp),
                                        clean.temp, dt=clean.dt)
    if event is not None:
        clean = type(clean).from_arrays(clean.t, clean.drift + event(clean.t), clean.temp,
                                        dt=clean.dt)
    rng = np.random.default_rng(seed + 5000)
    t1 = clean.t
    span = t1[-1]

    def frames(hz: float) -> np.ndarray:
        tf = np.arange(start_offset, span - end_cut, 1.0 / hz)
        tf = tf + rng.uniform(-jitter, jitter, tf.size)
        keep = rng.random(tf.size) >= drop
        if outage is not None:
            keep &= ~((tf >= outage[0]) & (tf < outage[1]))
        return np.sort(tf[keep])

    td = frames(drift_hz)
    yd = np.interp(td, t1, clean.drift) + \
        p["white.sigma"] * np.sqrt(drift_hz) * rng.standard_normal(td.size)
    tt = frames(temp_hz)
    yt = np.round((np.interp(tt, t1, clean.temp) + 0.01 * rng.standard_normal(tt.size))
                  / 0.05) * 0.05
    epoch = 1_700_000_000.0
    samples = [(0, 0, epoch + a, float(b)) for a, b in zip(td, yd, strict=True)]
    samples += [(0, 1, epoch + a, float(b)) for a, b in zip(tt, yt, strict=True)]
    samples.sort(key=lambda s: s[2])
    binner = Binner(["g"], dt=1.0, epoch=epoch)
    bins = binner.add_many(samples) + binner.flush()
    with path.open("w") as fh:
        fh.write("t,drift,temp,n_drift,n_temp\n")
        for b in bins:
            fh.write(f"{b.t!r},{b.drift!r},{b.temp!r},{b.n_drift},{b.n_temp}\n")
    return path
