"""Advice that runs: the commands gyrostand prints for the user to paste (``next:`` lines,
``init``'s hints, the report's next step) name gyrostand as the user invoked it and quote
every path, so each one works pasted as is. Standard library only: any layer above the
core may use it."""

from __future__ import annotations

import os
import shlex
import shutil
import sys
from pathlib import Path

__all__ = ["invocation", "command_line"]


def invocation() -> str:
    """gyrostand as the user ran it, to paste into a printed command: the console script
    as typed (``.venv/bin/gyrostand``, or ``gyrostand`` when it is on PATH), else this
    interpreter with ``-m gyrostand`` (``python -m gyrostand``, a test calling ``main``)."""
    argv0 = sys.argv[0] if sys.argv else ""
    if Path(argv0).name == "gyrostand" and (os.sep in argv0 or shutil.which(argv0)):
        return shlex.quote(argv0)
    return f"{shlex.quote(sys.executable)} -m gyrostand"


def command_line(*words: str | Path) -> str:
    """``gyrostand WORD ...`` as a line to paste: :func:`invocation`, then each word
    shell-quoted (a path with spaces stays one argument)."""
    return " ".join([invocation(), *(shlex.quote(str(w)) for w in words)])
