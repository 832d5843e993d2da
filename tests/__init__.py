"""The test suite. Importing it first pins the machine-dependent numerics before numpy
loads, as importing :mod:`gyrostand` does for every process (gyrostand/numerics.py), so
that results to the last digit, which the golden files and the byte-identical replay checks
compare, do not depend on which x86 CPU runs the suite nor on the process.
"""

from gyrostand.numerics import cpu_flags as cpu_flags  # importing gyrostand pins them

__all__ = ["cpu_flags"]
