"""The test suite. Importing it first pins the machine-dependent numerics (before numpy
loads), so that results to the last digit, which the golden files and the byte-identical
replay checks compare, do not depend on which x86 CPU runs the suite:

* OpenBLAS picks its kernels by CPU (measured: the golden files made on an AVX-512 Intel
  machine, SkylakeX kernels, differed in the last digits on an AMD EPYC, Haswell kernels,
  in 12 of 16 outputs, and matched again with ``OPENBLAS_CORETYPE=SkylakeX``);
* numpy dispatches its loops (exp, log, reductions) to AVX-512 where the CPU has it.

With AVX2 and FMA (every x86-64 server of the last decade) the suite runs on OpenBLAS's
Haswell kernels and numpy's X86_V3 (AVX2) loops. A value the user set is kept; other CPUs
run as they are.
"""

import os
import sys


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


def _pin_numerics() -> None:
    if "numpy" in sys.modules:  # too late: the libraries chose already
        return
    flags = cpu_flags()
    if {"avx2", "fma"} <= flags:
        os.environ.setdefault("OPENBLAS_CORETYPE", "Haswell")
        if "avx512f" in flags:
            os.environ.setdefault("NPY_DISABLE_CPU_FEATURES",
                                  "X86_V4 AVX512_ICL AVX512_SPR")


_pin_numerics()
