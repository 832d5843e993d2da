"""Sets of runs of one simulated gyro: shared physics, a new turn-on bias every switch-on.

Each run is a chamber cycle of ``hours`` simulated with the model's exact discretisation
(:func:`gyrostand.core.simulation.simulate`: every run starts from its own stationary
Markov state); the per-run biases are drawn ``N(BIAS_MEAN, SPREAD²)`` — the spread the
repeatability estimate must recover.
"""

from __future__ import annotations

import numpy as np

from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate

MODEL = "markov,temp,bias"
#: the gyro's physics, shared by every run (drift unit y, β 1/s, γ y/(s·°C))
PHYSICS = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
           "white.sigma": 0.02}
BIAS_MEAN = 0.3
#: turn-on-to-turn-on spread of the bias (the acceptance's 0.1)
SPREAD = 0.1


def run_set(seed: int, n_runs: int = 5, hours: float = 2.0, model: str = MODEL,
            extra: dict[str, float] | None = None):
    """``n_runs`` runs of one gyro and their true biases."""
    m = Model.parse(model)
    rng = np.random.default_rng(seed)
    biases = BIAS_MEAN + SPREAD * rng.standard_normal(n_runs)
    runs = []
    for r, b in enumerate(biases):
        p = {**PHYSICS, **(extra or {}), "bias.b": float(b)}
        runs.append(simulate(m, p, chamber_profile(hours), seed=seed * 100 + r + 1))
    return m, runs, biases
