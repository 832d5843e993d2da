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
