"""How many threads a stage of the numerics may run on: the CPUs this process may use,
and a pool's width (one thread inside a worker thread: a Dask task, a candidate refit,
already has its core)."""

from __future__ import annotations

import os
import threading

__all__ = ["pool_width", "usable_cpus"]


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
