"""A rate term's dT/dt for the online LKF centred on each bin, as ML computes it.

A term whose regressor is the temperature rate (``temp_rate``, ``hysteresis``:
``Term.rate_input``) is fitted by ML with the slope of the ``RATE_WINDOW_S`` window centred
on each bin (:func:`~gyrostand.core.terms.base.temperature_rate`). The online filter's
causal slope of the last window is that centred slope half a window (30 s at Δt = 1 s)
late: at every corner of a ramp the regressor was wrong for a minute, and temp_rate.k's
estimate with it. So each bin waits here until the half window after it is in, and goes
to the filter with the centred rate (:class:`CentredRates`): the first window's bins with
its quadratic at the start and the last ones, at stop, with the record's end quadratic,
the values ML's series has there.

Measured on 30 6-h chamber runs (``benchmarks/lkf_accuracy.py``'s), temp_rate.k's error
in its std at every 100-s checkpoint, whatever the status: RMS 1.66 / 1.48 / 1.72 (before
12,000 s / to 17,000 s / after) and beyond ±3 std at 8.0 / 8.5 / 7.9 % of the checkpoints
with the causal slope; 1.14 / 1.23 / 1.33 and 1.0 / 5.7 / 3.1 % centred (the ML fit of
the whole record: 1.33). On 300 such runs the band's checkpoints short of 0.98 among
``ok`` statuses went 3 → 0 (``benchmarks/results/lkf_accuracy.txt``).
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ..terms.base import rate_window, slope_kernel, temperature_rate

__all__ = ["CentredRates"]


class CentredRates:
    """Bins waiting for their centred temperature rate. ``lag``: how many later bins a
    bin waits for (half the rate window; 0: none wait, the filter takes each at once)."""

    def __init__(self, dt: float, active: bool):
        self.dt = float(dt)
        self.lag = (rate_window(self.dt) - 1) // 2 if active else 0
        self._bins: deque[tuple[float, float]] = deque()
        h = self.lag
        #: the centred line's slope as a weighted sum of the window (none when no bin waits)
        self._kernel = slope_kernel(2 * h + 1, self.dt) if h else np.zeros(1)
        #: the last 2·lag + 1 temperatures received (the oldest waiting bin's in the middle)
        self._last = np.zeros(2 * h + 1)
        self._started = False

    def __len__(self) -> int:
        return len(self._bins)

    def push(self, y: float, T: float) -> list[tuple[float, float, float]]:
        """Add a bin; return ``(y, T, rate)`` of each bin now ready, oldest first: none
        until the first window is in, then its first ``lag`` + 1 bins, then one a bin."""
        self._bins.append((y, T))
        last = self._last
        last[:-1] = last[1:]
        last[-1] = T
        h = self.lag
        if not self._started:
            if len(self._bins) < 2 * h + 1:
                return []
            # the first window: its quadratic's slopes, as ML's series at its start
            self._started = True
            rates = temperature_rate(last, self.dt)
            return [(*self._bins.popleft(), float(rates[k])) for k in range(h + 1)]
        y0, T0 = self._bins.popleft()
        return [(y0, T0, float(last @ self._kernel))]

    def flush(self, filtered_T: np.ndarray) -> list[tuple[float, float, float]]:
        """Every waiting bin with its rate at the record's end (the last window's
        quadratic, as ML's series there), oldest first; none wait afterwards."""
        if not self._bins:
            return []
        m = len(self._bins)
        tail = np.concatenate([filtered_T[max(len(filtered_T) - rate_window(self.dt), 0):],
                               [b[1] for b in self._bins]])
        rates = temperature_rate(tail, self.dt)[-m:]
        out = [(y, T, float(r)) for (y, T), r in zip(self._bins, rates, strict=True)]
        self._bins.clear()
        self._started = False  # a bin after it starts a window of its own
        return out

    def rates_of(self, filtered_T: np.ndarray) -> np.ndarray | None:
        """dT/dt of the filtered bins centred on the waiting ones' temperatures too (a
        re-linearisation's regressors, as the filter took them); None when none wait."""
        if not self._bins:
            return None
        temps = np.concatenate([filtered_T, [b[1] for b in self._bins]])
        return temperature_rate(temps, self.dt)[: len(filtered_T)]
