"""estimates.csv rows formatted in one operation (``runfolder.tables.estimates_row``) are the
rows the cell-by-cell formatting gave: every number through ``_num`` (``nan`` for any
NaN, ``%.9g`` otherwise), ``repr`` of the bin start, the status as it is."""

from __future__ import annotations

import random
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrostand.runfolder.tables import _num, estimates_row


@dataclass
class _Est:
    values: dict[str, tuple[Any, Any]]
    status: str


def _cell_by_cell(t, estimates, param_names):
    cells = [repr(t)]
    for e in estimates:
        for p in param_names:
            v, s = e.values[p]
            cells += [_num(v), _num(s)]
        cells.append(e.status)
    return ",".join(cells)


def test_rows_equal_the_cell_by_cell_rows():
    rng = random.Random(20261203)
    specials = [float("nan"), -float("nan"), float("inf"), -float("inf"), 0.0, -0.0,
                5e-324, 1.7976931348623157e308, np.float64(0.1), np.float64("nan"),
                np.float32(0.3), 0, 3]

    def x():
        r = rng.random()
        if r < 0.2:
            return rng.choice(specials)
        if r < 0.5:  # any bit pattern
            return struct.unpack("d", struct.pack("Q", rng.getrandbits(64)))[0]
        return rng.uniform(-1e3, 1e3)

    names = ["markov.beta", "markov.sigma", "temp.gamma", "white.sigma", "bias.b"]
    for _ in range(5000):
        ests = [_Est({n: (x(), x()) for n in names},
                     rng.choice(["ok", "warning", "insufficient_data", "failed"]))
                for _ in range(rng.randint(0, 3))]
        t = rng.choice([rng.uniform(0, 1e5), float(rng.randint(0, 10**6)), np.float64(12.5)])
        assert estimates_row(t, ests, names) == _cell_by_cell(t, ests, names)
