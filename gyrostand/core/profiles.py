"""Temperature profiles from breakpoints.

A profile is piecewise linear through ``(t_i, T_i)`` breakpoints and held constant outside
them. The paper's profile (MODEL.md, "The paper's test") is built in:
20 -> 45 degC over 0-500 s, 45 degC over 500-1000 s, 45 -> 35 degC over 1000-2000 s.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import ModelError


@dataclass(frozen=True)
class TemperatureProfile:
    """Piecewise-linear temperature T(t) through breakpoints.

    Attributes:
        times: breakpoint times, s, strictly increasing.
        temps: temperatures at the breakpoints, degC.
    """

    times: tuple[float, ...]
    temps: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.times) != len(self.temps) or len(self.times) < 1:
            raise ModelError("a temperature profile needs matching, non-empty times and temps")
        if any(b <= a for a, b in zip(self.times, self.times[1:], strict=False)):
            raise ModelError("temperature profile breakpoint times must increase strictly")

    @classmethod
    def from_breakpoints(cls, points: Sequence[Sequence[float]]) -> TemperatureProfile:
        """Build from ``[(t0, T0), (t1, T1), ...]``."""
        pts = [(float(a), float(b)) for a, b in points]
        return cls(tuple(p[0] for p in pts), tuple(p[1] for p in pts))

    @property
    def duration(self) -> float:
        """Time of the last breakpoint, s."""
        return self.times[-1]

    def __call__(self, t: np.ndarray | float) -> np.ndarray:
        """Temperature at ``t`` (s), degC: linear between breakpoints, held outside.

        >>> p = paper_profile()
        >>> [float(x) for x in p([0.0, 250.0, 750.0, 1500.0, 9999.0])]
        [20.0, 32.5, 45.0, 40.0, 35.0]
        """
        return np.interp(np.asarray(t, dtype=float), self.times, self.temps)

    def grid(self, dt: float = 1.0, duration: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Sample times ``0, dt, ..., duration`` and the temperatures there.

        >>> t, temp = paper_profile().grid(dt=500.0)
        >>> t.tolist(), temp.tolist()
        ([0.0, 500.0, 1000.0, 1500.0, 2000.0], [20.0, 45.0, 45.0, 40.0, 35.0])
        """
        end = self.duration if duration is None else duration
        t = self.times[0] + dt * np.arange(int(round((end - self.times[0]) / dt)) + 1)
        return t, self(t)


def paper_profile() -> TemperatureProfile:
    """The paper's 2000-s test profile (MODEL.md)."""
    return TemperatureProfile.from_breakpoints([(0, 20), (500, 45), (1000, 45), (2000, 35)])


def chamber_profile(hours: float = 6.0) -> TemperatureProfile:
    """A realistic thermal-chamber cycle: soaks and ramps of different rates.

    From 20 degC: soak 10 min, heat at 1 degC/min to 45, soak 30 min, cool at
    0.5 degC/min to 10, soak 30 min, heat at 2 degC/min to 30, soak 25 min; the cycle
    (200 min) repeats from there until ``hours`` have passed.
    """
    # (segment duration s, temperature at its end degC; None = soak at the current value)
    cycle = [(600, None), (1500, 45.0), (1800, None), (4200, 10.0), (1800, None),
             (600, 30.0), (1500, None)]
    t_end = hours * 3600.0
    t, T = 0.0, 20.0
    pts = [(t, T)]
    while t < t_end:
        for dur, target in cycle:
            t += dur
            T = T if target is None else target
            pts.append((t, T))
    prof = TemperatureProfile.from_breakpoints(pts)
    keep = [(a, b) for a, b in pts if a < t_end] + [(t_end, float(prof(t_end)))]
    return TemperatureProfile.from_breakpoints(keep)
