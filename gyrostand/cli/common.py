"""Options, printing and argument types shared by the subcommands: the bus options, the
output format (``--format text|json|html``, ``--json``), argument types."""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from collections.abc import Callable
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, TextIO

from ..report import FORMATS

if TYPE_CHECKING:
    from ..config import SessionConfig
    from ..session.pipeline import RunOutcome

#: the python-can command-line options (``can.logger``, ``can.player``, ``can.viewer``)
#: and the ``can.Bus`` argument each one sets
BUS_OPTIONS = {"interface": "interface", "channel": "channel", "bitrate": "bitrate",
               "fd": "fd", "data_bitrate": "data_bitrate"}


def add_bus_args(p: Any) -> None:
    """``-i/--interface``, ``-c/--channel``, ``-b/--bitrate``, ``--fd``, ``--data-bitrate``
    as python-can's own tools spell them; each one given replaces that key of the session's
    ``bus:`` (the other keys are passed to ``can.Bus`` as they are)."""
    g = p.add_argument_group(
        "bus (python-can's options; each one given overrides that key of the session's bus:)")
    g.add_argument("-i", "--interface", default=None, metavar="NAME",
                   help="python-can interface, e.g. socketcan, pcan, vector, kvaser, "
                        "remote, virtual")
    g.add_argument("-c", "--channel", default=None, metavar="CH",
                   help="channel of the interface, e.g. can0, PCAN_USBBUS1, 0, "
                        "ws://127.0.0.1:54701/")
    g.add_argument("-b", "--bitrate", type=int, default=None, metavar="BIT/S",
                   help="nominal bitrate, e.g. 500000")
    g.add_argument("--fd", action="store_true", default=None, help="open the bus in CAN FD mode")
    g.add_argument("--data-bitrate", dest="data_bitrate", type=int, default=None,
                   metavar="BIT/S", help="CAN FD data-phase bitrate, e.g. 2000000")


def bus_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The ``can.Bus`` arguments given on the command line (only those given)."""
    return {key: getattr(args, opt) for opt, key in BUS_OPTIONS.items()
            if getattr(args, opt, None) is not None}


def with_bus_overrides(cfg: SessionConfig, args: argparse.Namespace) -> SessionConfig:
    """``cfg`` with the command line's bus options merged over its ``bus:``."""
    over = bus_overrides(args)
    if not over:
        return cfg
    return dataclasses.replace(cfg, bus=MappingProxyType({**cfg.bus, **over}))


def add_data_format_args(p: Any) -> None:
    """``--data-format FORMAT`` (repeatable): a format the run also writes its samples and
    estimates in at its end, beside the CSVs (adds to the session's ``formats:``)."""
    from ..runfolder.layout import DATA_FORMATS

    p.add_argument("--data-format", action="append", choices=tuple(DATA_FORMATS),
                   default=[], metavar="FORMAT",
                   help="also write the run's data as FORMAT at its end, beside the CSVs "
                        "(which stay): parquet (<gyro>/samples.parquet, estimates.parquet; "
                        "pyarrow) or mf4 (<run>.mf4; asammdf); repeatable; adds to "
                        "session.formats")


def with_data_formats(cfg: SessionConfig, args: argparse.Namespace) -> SessionConfig:
    """``cfg`` with the ``--data-format`` options added to its ``formats``."""
    from ..config.parser import missing_packages
    from ..errors import ConfigError

    extra = [f for f in getattr(args, "data_format", []) if f not in cfg.formats]
    if not extra:
        return cfg
    missing = missing_packages(tuple(extra))
    if missing:
        raise ConfigError(f"--data-format: {missing}")
    return dataclasses.replace(cfg, formats=(*cfg.formats, *extra))


def add_format_args(p: Any, what: str = "the result", default: str = FORMATS[0],
                    verb: str = "print") -> None:
    """``--format text|json|html`` and ``--json``, its synonym."""
    p.add_argument("--format", choices=FORMATS, default=default,
                   help=f"{verb} {what} as text, JSON or an HTML page (default {default})")
    p.add_argument("--json", dest="format", action="store_const", const="json",
                   help="same as --format json")


def emit(obj: Any, format: str, out: TextIO | None = None) -> None:
    """Print ``obj`` rendered in ``format`` (:mod:`gyrostand.report`)."""
    from ..report import render

    (out or sys.stdout).write(render(obj, format))


def invocation() -> str:
    """gyrostand as the user ran it, to paste into a printed command: the console script
    as typed (``.venv/bin/gyrostand``, or ``gyrostand`` when it is on PATH), else this
    interpreter with ``-m gyrostand`` (``python -m gyrostand``, a test calling ``main``)."""
    import os
    import shlex
    import shutil

    argv0 = sys.argv[0] if sys.argv else ""
    if Path(argv0).name == "gyrostand" and (os.sep in argv0 or shutil.which(argv0)):
        return shlex.quote(argv0)
    return f"{shlex.quote(sys.executable)} -m gyrostand"


def workbench_command(args: argparse.Namespace, command: str) -> str:
    """``command`` (e.g. ``fit``) on the data ``args`` names, as a line to paste: the
    real path and the same ``--gyro``/``--model``/``--unit``/``--dt`` options."""
    import shlex

    parts = [invocation(), command, shlex.quote(str(args.run))]
    for opt in ("gyro", "model", "unit", "dt"):
        value = getattr(args, opt, None)
        if value is not None:
            parts += [f"--{opt}", shlex.quote(str(value))]
    return " ".join(parts)


def progress(args: argparse.Namespace) -> TextIO:
    """Where a command's progress lines go: stdout beside a text result, stderr when the
    result is a JSON or HTML document (which stdout then holds alone)."""
    return sys.stdout if getattr(args, "format", "text") == "text" else sys.stderr


def print_outcome(outcome: RunOutcome, out: TextIO,
                  truths: dict[str, dict[str, float]] | None = None,
                  format: str = "text") -> None:
    """The final table of every gyro, the counts, and the paths."""
    from ..report.views import RunSummary

    emit(RunSummary(outcome, truths or {}), format, out)


def number(*, positive: bool = False, nonnegative: bool = False) -> Callable[[str], float]:
    """An argparse ``type``: a finite float (``positive``: > 0; ``nonnegative``: >= 0);
    anything else is a usage error naming the argument (exit status 2)."""
    def parse(text: str) -> float:
        try:
            x = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text[:40]!r}") from None
        if not math.isfinite(x):
            raise argparse.ArgumentTypeError(f"must be finite, got {text[:40]!r}")
        if positive and not x > 0:
            raise argparse.ArgumentTypeError(f"must be > 0, got {text[:40]!r}")
        if nonnegative and x < 0:
            raise argparse.ArgumentTypeError(f"must be >= 0, got {text[:40]!r}")
        return x
    parse.__name__ = "number"
    return parse


def whole(minimum: int = 0) -> Callable[[str], int]:
    """An argparse ``type``: a whole number >= ``minimum``; anything else is a usage error
    naming the argument (exit status 2)."""
    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got "
                                             f"{text[:40]!r}") from None
        if n < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {text[:40]!r}")
        return n
    parse.__name__ = "whole number"
    return parse
