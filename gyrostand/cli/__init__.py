"""The ``gyrostand`` command line: one module per subcommand."""

from __future__ import annotations

import argparse
import faulthandler
import importlib
import logging
import os
import signal
import sys
from collections.abc import Sequence
from typing import Any, NoReturn

from .. import __version__, exitcodes
from ..errors import GyrostandError
from . import heap

#: the subcommands, in ``--help`` order: each is the module of its name here, whose
#: ``add_parser`` adds it (imported when a parser with it is built)
COMMANDS = ("init", "run", "replay", "simulate", "demo", "identify", "diagnose", "fit",
            "adopt", "report", "allan", "export", "design", "batch", "term")
#: commands that are (or start) the daemon: no progress output (its stderr is a journal)
DAEMON_COMMANDS = ("run",)


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser whose usage errors exit 64 (``EX_USAGE``), not argparse's 2;
    the subcommands' parsers are of this class too."""

    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        self.exit(exitcodes.USAGE, f"{self.prog}: error: {message}\n")


def exit_codes_epilog() -> str:
    """The exit-status table of ``gyrostand --help``."""
    rows = [f"  {code:>3}  {meaning}" for code, (_, meaning) in exitcodes.MEANING.items()]
    return ("exit status (BSD sysexits.h; docs/index.md#exit-status):\n"
            + "\n".join(rows))


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The command line's parser: every subcommand, or ``only`` that one (what a command
    line naming it parses to is the same; its module alone is imported and built)."""
    parser = ArgumentParser(
        prog="gyrostand",
        description="CAN-bus field service for gyro thermal test stands.",
        epilog=exit_codes_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"gyrostand {__version__}")
    _add_global_args(parser, argparse.SUPPRESS)
    # with one subcommand built, the usage line still names them all (as an error of the
    # main parser, e.g. an unrecognized argument, prints it)
    sub = parser.add_subparsers(dest="command", required=True, metavar=None if only is None
                                else "{" + ",".join(COMMANDS) + "}")
    for name in COMMANDS if only is None else (only,):
        importlib.import_module(f".{name}", __name__).add_parser(sub)
    for subparser in sub.choices.values():  # `gyrostand run CFG -v` works as `-v run CFG`
        _add_global_args(subparser, argparse.SUPPRESS)
    return parser


def _command_in(argv: Sequence[str]) -> str | None:
    """The subcommand ``argv`` names (its first word not an option, when it is one and
    only the global flags come before it), else None (the whole parser: ``--help``,
    ``--version``, no or an unknown command)."""
    for arg in argv:
        if not arg.startswith("-"):
            return arg if arg in COMMANDS else None
        if arg not in _GLOBAL_FLAGS and not (arg.startswith("-v") and set(arg[1:]) == {"v"}):
            return None
    return None


#: the main parser's options that may come before a subcommand and take no value
_GLOBAL_FLAGS = ("--debug", "-v", "--verbose", "-q", "--quiet")


def _add_global_args(parser: argparse.ArgumentParser, default: Any) -> None:
    """``--debug`` and ``-v``, before or after the subcommand. Each parser counts into its
    own destination (a subparser's namespace replaces the parent's values), suppressed
    when not given; :func:`main` adds them up."""
    g = parser.add_argument_group("global options (before or after the subcommand)")
    g.add_argument("--debug", action="store_true", default=default,
                   dest=f"debug_{id(parser)}", help="show tracebacks on errors")
    g.add_argument("-v", "--verbose", action="count", default=default,
                   dest=f"verbose_{id(parser)}", help="more logging (-vv: debug)")
    g.add_argument("-q", "--quiet", action="store_true", default=default,
                   dest=f"quiet_{id(parser)}",
                   help="no progress bars (off a terminal there are none either)")


def _gather_globals(args: argparse.Namespace) -> None:
    """Sum ``-v`` and OR ``--debug``, ``--quiet`` over the main parser and the
    subcommand's."""
    verbose, debug, quiet = 0, False, False
    for key in [k for k in vars(args) if k.startswith(("verbose_", "debug_", "quiet_"))]:
        value = getattr(args, key)
        delattr(args, key)
        if key.startswith("verbose_"):
            verbose += int(value)
        elif key.startswith("quiet_"):
            quiet = quiet or bool(value)
        else:
            debug = debug or bool(value)
    args.verbose, args.debug, args.quiet = verbose, debug, quiet


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; progress output is on for its duration only (an in-process call,
    e.g. from a test or a script, leaves the library silent afterwards)."""
    from .. import progress

    try:
        return _main(argv)
    finally:
        progress.configure(on=False)


#: BLAS libraries held to one thread in a command's process (read when numpy loads): the
#: algebra is on tiny matrices and 1-D series, where a BLAS thread team costs more than it
#: gives (a ddot of 21,600 values waits for a second core on a loaded machine); the
#: parallel work runs on the commands' own threads (candidate refits, ML evaluations) and
#: processes (replay's reader, batch workers). A value the user set is kept.
_ONE_THREAD = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS")
#: commands whose first run compiles ML's score and the smoother: started in a second
#: process while the command compiles the filter (gyrostand.core.prewarm)
PREWARM_COMMANDS = frozenset({"diagnose", "fit", "report", "demo"})


def _main(argv: Sequence[str] | None = None) -> int:
    if "numpy" not in sys.modules:
        for var in _ONE_THREAD:
            os.environ.setdefault(var, "1")
    parser = build_parser(_command_in(sys.argv[1:] if argv is None else argv))
    args = parser.parse_args(argv)
    _gather_globals(args)
    if hasattr(signal, "SIGUSR1"):  # `kill -USR1 PID`: every thread's stack to stderr
        try:
            faulthandler.register(signal.SIGUSR1, all_threads=True)
        except (ValueError, OSError):  # stderr is no file (io.UnsupportedOperation)
            pass
    from .. import progress  # stdlib only; tqdm is imported when a bar is drawn

    progress.configure(on=args.command not in DAEMON_COMMANDS, quiet=args.quiet)
    if args.command not in DAEMON_COMMANDS:  # a kernel's first-use compilation as a stage
        from .compiling import show_compilations

        show_compilations()
    if args.command in heap.COMMANDS and argv is None:  # a process of its own: see .heap
        heap.keep_heap()
    if args.command in PREWARM_COMMANDS:  # a first run: kernels compiled on the other core
        from ..core import prewarm

        prewarm.start(("score_run", "rts"))
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    for h in logging.getLogger().handlers:  # a run's run.log may lower gyrostand's level
        h.setLevel(level)
    try:
        from ..plugins import load_entry_points

        load_entry_points()  # user terms (entry points gyrostand.terms) before any model
        return int(args.func(args) or 0)
    except GyrostandError as exc:  # the status by the error's kind (gyrostand.exitcodes)
        if args.debug:
            raise
        print(f"error: {exc}", file=sys.stderr)
        return exitcodes.exit_status(exc)
    except BrokenPipeError:  # output piped into e.g. `head`, which closed early
        sys.stderr.close()
        return exitcodes.OK
    except OSError as exc:  # a file or folder the command cannot read or write
        if args.debug:
            raise
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"error: {where}{exc.strerror or exc}", file=sys.stderr)
        return exitcodes.os_error_status(exc)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return exitcodes.INTERRUPTED
    except Exception as exc:  # a bug: one line, the traceback with --debug
        if args.debug:
            raise
        print(f"error: internal error: {type(exc).__name__}: {exc} (rerun with --debug "
              "for the traceback, and please report it)", file=sys.stderr)
        return exitcodes.SOFTWARE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
