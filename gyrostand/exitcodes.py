"""The exit status of every ``gyrostand`` command: BSD ``sysexits.h`` numbers.

* 0 ``OK``: the command did what it was asked;
* 64 ``USAGE``: the command line is wrong (argparse's errors, bad option values or
  combinations);
* 65 ``DATAERR``: the input data are bad: a log that decodes nothing, a damaged file that
  cannot be read, data an identifier cannot fit;
* 66 ``NOINPUT``: an input file or folder is missing or unreadable;
* 69 ``UNAVAILABLE``: the CAN bus cannot be opened (or stays lost), no frame on it; an
  optional package the command needs is not installed;
* 70 ``SOFTWARE``: an internal error (an uncaught exception: a bug, please report it);
* 73 ``CANTCREAT``: an output file or folder cannot be created (no permission, a file
  where a folder should be, an existing file without ``--force``);
* 74 ``IOERR``: a write failed: disk full, file too large, I/O error, the run folder
  removed while written; or frames received were lost before they were binned (the
  decoded-sample buffer, ``sampling.buffer``, overflowed): the run went on and ended,
  its folder is complete but for those samples;
* 78 ``CONFIG``: the session file, its DBC or its mapping is wrong; ``run --check``
  refuses it;
* 130: Ctrl-C (128 + SIGINT, the shell's convention).

No command exits 1 today: 1 is kept for a command whose answer is negative by design (a
check that ran and says no); Python's own exit on an uncaught exception is mapped to 70.
A daemon under systemd is not restarted after 64, 65, 66 or 78
(``RestartPreventExitStatus=`` in ``deploy/gyrostand@.service``): restarting cannot help.

Errors map to a status by their class (:func:`exit_status`), one place for every command.
"""

from __future__ import annotations

import errno

from .errors import (
    BusUnavailableError,
    CanEdgeError,
    ConfigError,
    DataError,
    GyrostandError,
    IdentificationError,
    LogError,
    MissingPackageError,
    ModelError,
    NoInputError,
    OutputError,
    UsageError,
)

__all__ = ["OK", "NEGATIVE", "USAGE", "DATAERR", "NOINPUT", "UNAVAILABLE", "SOFTWARE",
           "CANTCREAT", "IOERR", "CONFIG", "INTERRUPTED", "MEANING", "NO_RESTART",
           "exit_status", "os_error_status"]

#: the command did what it was asked
OK = 0
#: the command ran and its answer is negative (reserved: no command uses it today)
NEGATIVE = 1
#: the command line is wrong: an unknown option, a bad value, a bad combination
USAGE = 64
#: the input data are bad: nothing decoded, a damaged file, data no identifier can fit
DATAERR = 65
#: an input file or folder is missing or unreadable
NOINPUT = 66
#: the CAN bus cannot be opened, or is lost for good, or carries no frame; an optional
#: package the command needs is missing
UNAVAILABLE = 69
#: an internal error (an uncaught exception)
SOFTWARE = 70
#: an output file or folder cannot be created
CANTCREAT = 73
#: a write failed: disk full, file too large, I/O error, folder removed mid-run; or
#: frames received were lost before they were binned (the sample buffer overflowed)
IOERR = 74
#: the session file, its DBC or its mapping is wrong (``run --check`` refuses it)
CONFIG = 78
#: interrupted by Ctrl-C (128 + SIGINT)
INTERRUPTED = 130

#: code -> (name, one-line meaning), in ``gyrostand --help``'s order
MEANING: dict[int, tuple[str, str]] = {
    OK: ("OK", "done"),
    USAGE: ("USAGE", "the command line is wrong"),
    DATAERR: ("DATAERR", "bad input data (nothing decoded, a damaged file)"),
    NOINPUT: ("NOINPUT", "an input file or folder is missing or unreadable"),
    UNAVAILABLE: ("UNAVAILABLE", "the CAN bus cannot be opened or is lost; a package "
                                 "the command needs is missing"),
    SOFTWARE: ("SOFTWARE", "internal error (a bug: please report it)"),
    CANTCREAT: ("CANTCREAT", "an output file or folder cannot be created"),
    IOERR: ("IOERR", "a write failed (disk full, I/O error, folder removed), "
                     "or received frames were lost (sample buffer full)"),
    CONFIG: ("CONFIG", "the session file, DBC or mapping is wrong"),
    INTERRUPTED: ("INTERRUPTED", "interrupted (Ctrl-C)"),
}

#: the codes after which a service restart cannot help (systemd's
#: ``RestartPreventExitStatus=``)
NO_RESTART = (USAGE, DATAERR, NOINPUT, CONFIG)

#: what a failed write says of the machine, not of the command: a failed write (74)
#: rather than an output that cannot be created (73)
_WRITE_FAILED = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO,
                           errno.ENOENT, errno.ESTALE})
#: an OSError of these on an input: it is missing or unreadable
_NO_INPUT = frozenset({errno.ENOENT, errno.EACCES, errno.EPERM, errno.EISDIR,
                       errno.ENOTDIR})


def os_error_status(exc: OSError) -> int:
    """An :class:`OSError` the command did not turn into a gyrostand error: a file it
    cannot read (66) or one it cannot write (74)."""
    return NOINPUT if exc.errno in _NO_INPUT else IOERR


def exit_status(exc: BaseException) -> int:
    """The exit status for ``exc``, by its class (the first that matches, most specific
    first): :class:`UsageError` 64, :class:`NoInputError` 66,
    :class:`BusUnavailableError` and :class:`MissingPackageError` 69, :class:`OutputError` 74 for a failed write (disk
    full, I/O error, folder removed) else 73, :class:`ConfigError` 78, :class:`ModelError`
    64 (a model on the command line; a session file's is a ConfigError),
    :class:`DataError` / :class:`IdentificationError` / :class:`LogError` 65, any other
    :class:`CanEdgeError` 78 (a DBC or mapping problem), any other GyrostandError 65,
    :class:`OSError` 66 / 74 (:func:`os_error_status`), ``KeyboardInterrupt`` 130, any
    other exception 70."""
    if isinstance(exc, UsageError):
        return USAGE
    if isinstance(exc, NoInputError):
        return NOINPUT
    if isinstance(exc, BusUnavailableError | MissingPackageError):
        return UNAVAILABLE
    if isinstance(exc, OutputError):
        cause = exc.__cause__
        failed = isinstance(cause, OSError) and cause.errno in _WRITE_FAILED
        return IOERR if failed else CANTCREAT
    if isinstance(exc, ConfigError):
        return CONFIG
    if isinstance(exc, ModelError):
        return USAGE
    if isinstance(exc, DataError | IdentificationError | LogError):
        return DATAERR
    if isinstance(exc, CanEdgeError):
        return CONFIG
    if isinstance(exc, GyrostandError):
        return DATAERR
    if isinstance(exc, OSError):
        return os_error_status(exc)
    if isinstance(exc, KeyboardInterrupt):
        return INTERRUPTED
    return SOFTWARE
