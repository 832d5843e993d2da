"""The end of a run: close the files, final fits, last frames, ``result.json`` and report.

:func:`finish_run` is what :meth:`Pipeline.finish <gyrostand.session.pipeline.Pipeline.finish>`
does, in this order: the state goes ``stopping`` (or ``fault``); the samples and estimates
files are closed; per gyro the online LKF re-linearises a last time and the final batch
fits run on ``samples.csv`` as written; a last result round (with the final ML) and a last
heartbeat (in the final state) go out; the stats are gathered, the live run's
``segments.json`` finished, ``result.json`` and ``report.txt`` written. A file that cannot
be written (e.g. a full disk) is reported in ``stats["unwritten"]`` and turns the state into
``fault``; everything that can be written still is.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from ..errors import OutputError
from ..runfolder import read_samples_csv
from ..runfolder.layout import REPORT, RESULT
from .commands import FAULT, STOPPED
from .final import GyroFinal, fit_gyro, write_report, write_result_json
from .online import OnlineEstimate

#: threads for the gyros' final fits (a run's stand has one to a few gyros)
FIT_WORKERS = 2

if TYPE_CHECKING:
    from ..can.binning import Binner
    from ..can.receive.listener import DecodingListener
    from ..config import SessionConfig
    from ..runfolder import SegmentLog
    from .acked import AckedFiles
    from .commands import CommandProtocol
    from .online import GyroTracker
    from .responses import Responses

__all__ = ["RunOutcome", "finish_run", "Ending"]


class Ending(Protocol):
    """What :func:`finish_run` uses of a run's pipeline
    (:class:`~gyrostand.session.pipeline.Pipeline`, which calls it): its session, folder
    and source, its parts, and its frame time, heartbeat and counts."""

    cfg: SessionConfig
    run_dir: Path
    source: str
    protocol: CommandProtocol
    responses: Responses
    files: AckedFiles
    listener: DecodingListener
    binner: Binner
    trackers: dict[str, GyroTracker]
    segments: SegmentLog | None

    def frame_time(self) -> float: ...

    def heartbeat(self, timestamp: float) -> None: ...

    def stats(self) -> dict[str, Any]: ...

log = logging.getLogger(__name__)


@dataclass
class RunOutcome:
    """What a finished run produced: paths, final fits, why it stopped, the state."""

    run_dir: Path
    result_json: Path
    report: Path
    finals: list[GyroFinal]
    stop_reason: str
    state: str
    stats: dict[str, Any] = field(default_factory=dict)
    #: the final result.json was written (else the file, if any, is the provisional
    #: one of a running run: not this run's result)
    result_written: bool = True

    @property
    def ok(self) -> bool:
        return self.state != FAULT


def finish_run(pipe: Ending, reason: str, *, extra_stats: dict[str, Any] | None = None,
               truths: dict[str, dict[str, float]] | None = None,
               state: str = STOPPED) -> RunOutcome:
    """End ``pipe``'s run for ``reason`` in ``state`` (``stopped`` or ``fault``); see the
    module doc. Call after the driver has delivered the last bins (its flush)."""
    if state not in (STOPPED, FAULT):
        raise ValueError(f"a run ends stopped or fault, not {state!r}")
    protocol, responses = pipe.protocol, pipe.responses
    protocol.end("fail" if state == FAULT else "end")
    unwritten: list[str] = []

    def attempt(write: Callable[[], object]) -> None:
        try:
            write()
        except OutputError as exc:  # e.g. the disk is full: say so, finish the rest
            unwritten.append(str(exc))
            log.error("%s", exc)

    pipe.files.close(attempt)
    finals, extra = _final_fits(pipe)
    responses.send_results(extra)
    if unwritten and state != FAULT:
        state, reason = FAULT, f"{reason}; {unwritten[0]}"
    protocol.end("fail" if state == FAULT else "done")
    pipe.heartbeat(max(pipe.frame_time(), responses.last_beat))
    responses.log_rejections(pipe.listener.stats(), pipe.binner.stats(), pipe.frame_time(),
                             force=True)
    stats = pipe.stats()
    stats.update(extra_stats or {})
    stats["stop_reason"] = reason
    if pipe.segments is not None:  # this segment's counts, then the whole run's
        segs = pipe.segments
        attempt(lambda: segs.update(stats, ended_by=reason, extra={
            k: stats[k] for k in ("recorder", "bus") if k in stats}))
        stats["segments"] = segs.segments()
        stats["run_totals"] = segs.totals()
    result = pipe.run_dir / RESULT
    report = pipe.run_dir / REPORT
    stats["unwritten"] = unwritten
    before = len(unwritten)
    attempt(lambda: write_result_json(result, pipe.cfg, pipe.source, pipe.run_dir,
                                      finals, stats))
    result_written = len(unwritten) == before  # else result.json is the provisional one
    attempt(lambda: write_report(report, pipe.cfg, pipe.source, finals, stats,
                                 truths or {}))
    if pipe.cfg.formats:  # Parquet/MF4 beside the CSVs, from the files as committed
        from .export import write_formats

        attempt(lambda: write_formats(pipe.run_dir, pipe.cfg.formats))
    if unwritten and state != FAULT:
        state, reason = FAULT, f"{reason}; {unwritten[0]}"
        stats["stop_reason"] = reason
    log.info("run finished (%s): %s, %s", reason, result, report)
    return RunOutcome(pipe.run_dir, result, report, finals, reason, state, stats,
                      result_written=result_written)


def _final_fits(pipe: Ending) -> tuple[list[GyroFinal], dict[str, list[OnlineEstimate]]]:
    """Per gyro: the online LKF's last re-linearisation (``lkf`` at stop), then the final
    batch fits on ``samples.csv``; the final ML as an extra estimate for the last round."""
    extra: dict[str, list[OnlineEstimate]] = {}
    jobs = []
    for g in pipe.cfg.gyros:
        path = pipe.files.samples.paths[g.name]
        try:
            cols = read_samples_csv(path)
        except OSError as exc:  # e.g. the run folder was removed while the run went on
            raise OutputError(f"{path}: cannot read the run's samples back: "
                              f"{exc.strerror or exc}") from exc
        tr = pipe.trackers[g.name]
        tr.finish()
        jobs.append((g, cols, f"{pipe.run_dir.name}/{g.name}/samples.csv", tr.estimates(),
                     tr.lkf_fit if "lkf" in tr.identifiers else None))

    def fit(job: tuple[Any, ...]) -> GyroFinal:
        g, cols, source, online, lkf = job
        return fit_gyro(g, cols, pipe.cfg.sampling.dt, source, None, online, lkf)

    # the gyros' final fits side by side (each the same computation on any thread; the
    # Kalman kernels release the GIL), in the gyros' order
    if len(jobs) > 1:
        with ThreadPoolExecutor(max_workers=FIT_WORKERS, thread_name_prefix="final") as pool:
            finals = list(pool.map(fit, jobs))
    else:
        finals = [fit(j) for j in jobs]
    for g, f in zip(pipe.cfg.gyros, finals, strict=True):
        ml = f.fits.get("ml")
        if ml is not None and not isinstance(ml, str):
            vals = {n: (e.value, e.std) for n, e in ml.parameters.items()}
            extra[g.name] = [OnlineEstimate("ml", "warning" if ml.warnings else "ok",
                                            vals, ml.n_observed, ml.residual_rms)]
    return finals, extra
