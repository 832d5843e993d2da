"""Replay of recorded logs through the live receive path.

:func:`read_log` opens anything :class:`can.LogReader` reads (``.blf``, ``.asc``, ``.csv``,
candump ``.log``, ``.trc``, ``.mf4`` when asammdf is installed); ASC is read with absolute
timestamps (note: python-can 4.6's ASC *writer* prints the start time's milliseconds
unpadded, so ASC files it wrote can be off by up to 0.99 s in absolute time; BLF is exact). :func:`replay` hands each frame to the very listeners a live run attaches to
its Notifier and pumps the same :class:`~gyrostand.can.ingest.Ingest`, so a log gives the
bins the live run gave. All timing comes from frame timestamps; ``realtime=True`` only
paces delivery (sleeping to frame time / ``speed``), it never changes the data.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path

import can

from gyrostand.can.binning import Bin
from gyrostand.can.ingest import Ingest
from gyrostand.errors import CanEdgeError

__all__ = ["read_log", "read_logs", "paced", "replay"]

log = logging.getLogger(__name__)


def read_log(path: str | Path) -> Iterator[can.Message]:
    """Frames of a log file, in file order. Raises :class:`CanEdgeError` naming the file.

    A BLF whose last object is torn (the recording process was killed while appending, or
    the disk filled up) is read up to the tear, with a warning: python-can's reader
    raises there, after the last complete frame. Damage anywhere else is an error.
    """
    path = Path(path)
    if not path.is_file():
        raise CanEdgeError(f"{path}: log file not found")
    kwargs = {"relative_timestamp": False} if path.suffix.lower() == ".asc" else {}
    try:
        reader = can.LogReader(path, **kwargs)
    except Exception as exc:
        raise CanEdgeError(f"{path}: cannot read CAN log: {exc}") from exc
    try:
        yield from reader
    except Exception as exc:
        f = getattr(reader, "file", None)
        try:
            at_end = f is not None and not f.closed and f.tell() >= path.stat().st_size
        except (OSError, ValueError):
            at_end = False
        if not (at_end and path.suffix.lower() == ".blf"):
            raise CanEdgeError(f"{path}: corrupt CAN log: {exc}") from exc
        log.warning("%s: torn last object ignored (the recording stopped while writing "
                    "it): %s", path, exc or type(exc).__name__)
    finally:
        reader.stop()


def read_logs(paths: Iterable[str | Path]) -> Iterator[can.Message]:
    """The frames of several logs (e.g. a resumed run's segments), one after the other."""
    for p in paths:
        yield from read_log(p)


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


def replay(messages: Iterable[can.Message] | str | Path, ingest: Ingest,
           listeners: Sequence[can.Listener] = (), *, realtime: bool = False,
           speed: float = 1.0, pump_every: int = 1024) -> Iterator[list[Bin]]:
    """Feed frames (or a log file's frames) to ``ingest.listener`` and ``listeners``;
    yield the bins that close, batch by batch, and at the end the flushed last bins.

    ``pump_every`` frames between pumps; the listener's FIFO must hold that many frames'
    samples (the default fits the default capacity).
    """
    if isinstance(messages, (str, Path)):
        messages = read_log(messages)
    if realtime:
        messages = paced(messages, speed)
    receivers = [ingest.listener.on_message_received]
    receivers += [lst.on_message_received for lst in listeners]
    n = 0
    for msg in messages:
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
