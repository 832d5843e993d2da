"""Replay of a recorded log, and the stand simulator's truth, for the CLI and the demo.

Replay feeds every frame of the log to the same :class:`~gyrostand.session.pipeline.Pipeline`
a live run uses (via :func:`gyrostand.can.replay.replay`, which calls the listener exactly
as the Notifier does), so the same frames give the same ``samples.csv`` and the same final
fits. Response frames are built and counted but go nowhere. A ``stop`` command in the log is
handled like live (acked into the void) but reading goes on to the end of the log: a live
run stops recording right after its stop, so the rest of the log is what the live run
binned too.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import can
import numpy as np

from .. import progress
from ..can.framesim import FrameSimOptions, Truth, generate_frames
from ..can.logs.read import LogDamage, read_log
from ..can.replay import replay
from ..can.routes import ChannelMap
from ..config import SessionConfig
from ..core.data import Samples
from ..core.model import Model
from ..core.profiles import TemperatureProfile
from ..core.simulation import simulate
from ..errors import ConfigError, DataError, GyrostandError
from ..runfolder import RunLog, make_run_dir, write_atomic
from ..runfolder.layout import RESULT
from .pipeline import NullSink, Pipeline, RunOutcome, session_ingest

__all__ = ["run_replay", "run_replays", "log_samples", "split_runs", "log_span", "simulated_truths",
           "simulated_frames", "truth_params"]

log = logging.getLogger(__name__)


def run_replay(cfg: SessionConfig,
               log_path: str | Path | Sequence[str | Path] | Iterable[can.Message], *,
               out: str | Path | None = None, realtime: bool = False, speed: float = 1.0,
               pump_every: int | None = None, parallel: bool | None = None,
               truths: dict[str, dict[str, float]] | None = None) -> RunOutcome:
    """Replay ``log_path`` (any format python-can reads; a list of such files, read one
    after the other, e.g. the raw segments of a resumed run; or frames) through the
    pipeline, as fast as possible unless ``realtime`` (paced to frame time / ``speed``).
    ``parallel``: parse log files in a reader process; ``pump_every``: frames between
    pumps (both: see :func:`~gyrostand.can.replay.replay`)."""
    source: Iterable[can.Message] | str | Path | list[str | Path]
    if isinstance(log_path, list | tuple) and all(isinstance(p, str | Path)
                                                  for p in log_path):
        what = " + ".join(str(p) for p in log_path)
        source = list(log_path)
    else:
        what = str(log_path) if isinstance(log_path, str | Path) else "<frames>"
        source = log_path  # type: ignore[assignment]
    run_dir = make_run_dir(out or cfg.output, cfg.name)
    runlog = RunLog(run_dir)
    damage = LogDamage()
    try:
        with Pipeline(cfg, run_dir, NullSink(), source=f"replay of {what}") as pipe:
            log.info("replaying %s into %s", what, run_dir)
            span = _stream_span(source) if progress.drawing() else None
            total = None if span is None else max(round(span[1] - span[0]), 1)
            with progress.stage("replay", "stream", total=total,
                                unit="bins" if span is None else "s of log") as bar:
                for bins in replay(source, pipe.ingest, realtime=realtime, speed=speed,
                                   pump_every=pump_every, parallel=parallel, damage=damage):
                    pipe.step(bins)
                    if total is None or span is None:
                        bar.update(len(bins))
                    elif bins:  # the log's time read so far: an ETA from its header
                        bar.update_to(min(round(bins[-1].t - span[0]), total))
                if total is not None:
                    bar.update_to(total)
                pipe.step([])
            if damage.total:
                log.warning("%s: %d damaged part(s) of the log skipped (%d containers, %d "
                            "truncated, %d lines; %d bytes skipped to resynchronise)", what,
                            damage.total, damage.containers, damage.truncated, damage.lines,
                            damage.bytes)
            with progress.stage("replay", "final fits and report"):
                return pipe.finish("end of log", truths=truths,
                                   extra_stats={"log": damage.as_dict()})
    except BaseException as exc:
        _mark_failed(run_dir / RESULT, cfg, f"replay of {what}", run_dir, exc)
        raise
    finally:
        runlog.close()


def log_samples(cfg: SessionConfig, log_path: str | Path | Sequence[str | Path]
                ) -> dict[str, Samples]:
    """Each gyro's 1-s samples of a raw log (or of several read one after the other),
    decoded through ``cfg``'s DBC mapping and binned by the receive path a replay uses
    (:func:`~gyrostand.session.pipeline.session_ingest`, :func:`~gyrostand.can.replay.replay`):
    the values a replay writes to ``<gyro>/samples.csv`` (which stores each float's
    ``repr``), with ``t`` from the gyro's first bin as the workbench reads a run folder.
    Nothing is written. A :class:`DataError` naming the log when no frame decodes."""
    paths = ([Path(log_path)] if isinstance(log_path, str | Path)
             else [Path(p) for p in log_path])
    what = " + ".join(str(p) for p in paths)
    ingest = session_ingest(cfg)
    rows: dict[str, list[tuple[float, float, float, int]]] = {g: [] for g in
                                                              ingest.binner.gyros}
    damage = LogDamage()
    with progress.stage("read", "decode and bin", unit="bins") as bar:
        for bins in replay(paths[0] if len(paths) == 1 else paths, ingest, damage=damage):
            for b in bins:
                rows[b.gyro].append((b.t, b.drift, b.temp, b.n_drift))
            bar.update(len(bins))
    if damage.total:
        log.warning("%s: %d damaged part(s) of the log skipped", what, damage.total)
    stats = ingest.listener.stats()
    if not stats.decoded:
        why = [f"{k} {v:,}" for k, v in stats.rejected.items() if v]
        if stats.ignored:
            why.insert(0, f"ignored {stats.ignored:,} (DBC messages no channel maps)")
        raise DataError(f"{what}: decoded none of {stats.received:,} CAN frames through "
                        f"the DBC mapping of {cfg.path}"
                        + (f" ({', '.join(why)})" if why else "")
                        + ": a log of another stand, or the wrong --config?")
    out = {}
    for g, r in rows.items():
        if not r:
            continue
        a = np.array(r, dtype=float)
        s = Samples.from_arrays(a[:, 0], a[:, 1], a[:, 2], dt=cfg.sampling.dt,
                                source=what, counts=a[:, 3])
        t = s.t - s.t[0]  # as a run folder is read (its epoch times stay in the file)
        t.setflags(write=False)
        out[g] = s.replace(t=t)
    return out


def _stream_span(source: Any) -> tuple[float, float] | None:
    """The frame time a replay's logs cover, from their BLF headers (no frame read), for
    its progress bar's total; None when a log is no BLF or a header lacks it."""
    paths = [source] if isinstance(source, str | Path) else source
    if not isinstance(paths, list) or not paths or not all(
            Path(p).suffix.lower() == ".blf" for p in paths):
        return None
    spans = []
    for p in paths:
        try:
            reader = can.BLFReader(p)
            first, last = float(reader.start_timestamp), float(reader.stop_timestamp)
            reader.stop()
        except Exception:  # noqa: BLE001 - the replay itself names a damaged file
            return None
        if not 0 < first <= last:
            return None
        spans.append((first, last))
    return min(a for a, _ in spans), max(b for _, b in spans)


def log_span(path: str | Path) -> tuple[float, float] | None:
    """Frame time of a log's first and last frame (None: no frame). A BLF's file header
    holds both; another log (or a BLF whose header lacks them: cut short) is read."""
    path = Path(path)
    if path.suffix.lower() == ".blf":
        try:
            reader = can.BLFReader(path)
            first, last = float(reader.start_timestamp), float(reader.stop_timestamp)
            reader.stop()
            if 0 < first <= last:
                return first, last
        except Exception as exc:  # noqa: BLE001 - read_log below names a damaged file
            log.debug("%s: no time span in the BLF header (%s); reading it", path, exc)
    first_t: float | None = None
    last_t = 0.0
    for msg in read_log(path):
        if first_t is None:
            first_t = float(msg.timestamp)
        last_t = float(msg.timestamp)
    return None if first_t is None else (first_t, last_t)


def split_runs(groups: Sequence[Sequence[str | Path]], max_gap: float) -> list[list[Path]]:
    """Logs grouped into runs, in the given order. Each group (one log, or a run folder's
    raw segments) belongs to one run; the next group continues it when its frames start
    after the run's last frame by at most ``max_gap`` s (``sampling.max_gap``: a pause),
    else it starts a new run (another switch-on, e.g. days later, or a log of an earlier
    time): one run folder per run, never a whole run rejected as a time jump."""
    if len(groups) <= 1:  # one run whatever its frames (nothing to read ahead)
        return [[Path(p) for g in groups for p in g]]
    runs: list[list[Path]] = []
    end: float | None = None
    for group in groups:
        paths = [Path(p) for p in group]
        spans = [sp for sp in (log_span(p) for p in paths) if sp is not None]
        if not spans:
            if runs:
                runs[-1] += paths
            else:
                runs.append(paths)
            continue
        first, last = spans[0][0], max(sp[1] for sp in spans)
        if end is not None and runs and end - 1.0 <= first <= end + max_gap:
            runs[-1] += paths
        else:
            if end is not None:
                log.info("%s starts %+.0f s from the previous log's end: a new run", paths[0],
                         first - end)
            runs.append(paths)
        end = last if end is None or runs[-1] is paths else max(end, last)
    return runs


def run_replays(cfg: SessionConfig, groups: Sequence[Sequence[str | Path]], **options: Any
                ) -> list[RunOutcome]:
    """Replay logs as runs (:func:`split_runs`): one run folder each, each what replaying
    that run's logs alone gives. ``options`` as :func:`run_replay`."""
    runs = split_runs(groups, cfg.sampling.max_gap)
    if len(runs) > 1:
        log.info("%d runs in the logs: one run folder each", len(runs))
    return [run_replay(cfg, paths[0] if len(paths) == 1 else paths, **options)
            for paths in runs]


def _mark_failed(path: Path, cfg: SessionConfig, source: str, run_dir: Path,
                 exc: BaseException) -> None:
    """A replay that did not finish: ``result.json`` says ``"state": "failed"`` and why
    (it would otherwise stay ``running``, as if a daemon were still writing it)."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(doc, dict):
            raise ValueError("not an object")
    except (OSError, ValueError):
        doc = {"session": cfg.name, "config": str(cfg.path), "source": source,
               "run_dir": str(run_dir), "dt": cfg.sampling.dt, "gyros": {}, "stats": {}}
    why = f"{type(exc).__name__}: {exc}" if not isinstance(exc, GyrostandError) else str(exc)
    doc["state"] = "failed"
    doc["error"] = why[:2000]
    if isinstance(doc.get("stats"), dict):
        doc["stats"]["stop_reason"] = f"failed: {why[:2000]}"
    try:
        write_atomic(path, json.dumps(doc, indent=2, allow_nan=False) + "\n")
    except (OSError, ValueError) as err:
        log.error("%s: cannot mark the replay failed: %s", path, err)


def truth_params(cfg: SessionConfig) -> dict[str, dict[str, float]]:
    """The simulator's true parameters per gyro (``white.sigma`` 0 unless given)."""
    if cfg.simulate is None:
        return {}
    out = {}
    for name, g in cfg.simulate.gyros.items():
        p = {"white.sigma": 0.0}
        p.update(g.params)
        out[name] = p
    return out


def simulated_truths(cfg: SessionConfig) -> list[Truth]:
    """1-s truth of every configured gyro from the core simulator: the ``simulate``
    section's model terms and parameters on its temperature profile, seeded (gyro i uses
    the stream ``[seed, i]``); ``duration`` defaults to the profile's last breakpoint."""
    sim = cfg.simulate
    if sim is None:
        raise ConfigError(f"{cfg.path}: simulate: missing (the simulator needs this section)")
    profile = TemperatureProfile.from_breakpoints(sim.temperature)
    params = truth_params(cfg)
    truths = []
    for i, g in enumerate(cfg.gyros):
        if g.name not in sim.gyros:
            raise ConfigError(f"{cfg.path}: simulate.gyros: no truth for gyro {g.name!r}")
        model = Model.parse(sim.gyros[g.name].model)
        s = simulate(model, params[g.name], profile, dt=cfg.sampling.dt,
                     duration=sim.duration, seed=np.random.default_rng([sim.seed, i]))
        truths.append(Truth(s.t, s.drift, s.temp))
    return truths


def simulated_frames(cfg: SessionConfig) -> Iterator[can.Message]:
    """The simulated stand's frames (time-ordered), per the config's ``simulate`` section."""
    truths = simulated_truths(cfg)  # raises ConfigError without a simulate section
    sim = cfg.simulate
    if sim is None:  # (simulated_truths refuses it first)
        raise ConfigError(f"{cfg.path}: simulate: missing")
    return generate_frames(cfg.db, ChannelMap.from_config(cfg), truths,
                           FrameSimOptions.from_config(sim))
