"""Options, printing and argument types shared by the subcommands: the bus options, the
output format (``--format text|json|html``, ``--json``), argument types."""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TextIO

from ..advice import invocation
from ..report import FORMATS

if TYPE_CHECKING:
    from ..config import SessionConfig
    from ..session.pipeline import RunOutcome

#: the python-can command-line options (``can.logger``, ``can.player``, ``can.viewer``)
#: and the ``can.Bus`` argument each one sets
BUS_OPTIONS = {"interface": "interface", "channel": "channel", "bitrate": "bitrate",
               "fd": "fd", "data_bitrate": "data_bitrate", "app_name": "app_name"}


def _bus_kwarg(text: str) -> tuple[str, Any]:
    from ..can.busconfig import parse_bus_kwarg

    try:
        return parse_bus_kwarg(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_bus_args(p: Any) -> None:
    """``-i/--interface``, ``-c/--channel``, ``-b/--bitrate``, ``--fd``, ``--data-bitrate``,
    ``--bus-kwargs KEY=VALUE...`` and ``--app-name`` as python-can's own tools spell them;
    each one given replaces that key of the session's ``bus:``; a key given nowhere comes
    from python-can's config (:mod:`gyrostand.can.busconfig`)."""
    g = p.add_argument_group(
        "bus (python-can's options; each one given overrides that key of the session's "
        "bus:, which overrides python-can's config: ~/.canrc, CAN_INTERFACE, ...)")
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
    g.add_argument("--bus-kwargs", dest="bus_kwargs", nargs="+", type=_bus_kwarg,
                   default=None, metavar="KEY=VALUE",
                   help="more can.Bus arguments, typed as python-can types them (500000 an "
                        "int, true a bool), e.g. --bus-kwargs serial=1234 "
                        "receive_own_messages=true")
    g.add_argument("--app-name", dest="app_name", default=None, metavar="NAME",
                   help="application name of the interface's driver configuration "
                        "(vector: the app_name in Vector Hardware Config)")


def bus_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The ``can.Bus`` arguments given on the command line (only those given): the
    ``--bus-kwargs``, then the options (as python-can's tools apply them, ``--bus-kwargs``
    would win; an option and a ``--bus-kwargs`` of one key are refused as ambiguous)."""
    options = {key: getattr(args, opt) for opt, key in BUS_OPTIONS.items()
               if getattr(args, opt, None) is not None}
    extra = dict(getattr(args, "bus_kwargs", None) or [])
    both = sorted(set(options) & set(extra))
    if both:
        from ..errors import UsageError

        raise UsageError(f"--bus-kwargs: {both[0]} is also given by its own option "
                         f"(--{both[0].replace('_', '-')}); give it once")
    return {**extra, **options}


def with_bus_overrides(cfg: SessionConfig, args: argparse.Namespace) -> SessionConfig:
    """``cfg`` with its bus resolved: the command line's bus options over the session's
    ``bus:`` over python-can's config, and where each key came from (``cfg.bus_sources``).
    A ConfigError when no source names an interface."""
    from ..can.busconfig import resolve_bus
    from ..errors import ConfigError

    bus = resolve_bus(cfg.bus, bus_overrides(args))
    if bus.values.get("interface") in (None, ""):
        raise ConfigError(
            f"{cfg.path}: bus.interface: not given: set it in the session file's bus:, with "
            f"-i/--interface, or in python-can's config (~/.canrc: [default] interface = "
            f"virtual; or env CAN_INTERFACE)")
    return dataclasses.replace(cfg, bus=bus.values, bus_sources=bus.sources)


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


def workbench_command(args: argparse.Namespace, command: str,
                      skip: tuple[str, ...] = ()) -> str:
    """``command`` (e.g. ``fit``) on the data ``args`` names, as a line to paste: the
    real path and the same ``--config``/``--gyro``/``--model``/``--unit``/``--dt``
    options (less those in ``skip``, e.g. ``model`` for the step after a fit, whose
    model the ledger holds)."""
    import shlex

    parts = [invocation(), command, shlex.quote(str(args.run))]
    for opt in ("config", "gyro", "model", "unit", "dt"):
        value = None if opt in skip else getattr(args, opt, None)
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
    anything else is a usage error naming the argument (exit status 64)."""
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


def fault_status(outcome: RunOutcome) -> int:
    """The exit status of a run that ended in ``fault``: the bus lost for good (69), else
    a write that failed (74: disk full, folder removed)."""
    from .. import exitcodes

    if outcome.stop_reason.startswith("bus failure"):
        return exitcodes.UNAVAILABLE
    return exitcodes.IOERR


def decoded_nothing(outcome: RunOutcome, cfg: SessionConfig, what: str) -> str | None:
    """Why a run (``what``: ``replay``, ``run``) that decoded no frame measured nothing,
    in one line (the frames received, why each was not decoded, the mapped messages, the
    ids seen most often, the run folder, which is kept); None when it decoded a frame."""
    dec = outcome.stats.get("decoder", {})
    if dec.get("decoded", 0):
        return None
    kept = f"the run folder is kept: {outcome.run_dir}"
    n = dec.get("received", 0)
    if not n:
        where = "in the log" if what == "replay" else "received on the bus"
        return f"{what}: no CAN frame {where}, nothing measured; {kept}"
    why = [f"{k} {v:,}" for k, v in dec.get("rejected", {}).items() if v]
    if dec.get("ignored"):
        why.insert(0, f"ignored {dec['ignored']:,} (DBC messages no channel maps)")
    refs = {c.signal.message.key: c.signal.message
            for g in cfg.gyros for c in (g.drift, g.temperature)}
    mapped = ", ".join(f"{m.name} 0x{m.frame_id:X}" for m in refs.values())
    seen = ", ".join(f"{i} ({c:,} frames)"
                     for i, c in list(dec.get("unknown_ids", {}).items())[:5])
    return (f"{what} decoded none of {n:,} frames ({', '.join(why)}); the mapped messages "
            f"are {mapped}" + (f"; ids seen most: {seen}" if seen else "") + f"; {kept}")


def lost_received(outcome: RunOutcome, cfg: SessionConfig, what: str) -> str | None:
    """Why a run (``what``: ``replay``, ``run``) lost frames it had received, in one line:
    decoded samples dropped because the sample buffer was full (``overflow``); None when
    it lost none. The run's folder is complete but for those samples."""
    dec = outcome.stats.get("decoder", {})
    n = dec.get("rejected", {}).get("overflow", 0)
    if not n:
        return None
    return (f"{what} lost {n:,} of {dec.get('received', 0):,} received frames: decoded "
            f"samples dropped because the sample buffer (sampling.buffer = "
            f"{cfg.sampling.buffer:,}) was full; their bins lack them (run.log has when); "
            f"a larger sampling.buffer keeps them; the run folder is kept: {outcome.run_dir}")


def whole(minimum: int = 0) -> Callable[[str], int]:
    """An argparse ``type``: a whole number >= ``minimum``; anything else is a usage error
    naming the argument (exit status 64)."""
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
