"""Kernels compiled in a second process while the command compiles and runs its own
(issue 25: the first run after an install).

A fresh install has no compiled kernels: ``diagnose``'s first run compiled ``kf_run``
(2.7 s), then ``score_run`` (2.1 s), ``rts_forward`` (1.3 s) and ``rts_backward`` (0.7 s)
one after the other, each when first called, on one core (numba's compiler runs under
the GIL). When :func:`start` finds ML's score or the smoother missing from numba's cache,
a child process (``python -m gyrostand.core.prewarm NAME ...``) compiles them on the
other core with the argument types the command will call them with (each module's
``warm``), into the same cache, while the command compiles the filter; the command, at
its first call of one (:func:`~gyrostand.core.jit.ready`), waits for the child's report
and loads it from the cache. A kernel already cached costs one index read and starts no
process; a child that fails only means the command compiles the kernel itself.
Measured (``benchmarks/first_run.py``): an empty-cache ``diagnose`` 11.5 → 7.7 s wall.

The filter, ML's score and the smoother allocate nothing themselves (the LKF's pass, called
once a bin on a stand, still allocates its few work arrays: allocating them in Python at
each call would add a few µs to a bin that costs about 10 µs); their callers pass every
output and work array:
``kalman.kf_work``, ``rts.forward_work``, ``score.score_work``. numba compiled each
``np.zeros``/``np.empty``/``np.ones`` of a kernel for its own rank, and the filter's block
product its own output. Compiles in a fresh process: ``kf_run`` 2.7 → 1.6 s, ``score_run``
2.0 → 1.3 s, ``rts_forward`` 0.92 → 0.77 s; an empty-cache ``diagnose`` 5.1 → 4.0 s wall
(session 21, the same outputs to the bit).
"""

from __future__ import annotations

import subprocess
import sys
import threading
from collections.abc import Iterable
from types import ModuleType

from . import aot, jit, rts
from .ml import score

__all__ = ["KERNELS", "start"]

#: kernel name (as :func:`~gyrostand.core.jit.ready` knows it) → its module (``KERNELS``:
#: its numba dispatchers; ``warm()``: a call compiling them with the command's types)
KERNELS: dict[str, ModuleType] = {"score_run": score, "rts": rts}


def _cached(name: str) -> bool:
    """Whether numba's cache holds every dispatcher of kernel ``name`` for this source
    (its index names a compiled version), or the kernels compiled at install serve them
    (:mod:`.aot`); unknown: treated as cached."""
    if aot.built() is not None:
        return True
    for disp in KERNELS[name].KERNELS:
        if disp.signatures:  # compiled (or loaded) in this process already
            continue
        try:
            if not disp._cache._cache_file._load_index():
                return False
        except Exception:  # noqa: BLE001 - numba's cache internals moved: compile as before
            continue
    return True


def start(names: Iterable[str]) -> list[str]:
    """Compile the kernels ``names`` that numba's cache lacks in a child process; returns
    those it compiles (empty: every one cached, no process). Call once, early."""
    missing = [n for n in names if not jit.expecting(n) and not _cached(n)]
    if not missing:
        return []
    try:
        child = subprocess.Popen(
            [sys.executable, "-m", "gyrostand.core.prewarm", *missing],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL,
            text=True)  # this process's environment: the same NUMBA_CACHE_DIR
    except OSError:
        return []
    events = jit.expect(missing)

    def follow() -> None:
        assert child.stdout is not None
        for line in child.stdout:
            word = line.split()
            if len(word) == 2 and word[0] == "ready" and word[1] in events:
                events[word[1]].set()
        child.wait()
        for ev in events.values():  # the child is gone: nobody waits any longer
            ev.set()

    threading.Thread(target=follow, name="prewarm", daemon=True).start()
    return missing


def main(argv: list[str]) -> int:
    """The child: compile each named kernel, then report it on stdout (``ready NAME``)."""
    for name in argv:
        if name in KERNELS:
            KERNELS[name].warm()
            print(f"ready {name}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
