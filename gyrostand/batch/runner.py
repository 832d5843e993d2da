"""The client side of a batch: connect to a Dask scheduler, skip the runs already done,
submit one task per remaining run, count what comes back.

The client holds the list of runs and each finished run's record (a few kB: its rows),
never a run's frames or samples — those live on the worker that does the run, one run at a
time per worker thread. Workers write the records themselves (:mod:`.tasks`), so they must
see the batch folder (a local cluster does; a real cluster needs it on a shared file
system, as its workers need the archive).

Dask is imported inside the functions: ``import gyrostand.batch.runner`` is cheap.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import GyrostandError, MissingPackageError
from .inputs import RunSpec
from .tasks import RECORD_VERSION, TaskOptions, failed_record, read_record, run_task

__all__ = ["BatchCounts", "connect", "require_dask", "run_batch", "plan"]

log = logging.getLogger(__name__)

INSTALL_HINT = ("gyrostand batch runs on Dask: install it with "
                "pip install 'gyrostand[fleet]' (dask, distributed, pyarrow)")


def require_dask() -> None:
    """A clear error naming the extra to install when Dask is missing."""
    import importlib.util

    for mod in ("dask", "distributed"):
        if importlib.util.find_spec(mod) is None:
            raise MissingPackageError(f"no module {mod!r}: {INSTALL_HINT}")


@dataclass
class BatchCounts:
    """Where the batch is: runs done / failed this time, skipped (done before), left."""

    total: int
    skipped: int = 0
    done: int = 0
    failed: int = 0
    started: float = 0.0

    @property
    def remaining(self) -> int:
        return self.total - self.skipped - self.done - self.failed

    @property
    def rate(self) -> float:
        """Runs per second since the first task was submitted."""
        dt = time.perf_counter() - self.started
        return (self.done + self.failed) / dt if dt > 0 else 0.0


@contextmanager
def connect(scheduler: str = "local", *, workers: int | None = None,
            memory_limit: str | float | None = "auto",
            timeout: float = 30.0) -> Iterator[Any]:
    """A :class:`distributed.Client`: ``"local"`` starts a ``LocalCluster`` on 127.0.0.1
    (``workers`` processes, default one per CPU, one thread each: a run's fits are
    sequential numba loops, so processes, not threads, use the cores), else the address of
    a running scheduler (``tcp://HOST:PORT``). Closed (the local cluster stopped) on exit."""
    require_dask()
    from distributed import Client, LocalCluster

    if scheduler == "local":
        n = workers or os.cpu_count() or 1
        try:
            import bokeh  # noqa: F401 - the dashboard needs it
            dashboard: str | None = "127.0.0.1:0"
        except ImportError:
            dashboard = None
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                               host="127.0.0.1", dashboard_address=dashboard,
                               memory_limit=memory_limit, scheduler_port=0)
        try:
            client = Client(cluster, timeout=timeout)
            try:
                yield client
            finally:
                client.close()
        finally:
            cluster.close()
        return
    if not scheduler.startswith(("tcp://", "tls://", "ucx://", "inproc://")):
        raise GyrostandError(f"--scheduler {scheduler!r}: 'local' or a scheduler address "
                             "such as tcp://127.0.0.1:8786")
    try:
        client = Client(scheduler, timeout=timeout)
    except OSError as exc:
        raise GyrostandError(f"--scheduler {scheduler}: cannot reach the scheduler within "
                             f"{timeout:g} s ({exc})") from None
    try:
        if workers:
            client.wait_for_workers(workers, timeout=timeout)
        yield client
    finally:
        client.close()


def dashboard_link(client: Any) -> str | None:
    """The scheduler's dashboard, when it serves one."""
    try:
        port = client.scheduler_info().get("services", {}).get("dashboard")
        if port is None:
            return None
        from urllib.parse import urlsplit

        host = urlsplit(client.scheduler.address).hostname
        return f"http://{host}:{port}/status"
    except Exception:  # noqa: BLE001 - no link is no link
        return None


def _is_done(rec: dict[str, Any] | None, spec: RunSpec, opts: TaskOptions,
             retry_failed: bool) -> bool:
    if rec is None or rec.get("version") != RECORD_VERSION:
        return False
    was = rec.get("input") or {}
    if rec.get("options") != opts.to_dict() or any(
            was.get(k) != v for k, v in spec.to_dict().items() if k != "attrs"):
        return False  # another model, method, steps, input or session file: redo
    # (the attributes are the manifest's, read again for the table: editing them redoes
    # nothing)
    if rec.get("status") == "failed" and retry_failed:
        return False
    return rec.get("status") in ("ok", "partial", "failed")


def plan(specs: Sequence[RunSpec], opts: TaskOptions, out: str | Path, *,
         force: bool = False, retry_failed: bool = False) -> list[RunSpec]:
    """The runs still to do: all with ``force``, else those without a record made with
    these options (recorded failures too with ``retry_failed``)."""
    if force:
        return list(specs)
    return [s for s in specs
            if not _is_done(read_record(out, s.run), s, opts, retry_failed)]


def run_batch(client: Any, specs: Sequence[RunSpec], opts: TaskOptions, out: str | Path,
              *, force: bool = False, retry_failed: bool = False,
              on_progress: Callable[[BatchCounts, dict[str, Any] | None], None] | None = None
              ) -> BatchCounts:
    """Submit every run still to do to ``client``'s scheduler and wait for all of them;
    ``on_progress(counts, record)`` after each (and once with ``None`` before the first).
    A task Dask loses (its worker died) is recorded as that run's failure."""
    from distributed import as_completed

    out = Path(out).resolve()
    (out / "results").mkdir(parents=True, exist_ok=True)
    todo = plan(specs, opts, out, force=force, retry_failed=retry_failed)
    counts = BatchCounts(total=len(specs), skipped=len(specs) - len(todo),
                         started=time.perf_counter())
    if on_progress:
        on_progress(counts, None)
    if not todo:
        return counts
    stamp = f"{time.time_ns():x}"
    futures = {}
    for spec in todo:
        fut = client.submit(run_task, spec, opts, str(out), pure=False,
                            key=f"gyrostand-run-{spec.run}-{stamp}")
        futures[fut.key] = (fut, spec)
    for fut in as_completed([f for f, _ in futures.values()]):
        spec = futures[fut.key][1]
        if fut.status == "finished":
            rec = fut.result()
            if rec.get("unwritten"):  # the worker could not write it: try from here
                rec = failed_record(spec, opts, out, f"record not written by the worker: "
                                                     f"{rec['unwritten']}")
        else:
            exc = fut.exception()
            rec = failed_record(spec, opts, out, f"task lost: {type(exc).__name__}: {exc}")
        if rec.get("status") == "failed":
            counts.failed += 1
        else:
            counts.done += 1
        fut.release()
        if on_progress:
            on_progress(counts, rec)
    return counts
