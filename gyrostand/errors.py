"""One exception tree for gyrostand.

Every error raised on purpose derives from :class:`GyrostandError` and also from the
standard exception that fits it, so callers may catch either (``except ValueError`` still
works for bad data). Errors from python-can / cantools are wrapped at the CAN edge with
``raise ... from``.
"""

from __future__ import annotations


class GyrostandError(Exception):
    """Root of every error gyrostand raises on purpose."""


class DataError(GyrostandError, ValueError):
    """Input samples that cannot be used: missing columns, NaN, non-monotonic time, ..."""


class ModelError(GyrostandError, ValueError):
    """A model specification that is invalid, or that an identifier cannot represent."""


class IdentificationError(GyrostandError, RuntimeError):
    """An identifier failed to produce an estimate (e.g. the optimiser found no finite point)."""


class ConfigError(GyrostandError, ValueError):
    """A session configuration that is invalid; the message names the key path."""


class CanEdgeError(GyrostandError, RuntimeError):
    """A failure at the CAN edge (bus, DBC, log file), wrapping python-can / cantools errors."""


class OutputError(GyrostandError, OSError):
    """A file of a run that cannot be written (disk full, no permission, not a folder);
    the message names the path."""


# Finer kinds, one exit status each (gyrostand.exitcodes): each also is the kind above it,
# so ``except ConfigError`` / ``except DataError`` / ``except CanEdgeError`` still catch it.


class UsageError(ConfigError):
    """The command line used wrongly: an option's value, or a combination of options,
    that argparse cannot check (exit 64)."""


class NoInputError(DataError):
    """An input file or folder that is missing or cannot be read: a run folder, a log, a
    CSV (exit 66)."""


class LogNotFoundError(NoInputError, CanEdgeError):
    """A CAN log file that does not exist (exit 66)."""


class SessionFileNotFoundError(NoInputError, ConfigError):
    """A session file that does not exist or cannot be read (exit 66)."""


class LogError(CanEdgeError):
    """A CAN log that cannot be read: not a log, a damaged header, a reader that fails
    (exit 65)."""


class BusUnavailableError(CanEdgeError):
    """A CAN bus that cannot be opened, or sent on (exit 69)."""


class MissingPackageError(GyrostandError, ImportError):
    """An optional package a command needs is not installed; the message names the extra
    to install (exit 69)."""
