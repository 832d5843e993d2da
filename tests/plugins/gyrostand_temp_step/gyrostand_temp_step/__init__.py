"""gyrostand plugin term ``temp_step``: the gyro's offset changes by ``d`` when its
temperature passes ``T_STEP`` (e.g. a bonding layer or a mode change of the electronics).

    y += d · s(T),   s(T) = ½ (1 + tanh((T − T_STEP) / WIDTH))

a smooth step (``WIDTH`` = 0.5 °C: 12 % / 88 % at ∓0.5 °C from ``T_STEP``), so the
regressor is differentiable and a quantised temperature does not flip it sample by sample.
The transition temperature is a property of the part, fixed here; ``d`` is estimated.
Being linear in ``d`` with a regressor that needs only the current temperature, it runs in
every identifier: ML, the LKF online and in batch (the same regressor both ways).
"""

from __future__ import annotations

import math

import numpy as np

from gyrostand.core.terms import Param, Term

#: transition temperature (degC) and width of the step (degC)
T_STEP = 40.0
WIDTH = 0.5


def step(T):
    """s(T) = ½ (1 + tanh((T − T_STEP) / WIDTH)), for a float or an array."""
    if isinstance(T, np.ndarray):
        return 0.5 * (1.0 + np.tanh((T - T_STEP) / WIDTH))
    return 0.5 * (1.0 + math.tanh((T - T_STEP) / WIDTH))


class TempStep(Term):
    """Offset step d above T_STEP: + d · s(T)."""

    name = "temp_step"
    params = (Param("d", "linear", "y", f"offset change above {T_STEP:g} °C"),)
    math = f"+ d·s(T − {T_STEP:g} °C)"
    role = "output"
    look_alikes = {
        "temp2": "a soak on each side of the transition temperature: the step is flat "
                 "there, a quadratic term keeps changing with temperature",
        "hysteresis": "a soak above the transition temperature: the step holds, "
                      "hysteresis fades as the ramp stops",
    }

    def regressors(self, p, ctx):
        return {self.key("d"): step(ctx.temp)}

    def causal_regressors(self, p, now):
        return {self.key("d"): step(now.T)}
