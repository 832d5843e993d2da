"""The run folder and what is written into it.

::

    <output>/<session name>-<UTC yyyymmdd-HHMMSS>/
        raw.blf              every raw frame received (live runs; replayable)
        <gyro>/samples.csv   1-s bins: t, drift, temp, n_drift, n_temp
        <gyro>/estimates.csv online estimates after every bin, with stds
        result.json          final batch fits per gyro + counts
        report.txt           the final table and counts, readable
        run.log              the log of the run

The folder name uses the wall clock (it names a file, it is not data); a suffix ``-2``,
``-3``, ... keeps two runs started in the same second apart.
"""

from __future__ import annotations

import csv
import logging
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TextIO

from .online import OnlineEstimate

__all__ = ["make_run_dir", "RunLog", "EstimatesWriter", "estimate_columns"]

log = logging.getLogger(__name__)


def make_run_dir(output: str | Path, name: str, wall: float | None = None) -> Path:
    """Create and return a fresh ``<output>/<name>-<timestamp>`` folder."""
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime(time.time() if wall is None else wall))
    base = Path(output) / f"{name}-{stamp}"
    path, n = base, 1
    while True:
        try:
            path.mkdir(parents=True)
            return path
        except FileExistsError:
            n += 1
            path = base.with_name(f"{base.name}-{n}")


class RunLog:
    """Attach a ``run.log`` file handler to the ``gyrostand`` logger for one run (INFO and
    above, with wall-clock times); :meth:`close` detaches it."""

    def __init__(self, run_dir: Path, level: int = logging.INFO) -> None:
        self.path = run_dir / "run.log"
        self.handler = logging.FileHandler(self.path, encoding="utf-8")
        self.handler.setLevel(level)
        self.handler.setFormatter(logging.Formatter(
            "%(asctime)s %(levelname)s %(name)s: %(message)s"))
        self.logger = logging.getLogger("gyrostand")
        self._old_level = self.logger.level
        if self.logger.getEffectiveLevel() > level:
            self.logger.setLevel(level)
        self.logger.addHandler(self.handler)

    def close(self) -> None:
        self.logger.removeHandler(self.handler)
        self.logger.setLevel(self._old_level)
        self.handler.close()


def estimate_columns(identifiers: Sequence[str], param_names: Sequence[str]) -> list[str]:
    """``t`` then, per identifier and parameter, ``<id>:<param>`` and ``<id>:<param>:std``,
    then ``<id>:status``."""
    cols = ["t"]
    for ident in identifiers:
        for p in param_names:
            cols += [f"{ident}:{p}", f"{ident}:{p}:std"]
        cols.append(f"{ident}:status")
    return cols


class EstimatesWriter:
    """``<run>/<gyro>/estimates.csv``: one row per closed bin (t = bin start, s), the
    online estimates after that bin (NaN written ``nan`` while unknown)."""

    def __init__(self, path: Path, identifiers: Sequence[str],
                 param_names: Sequence[str]) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self.param_names = tuple(param_names)
        self._f: TextIO = path.open("w", newline="", encoding="utf-8")
        self._w = csv.writer(self._f, lineterminator="\n")
        self._w.writerow(estimate_columns(identifiers, param_names))

    def write(self, t: float, estimates: Sequence[OnlineEstimate]) -> None:
        row: list[object] = [repr(t)]
        for e in estimates:
            for p in self.param_names:
                v, s = e.values[p]
                row += [_num(v), _num(s)]
            row.append(e.status)
        self._w.writerow(row)

    def flush(self) -> None:
        self._f.flush()

    def close(self) -> None:
        self._f.close()


def _num(x: float) -> str:
    return "nan" if math.isnan(x) else f"{x:.9g}"
