"""Pin the machine-dependent numerics before numpy loads, so that a fit gives the same
numbers to the last digit in every process on a machine, and on every x86 CPU with AVX2
and FMA (every x86-64 server of the last decade):

* OpenBLAS picks its kernels by CPU (measured: the golden files made on an AVX-512 Intel
  machine, SkylakeX kernels, differed in the last digits on an AMD EPYC, Haswell kernels,
  in 12 of 16 outputs, and matched again with ``OPENBLAS_CORETYPE=SkylakeX``);
* numpy dispatches its loops (exp, log, reductions) to AVX-512 where the CPU has it.

Last digits decide where the search ends on a flat likelihood: ten minutes of a near-white
drift (tests/session/test_online_band.py) gave β̂ 0.077 ("the likelihood is flat") with
SkylakeX kernels and AVX-512 loops, 0.0995 with Haswell kernels only and 5.0 (β at its
upper search bound) with both pinned — the test suite pinned them, the command line did
not (#24 item 6). Importing :mod:`gyrostand` now pins them: OpenBLAS's Haswell kernels
and numpy's AVX2 loops. A value the user set is kept; other CPUs run as they are; a process
that imported numpy before gyrostand keeps what numpy chose (too late to pin).
"""

from __future__ import annotations

import os
import sys

__all__ = ["cpu_flags", "pin_numerics"]


def cpu_flags() -> set[str]:
    """The CPU's feature flags from /proc/cpuinfo (empty where there is none)."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def pin_numerics() -> bool:
    """Set ``OPENBLAS_CORETYPE=Haswell`` (and on AVX-512 CPUs
    ``NPY_DISABLE_CPU_FEATURES``) unless set already; False when numpy is already loaded
    (too late: the libraries chose) or the CPU lacks AVX2+FMA."""
    if "numpy" in sys.modules:
        return False
    flags = cpu_flags()
    if not {"avx2", "fma"} <= flags:
        return False
    os.environ.setdefault("OPENBLAS_CORETYPE", "Haswell")
    if "avx512f" in flags:
        os.environ.setdefault("NPY_DISABLE_CPU_FEATURES", "X86_V4 AVX512_ICL AVX512_SPR")
    return True
