"""Progress of long commands (replay, diagnose, report, ...) on stderr.

On a terminal each stage shows a tqdm bar: with a total, the count, rate and ETA
(``replay: stream: 40% 4.1M/10.2M bytes [00:02<00:03]``); without one, the count and rate,
or the time elapsed, redrawn every half second so a long stage never looks stuck.
Elsewhere (a pipe, a file, a service's journal) and with ``-q/--quiet``, nothing: the
command's result and its errors are what it prints there (issue 27). Nothing is printed
per frame: a stage is updated by its caller once per batch (the daemon's hot path never
sees it).

    with progress.stage("replay", "stream", unit="bins") as bar:
        for batch in work:
            ...
            bar.update(len(batch))

Library code calls :func:`stage`; only the CLI turns it on (:func:`configure`), so tests
and scripts that import gyrostand print nothing. :attr:`Stage.lines` says whether a
stage's bar is drawn (a caller may skip work that only feeds it).
"""

from __future__ import annotations

import shutil
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import IO, Any

__all__ = ["configure", "drawing", "stage", "Stage"]

_state: dict[str, Any] = {"on": False, "quiet": False, "stream": None}


def configure(*, on: bool = True, quiet: bool = False, stream: IO[str] | None = None) -> None:
    """Turn progress on for this process (the CLI does); ``quiet``: no bars either."""
    _state.update(on=on, quiet=quiet, stream=stream)


def drawing() -> bool:
    """Whether a stage started now draws a bar (progress on, not quiet, a terminal): a
    caller may skip work that only feeds one (e.g. reading a log's time span)."""
    return bool(_state["on"] and not _state["quiet"] and _is_terminal(_stream()))


def _stream() -> IO[str]:
    return _state["stream"] or sys.stderr


def _is_terminal(stream: IO[str]) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


class Stage:
    """One stage's counter: :meth:`update` by a batch; a bar on a terminal (with progress
    on and not quiet), else silent."""

    #: seconds between redraws of a bar whose caller has not updated it
    TICK = 0.5

    def __init__(self, command: str, name: str, total: float | None, unit: str) -> None:
        self.command, self.name, self.total, self.unit = command, name, total, unit
        self.n: float = 0  # an int while every update is one (tqdm prints it so)
        self._t0 = time.perf_counter()
        self._bar: Any = None
        self._stop = threading.Event()
        stream = _stream()
        if drawing():
            try:
                from tqdm import tqdm
            except ImportError:  # no tqdm: silent
                tqdm = None
            if tqdm is not None:  # the terminal's size; 80x24 where it reports 0x0 (tqdm
                size = shutil.get_terminal_size((80, 24))  # hides bars below row 0)
                fmt = {} if unit else {"bar_format": "{desc} [{elapsed}]"}
                self._bar = tqdm(total=total, unit=f" {unit}", **fmt,
                                 desc=f"{command}: {name}", file=stream, leave=True,
                                 ncols=min(size.columns or 80, 120),
                                 nrows=size.lines or 24, mininterval=0.2,
                                 unit_scale=unit == "bytes")
                threading.Thread(target=self._tick, daemon=True,
                                 name=f"progress-{name}").start()

    @property
    def lines(self) -> bool:
        """Whether this stage draws anything."""
        return self._bar is not None

    def _tick(self) -> None:
        """Redraw the bar (its elapsed time, its ETA) while its caller is busy."""
        while not self._stop.wait(self.TICK):
            bar = self._bar
            if bar is None:
                return
            try:
                bar.refresh()
            except (ValueError, OSError):  # the terminal went away
                return

    def update_to(self, n: float) -> None:
        """Set the count to ``n`` (e.g. the seconds of a log read so far)."""
        if n > self.n:
            self.update(n - self.n)

    def update(self, n: float = 1) -> None:
        self.n += n
        if self._bar is not None:
            self._bar.update(n)

    def close(self, failed: bool = False) -> None:
        self._stop.set()
        if self._bar is not None:
            self._bar.close()
            self._bar = None


@contextmanager
def stage(command: str, name: str, *, total: float | None = None,
          unit: str = "") -> Iterator[Stage]:
    """A stage of ``command`` (see the module docstring); its line or bar ends with it."""
    st = Stage(command, name, total, unit)
    failed = True
    try:
        yield st
        failed = False
    finally:
        st.close(failed)
