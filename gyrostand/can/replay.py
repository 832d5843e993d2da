"""Replay of recorded logs through the live receive path.

Logs are read by :mod:`gyrostand.can.logs.read` (anything :class:`can.LogReader` reads).
:func:`replay` hands each frame to the very listeners a live run attaches to its Notifier
and pumps the same :class:`~gyrostand.can.ingest.Ingest`, so a log gives the bins the live
run gave. All timing comes from frame timestamps; ``realtime=True`` only paces delivery
(sleeping to frame time / ``speed``), it never changes the data.

Log files replayed as fast as possible are read as arrays: a BLF's containers parsed
whole (:mod:`gyrostand.can.logs.blfarray`), batches of frames received by
:meth:`~gyrostand.can.receive.listener.DecodingListener.receive_arrays`, which applies the
per-frame path's rules to whole batches and hands the frames it cannot decide alone to
the per-frame code. Other formats are parsed in a reader process
(:class:`~gyrostand.can.logs.reader.ReaderProcess`) while this process decodes, bins and
estimates. ``GYROSTAND_PER_FRAME=1`` forces the per-frame path (frames as tuples, or
messages). Either way the frames reach the listener in the same order and the pumps
fall after the same frames, so the bins, counts and rejections are identical (tested:
tests/can/test_array_path.py).
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Generator, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import can

from gyrostand.can.binning import Bin
from gyrostand.can.ingest import Ingest
from gyrostand.can.logs.read import LogDamage, read_log, read_logs, read_logs_arrays
from gyrostand.can.logs.reader import ReaderProcess, array_batches
from gyrostand.core.threads import usable_cpus

__all__ = ["read_log", "read_logs", "paced", "replay", "PARALLEL_MIN_BYTES", "LogDamage",
           "per_frame_forced", "FILE_PUMP", "PUMP"]

#: frames between pumps of a replay of log files as fast as possible, when the caller
#: names none: the array path pays per batch (~0.7 ms of numpy calls), so 8192 frames
#: (~8 s of a 3-gyro stand) receive a 1 M-frame BLF in ~0.33 s of CPU where 1024 took
#: ~0.68 s (benchmarks/results/replay_whole_command.txt); bins do not depend on where the
#: pumps fall (a bin closes on the next sample of its gyro)
FILE_PUMP = 8192
#: frames between pumps otherwise (frames given as messages, or paced by ``realtime``)
PUMP = 1024

#: log files (in total) at least this large are parsed in a reader process when
#: ``parallel`` is None; below it the process start (~0.2 s) is not worth it
PARALLEL_MIN_BYTES = 1 << 20

log = logging.getLogger(__name__)


def paced(messages: Iterable[can.Message], speed: float = 1.0,
          clock: Callable[[], float] = time.monotonic,
          sleep: Callable[[float], None] = time.sleep) -> Iterator[can.Message]:
    """Yield frames no faster than their timestamps say (``speed`` x real time)."""
    if not speed > 0:
        raise ValueError(f"speed must be > 0, got {speed!r}")
    t_first = wall0 = 0.0
    for n, msg in enumerate(messages):
        if n == 0:
            t_first, wall0 = msg.timestamp, clock()
        else:
            delay = wall0 + (msg.timestamp - t_first) / speed - clock()
            if delay > 0:
                sleep(delay)
        yield msg


def per_frame_forced() -> bool:
    """True when ``GYROSTAND_PER_FRAME`` is set (not "" or "0"): replays of log files
    take the per-frame path (frames as tuples or messages) instead of the array path,
    e.g. to compare the two (they give the same counts and byte-identical bins)."""
    return os.environ.get("GYROSTAND_PER_FRAME", "") not in ("", "0")


def replay(messages: Iterable[can.Message] | str | Path | Sequence[str | Path],
           ingest: Ingest, listeners: Sequence[can.Listener] = (), *,
           realtime: bool = False, speed: float = 1.0, pump_every: int | None = None,
           parallel: bool | None = None, damage: LogDamage | None = None,
           arrays: bool | None = None) -> Iterator[list[Bin]]:
    """Feed frames (or the frames of a log file, or of several read one after the other)
    to ``ingest.listener`` and ``listeners``; yield the bins that close, batch by batch,
    and at the end the flushed last bins.

    ``pump_every`` frames between pumps (None: :data:`FILE_PUMP` for log files replayed
    as fast as possible, every path alike, else :data:`PUMP`), at most what the listener's FIFO always holds
    (:meth:`~gyrostand.can.receive.listener.DecodingListener.frames_that_fit`): a replay never
    overflows it, whatever ``sampling.buffer`` is. ``parallel``: parse log files in a
    reader process (None: when they total at least :data:`PARALLEL_MIN_BYTES` and this
    process may use two CPUs or more; never with ``realtime`` or extra ``listeners``,
    which take :class:`can.Message` objects; None also when every file is a BLF read as
    ``arrays``, whose parse is cheaper than a process). ``damage`` receives what reading the
    log files skipped (:class:`~gyrostand.can.logs.read.LogDamage`). ``arrays``: log
    files are read as arrays (BLF containers parsed whole,
    :func:`~gyrostand.can.logs.read.read_log_arrays`) and received through
    :meth:`~gyrostand.can.receive.listener.DecodingListener.receive_arrays`, in this process or the
    reader process (None: unless :func:`per_frame_forced`; never with ``realtime`` or
    extra ``listeners``); the bins, counts and rejections are the same either way.
    """
    damage = damage if damage is not None else LogDamage()
    paths: list[Path] | None = None
    if isinstance(messages, (str, Path)):
        paths = [Path(messages)]
    elif isinstance(messages, (list, tuple)) and messages and all(
            isinstance(p, (str, Path)) for p in messages):
        paths = [Path(p) for p in messages]
    if pump_every is None:
        pump_every = FILE_PUMP if paths is not None and not realtime else PUMP
    # back-pressure: pump before the listener's FIFO can overflow (a replay never drops)
    pump_every = max(1, min(int(pump_every), ingest.listener.frames_that_fit()))
    vector = not per_frame_forced() if arrays is None else bool(arrays)
    if paths is not None and not realtime and not listeners:
        # BLF read as arrays costs ~0.1 us a frame: a reader process would cost more
        # (its start, the pipe) than it saves; other formats still pay off in one
        blf_arrays = vector and all(p.suffix.lower() == ".blf" for p in paths)
        if parallel or (parallel is None and not blf_arrays and _cores() >= 2 and sum(
                p.stat().st_size for p in paths if p.is_file()) >= PARALLEL_MIN_BYTES):
            yield from _replay_parallel(paths, ingest, pump_every, damage, vector)
            return
        if vector:
            yield from _replay_arrays(paths, ingest, pump_every, damage)
            return
    frames: Iterable[can.Message] = (read_logs(paths, damage) if paths is not None
                                     else messages)  # type: ignore[assignment]
    if realtime:
        frames = paced(frames, speed)
    receivers = [ingest.listener.on_message_received]
    receivers += [lst.on_message_received for lst in listeners]
    n = 0
    for msg in frames:
        for receive in receivers:
            receive(msg)
        n += 1
        if n % pump_every == 0:
            bins = ingest.pump()
            if bins:
                yield bins
    bins = ingest.finish()
    if bins:
        yield bins
    log.info("replayed %d frames", n)


def _cores() -> int:
    """CPUs this process may run on (a reader process only pays off with two or more)."""
    return usable_cpus()


def _receive_and_pump(batches: Iterable[Any], receive: Callable[[Any], None],
                      ingest: Ingest, pump_every: int) -> Generator[list[Bin], None, int]:
    """Receive each batch of frames, and pump the ingest after every full one (a short
    batch is the last: the caller's ``finish()`` pumps it), as the serial loop pumps every
    ``pump_every`` frames; returns the number of frames received."""
    n = 0
    for frames in batches:
        receive(frames)
        n += len(frames)
        if len(frames) == pump_every:
            bins = ingest.pump()
            if bins:
                yield bins
    return n


def _replay_arrays(paths: list[Path], ingest: Ingest, pump_every: int,
                   damage: LogDamage) -> Iterator[list[Bin]]:
    """:func:`replay` of log files read as arrays in this process: batches of
    ``pump_every`` frames, each received then pumped, as the serial loop pumps."""
    n = yield from _receive_and_pump(array_batches(read_logs_arrays(paths, damage),
                                                   pump_every),
                                     ingest.listener.receive_arrays, ingest, pump_every)
    bins = ingest.finish()
    if bins:
        yield bins
    log.info("replayed %d frames (read as arrays)", n)


def _replay_parallel(paths: list[Path], ingest: Ingest, pump_every: int,
                     damage: LogDamage, arrays: bool = False) -> Iterator[list[Bin]]:
    """:func:`replay` of log files parsed by a reader process: batches of ``pump_every``
    frames, each received then pumped, as the serial loop pumps every ``pump_every``."""
    reader = ReaderProcess(paths, batch=pump_every, arrays=arrays)
    receive = ingest.listener.receive_arrays if arrays else ingest.listener.receive_frames
    try:
        yield from _receive_and_pump(reader, receive, ingest, pump_every)
    finally:
        damage.add(reader.damage.as_dict())
    bins = ingest.finish()
    if bins:
        yield bins
    log.info("replayed %d frames (log parsed in a reader process)", reader.frames)
