"""Acknowledged writing: the run files the daemon writes while it runs.

Per gyro ``samples.csv`` (the closed bins, :class:`~gyrostand.runfolder.SamplesWriter`)
and ``estimates.csv`` (the online estimates after each bin,
:class:`~gyrostand.runfolder.EstimatesWriter`), plus ``snapshot.json`` on command.
Rows wait in memory until :meth:`AckedFiles.flush`, which first commits the raw log
(``before_flush``, the live daemon's recorder), then the bins, then the estimates: a row
on disk is *acknowledged*, the raw log replays to it.

The constructor only stores; :meth:`AckedFiles.open` creates (or, resuming, continues)
the files.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from ..can.binning import Bin
from ..errors import OutputError
from ..runfolder import EstimatesWriter, SamplesWriter, write_atomic
from ..runfolder.layout import ESTIMATES, SNAPSHOT
from .online import GyroTracker
from .resume import ResumeState

__all__ = ["AckedFiles", "SNAPSHOT_FILE"]

log = logging.getLogger(__name__)

SNAPSHOT_FILE = SNAPSHOT


class AckedFiles:
    """The samples and estimates of every gyro of ``trackers`` in ``run_dir``.

    Args:
        run_dir: the run folder.
        trackers: gyro name → its online identifiers (their estimates are written).
        before_flush: called first by every :meth:`flush` (commit the raw log).
        append: continue existing files (a resumed run) instead of starting them over.
        sync: fdatasync each file at each flush.
    """

    def __init__(self, run_dir: Path, trackers: Mapping[str, GyroTracker], *,
                 before_flush: Callable[[], None] | None = None, append: bool = False,
                 sync: bool = False) -> None:
        self.run_dir, self.trackers = run_dir, trackers
        self.before_flush, self.append, self.sync = before_flush, append, sync
        self._samples: SamplesWriter | None = None
        self.estimates: dict[str, EstimatesWriter] = {}
        self.closed = False

    @property
    def is_open(self) -> bool:
        return self._samples is not None and not self.closed

    @property
    def samples(self) -> SamplesWriter:
        if self._samples is None:
            raise OutputError(f"{self.run_dir}: the run files are not open (open() first)")
        return self._samples

    def open(self) -> None:
        """Create the files (headers written) or, with ``append``, continue them."""
        self._samples = SamplesWriter(self.run_dir, tuple(self.trackers),
                                      before_flush=self.before_flush, append=self.append,
                                      sync=self.sync)
        self.estimates = {
            name: EstimatesWriter(self.run_dir / name / ESTIMATES, tr.identifiers,
                                  tr.model.param_names, append=self.append, sync=self.sync)
            for name, tr in self.trackers.items()}

    def write(self, bins: Sequence[Bin], identify: bool) -> None:
        """Closed bins: to ``samples.csv``; each updates its gyro's online identifiers
        when ``identify``, and the estimates after it go to ``estimates.csv``."""
        self.samples.write(bins)
        for b in bins:
            tr = self.trackers[b.gyro]
            if identify:
                tr.update(b.drift, b.temp)
            self.estimates[b.gyro].write(b.t, tr.estimates())

    def resume(self, st: ResumeState) -> dict[str, int]:
        """Feed the kept bins to the online identifiers again and write the estimate rows
        the run had not written; flush. Returns the kept bins per gyro."""
        kept: dict[str, int] = {}
        for name, cols in st.columns.items():
            tr, until = self.trackers[name], st.estimates_until.get(name, -math.inf)
            for t, d, tm in zip(cols["t"], cols["drift"], cols["temp"], strict=True):
                tr.update(d, tm)
                if t > until:
                    self.estimates[name].write(t, tr.estimates())
            kept[name] = len(cols["t"])
        self.flush()
        return kept

    def flush(self) -> None:
        """Acknowledge: the raw log (``before_flush``), then the pending bins, then the
        estimates, to disk. Raises :class:`~gyrostand.errors.OutputError`."""
        self.samples.flush()
        for w in self.estimates.values():
            w.flush()

    def close(self, attempt: Callable[[Callable[[], None]], None]) -> None:
        """Flush and close every file, each through ``attempt(close)`` (which reports an
        :class:`~gyrostand.errors.OutputError` and goes on with the next)."""
        if self.closed or self._samples is None:
            return
        self.closed = True
        attempt(self._samples.close)
        for w in self.estimates.values():
            attempt(w.close)

    def write_snapshot(self, t: float) -> Path:
        """Write ``snapshot.json``: the current online estimates at frame time ``t`` (s)
        (the caller acknowledges the rows first)."""
        doc = {"t": t, "gyros": {
            name: {e.identifier: {"status": e.status, "samples": e.samples, "note": e.note,
                                  "parameters": {k: {"value": _j(v), "std": _j(s)}
                                                 for k, (v, s) in e.values.items()}}
                   for e in tr.estimates()} for name, tr in self.trackers.items()}}
        path = self.run_dir / SNAPSHOT_FILE
        write_atomic(path, json.dumps(doc, indent=2, allow_nan=False) + "\n")
        return path


def _j(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None
