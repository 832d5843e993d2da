"""Progress of long commands (replay, diagnose, report, ...) on stderr.

On a terminal each stage shows a tqdm bar (a count and rate when the total is unknown);
elsewhere (a pipe, a file, a service's journal) and with ``-q/--quiet``, one line per
finished stage: ``replay: stream: 21,600 bins in 4.2 s``. Nothing is printed per frame:
a stage is updated by its caller once per batch (the daemon's hot path never sees it).

    with progress.stage("replay", "stream", unit="bins") as bar:
        for batch in work:
            ...
            bar.update(len(batch))

Library code calls :func:`stage`; only the CLI turns it on (:func:`configure`), so tests
and scripts that import gyrostand print nothing.
"""

from __future__ import annotations

import shutil
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import IO, Any

__all__ = ["configure", "stage", "Stage"]

_state: dict[str, Any] = {"on": False, "quiet": False, "stream": None}


def configure(*, on: bool = True, quiet: bool = False, stream: IO[str] | None = None) -> None:
    """Turn progress on for this process (the CLI does), ``quiet``: stage lines only."""
    _state.update(on=on, quiet=quiet, stream=stream)


def _stream() -> IO[str]:
    return _state["stream"] or sys.stderr


def _is_terminal(stream: IO[str]) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


class Stage:
    """One stage's counter: :meth:`update` by a batch; a bar on a terminal, else silent
    until the stage ends."""

    def __init__(self, command: str, name: str, total: float | None, unit: str) -> None:
        self.command, self.name, self.total, self.unit = command, name, total, unit
        self.n = 0.0
        self._t0 = time.perf_counter()
        self._bar: Any = None
        stream = _stream()
        if _state["on"] and not _state["quiet"] and _is_terminal(stream):
            try:
                from tqdm import tqdm
            except ImportError:  # no tqdm: stage lines only
                tqdm = None
            if tqdm is not None:  # the terminal's size; 80x24 where it reports 0x0 (tqdm
                size = shutil.get_terminal_size((80, 24))  # hides bars below row 0)
                fmt = {} if unit else {"bar_format": "{desc} [{elapsed}]"}
                self._bar = tqdm(total=total, unit=f" {unit}", **fmt,
                                 desc=f"{command}: {name}", file=stream, leave=True,
                                 ncols=min(size.columns or 80, 120),
                                 nrows=size.lines or 24, mininterval=0.2)

    def update(self, n: float = 1) -> None:
        self.n += n
        if self._bar is not None:
            self._bar.update(n)

    def close(self, failed: bool = False) -> None:
        elapsed = time.perf_counter() - self._t0
        if self._bar is not None:
            self._bar.close()
            return
        if not _state["on"]:
            return
        what = f"{self.n:,.0f} {self.unit} " if self.n else ""
        end = "failed after" if failed else "in"
        print(f"{self.command}: {self.name}: {what}{end} {elapsed:.1f} s", file=_stream(),
              flush=True)


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
