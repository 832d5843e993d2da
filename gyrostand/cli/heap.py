"""The C heap of a workbench command: large temporary arrays reused, not mapped afresh.

A 6-h run's series are 21,600 doubles (173 kB), above glibc's initial mmap threshold
(128 kB): each temporary array of a fit (a filter's input, a regressor, a replicate of
the model error) is then a fresh ``mmap`` whose pages fault in one by one and an
``munmap`` when freed. ``gyrostand diagnose`` on a 6-h run took 166,000 page faults to
``identify``'s 30,000, 0.4 s more of system CPU (``benchmarks/diagnose_speed.py``).
:func:`keep_heap` raises the mmap threshold to :data:`MMAP_THRESHOLD` and the heap's
trim threshold to :data:`TRIM_THRESHOLD` (glibc's ``mallopt``; what ``MALLOC_MMAP_THRESHOLD_``
and ``MALLOC_TRIM_THRESHOLD_`` set before a process starts), so freed arrays are reused
from the heap. Only the batch commands of :data:`COMMANDS` ask for it (a daemon's
resident memory stays glibc's default), ``GYROSTAND_HEAP=default`` leaves glibc's
defaults, and where the C library has no ``mallopt`` (musl, macOS, Windows) nothing
changes.
"""

from __future__ import annotations

import ctypes
import os
import sys

__all__ = ["COMMANDS", "MMAP_THRESHOLD", "TRIM_THRESHOLD", "keep_heap"]

#: the commands that fit on a whole record in one go (the daemon ``run`` and ``replay``
#: keep glibc's defaults)
COMMANDS = frozenset({"identify", "diagnose", "fit", "report", "allan", "design", "demo"})
#: allocations from this size on are mapped apart (glibc's default starts at 128 kB)
MMAP_THRESHOLD = 32 << 20
#: free memory at the heap's top kept up to this size before it is returned
TRIM_THRESHOLD = 64 << 20
#: glibc's mallopt parameters
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3


def keep_heap() -> bool:
    """Set the thresholds (see the module); True when the C library took them."""
    if os.environ.get("GYROSTAND_HEAP", "") == "default" or not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # no mallopt in this C library
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and \
        bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
