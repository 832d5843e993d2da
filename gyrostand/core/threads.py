"""How many threads a stage of the numerics may run on: the CPUs this process may use,
and a pool's width (one thread inside a worker thread: a Dask task, a candidate refit,
already has its core)."""

from __future__ import annotations

import os
import threading
from typing import Any

__all__ = ["one_blas_thread", "pool_width", "usable_cpus"]


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity where the system has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def pool_width(limit: int) -> int:
    """Threads for independent work items: up to ``limit`` and the usable CPUs in the
    main thread, 1 in any other."""
    if threading.current_thread() is not threading.main_thread():
        return 1
    return max(1, min(usable_cpus(), limit))


_controller: list[Any] = []
_controller_lock = threading.Lock()


def one_blas_thread() -> Any:
    """A context holding BLAS to one thread (the algebra here is on tiny matrices, where
    OpenBLAS's thread hand-offs cost more than the work), through one
    ``threadpoolctl.ThreadpoolController`` made at the first call: ``threadpool_limits``
    scans the process's loaded libraries at each entry (0.15-0.5 ms; ~1 % of a 6-h
    ``diagnose``, whose fits and curvatures enter it a few hundred times). The first
    call comes after numpy's and scipy's BLAS are loaded (ML imports scipy.optimize)."""
    if not _controller:
        from threadpoolctl import ThreadpoolController

        with _controller_lock:
            if not _controller:
                _controller.append(ThreadpoolController())
    return _controller[0].limit(limits=1, user_api="blas")
