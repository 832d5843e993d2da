"""``gyrostand batch INPUT ... --out DIR [--manifest CSV] [--config CFG]
[--do replay,identify,diagnose] [--model TERMS] [--method lsq|lkf|ml]
[--scheduler local|tcp://HOST:PORT] [--workers N] [--force] [--retry-failed]``:
every run x gyro of an archive as Dask tasks, one fleet table."""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from ..core.names import METHODS
from ..errors import UsageError
from ..plugins import available_terms
from .common import number


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "batch", help="replay, identify and diagnose a whole archive of runs on Dask",
        description="Every run x gyro of an archive (run folders, raw logs, globs, a "
                    "manifest CSV of run attributes) as Dask tasks on a local cluster or a "
                    "running scheduler; resumable; one fleet table (CSV, Parquet) and a "
                    "fleet page. Needs the 'fleet' extra: pip install 'gyrostand[fleet]'.")
    p.add_argument("inputs", nargs="*", metavar="INPUT",
                   help="run folders, raw logs (with --config) or globs of them (quoted "
                        "patterns are expanded here, ** included)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="the batch folder: results/ (one record per run), replays/, "
                        "fleet.csv, fleet.parquet, fleet.html; rerun with the same DIR to "
                        "resume")
    p.add_argument("--manifest", default=None, metavar="CSV",
                   help="CSV with a 'path' column (run folder or log, relative to the CSV), "
                        "optional 'config' (a log's session file) and 'run' (its name), and "
                        "any other column a run attribute (serial, date, orientation, test, "
                        "type, ...)")
    p.add_argument("--config", default=None, metavar="CFG",
                   help="the session file that decodes every raw log given without one")
    p.add_argument("--do", default="identify,diagnose",
                   help="comma-separated steps per run x gyro of: replay (replay run "
                        "folders' raw logs again; raw logs are always replayed), identify, "
                        "diagnose (default identify,diagnose)")
    p.add_argument("--model", default=None,
                   help="fit this model (comma-separated terms) to every run instead of "
                        f"each gyro's current one; of: {', '.join(available_terms())}")
    p.add_argument("--method", choices=sorted(METHODS), default="ml",
                   help="identifier of the identify step (default ml; diagnose always "
                        "fits by ML)")
    p.add_argument("--sigma", type=number(positive=True), default=None,
                   help="identify: known stationary drift std (markov.sigma, > 0)")
    g = p.add_argument_group("Dask")
    g.add_argument("--scheduler", default="local",
                   help="'local' (default): a LocalCluster on 127.0.0.1, one worker "
                        "process per CPU; or a running scheduler's address, e.g. "
                        "tcp://10.0.0.5:8786 (its workers must see the archive and --out)")
    g.add_argument("--workers", type=int, default=None, metavar="N",
                   help="local: number of worker processes (default: CPUs); a scheduler "
                        "address: wait for N workers before submitting")
    g.add_argument("--memory-limit", default="auto", metavar="BYTES",
                   help="local: memory limit per worker, e.g. 2GiB (default auto: the "
                        "machine's memory / workers)")
    g.add_argument("--timeout", type=number(positive=True), default=60.0, metavar="S",
                   help="seconds to wait for the scheduler (and --workers) (default 60)")
    g = p.add_argument_group("resuming")
    g.add_argument("--force", action="store_true",
                   help="redo every run, even those done with these options")
    g.add_argument("--retry-failed", action="store_true",
                   help="redo the runs whose record is a failure")
    p.add_argument("--trend", default=None, metavar="UNIT",
                   help="one unit's ageing in the fleet view: SERIAL (each of its gyros) or "
                        "SERIAL/GYRO; its slopes with intervals are also printed")
    p.add_argument("--no-view", action="store_true",
                   help="write the table only, not the fleet page")
    p.set_defaults(func=run)


def _steps(text: str) -> tuple[str, ...]:
    from ..batch.tasks import DO_STEPS

    steps = [s.strip() for s in text.split(",") if s.strip()]
    bad = [s for s in steps if s not in DO_STEPS]
    if bad or not steps:
        raise UsageError(f"--do {text!r}: steps are {', '.join(DO_STEPS)} (got "
                         f"{', '.join(bad) or 'none'})")
    if not {"identify", "diagnose"} & set(steps):
        raise UsageError(f"--do {text!r}: give identify and/or diagnose (a replay alone "
                         "makes no table)")
    return tuple(s for s in DO_STEPS if s in steps)


def run(args: argparse.Namespace) -> int:
    from ..batch.inputs import collect_runs
    from ..batch.runner import connect, dashboard_link, require_dask, run_batch
    from ..batch.table import fleet_rows, write_table
    from ..batch.tasks import TaskOptions

    require_dask()  # before anything slow: the error says which extra to install
    if args.model is not None:
        from ..core.model import Model

        Model.parse(args.model)  # a bad term is a usage error now, not N failed runs
    opts = TaskOptions(do=_steps(args.do), model=args.model, method=args.method,
                       identify_options={"sigma": args.sigma} if args.sigma else {})
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers {args.workers}: at least 1")
    specs = collect_runs(args.inputs, config=args.config, manifest=args.manifest)
    attrs = list(dict.fromkeys(k for s in specs for k in s.attrs))
    if args.trend is not None:
        serials = sorted({str(s.attrs["serial"]) for s in specs if s.attrs.get("serial")})
        if args.trend.split("/", 1)[0] not in serials:
            known = ", ".join(serials) or "none: give a manifest with a serial column"
            raise UsageError(f"--trend {args.trend}: no run of that serial in the inputs "
                             f"(serials: {known})")
    tty = sys.stderr.isatty() and not args.quiet
    last = [0.0]

    def line(c: Any, rec: dict[str, Any] | None) -> None:
        if rec is None:
            print(f"batch: {c.total} runs, {c.skipped} done before, {c.remaining} to do",
                  file=sys.stderr, flush=True)
            return
        if rec.get("status") == "failed":
            print(f"batch: {rec['run']}: failed: {str(rec.get('error'))[:300]}",
                  file=sys.stderr, flush=True)
        now = time.perf_counter()
        if not tty and (now - last[0] >= 5.0 or c.remaining == 0):
            last[0] = now
            print(f"batch: {c.done} done, {c.failed} failed, {c.remaining} remaining, "
                  f"{c.rate * 60:.2f} runs/min", file=sys.stderr, flush=True)

    from .. import progress

    with connect(args.scheduler, workers=args.workers, memory_limit=args.memory_limit,
                 timeout=args.timeout) as client:
        link = dashboard_link(client)
        nworkers = len(client.scheduler_info().get("workers", {}))
        print(f"batch: scheduler {client.scheduler.address}, {nworkers} worker(s)"
              + (f", dashboard {link}" if link else ""), file=sys.stderr, flush=True)
        with progress.stage("batch", "runs", unit="runs") as bar:
            def on_progress(c: Any, rec: dict[str, Any] | None) -> None:
                if rec is None:
                    bar.total = c.remaining
                    if bar._bar is not None:  # noqa: SLF001 - the bar's total, once known
                        bar._bar.total = c.remaining
                        bar._bar.refresh()
                else:
                    bar.update(1)
                    if bar._bar is not None:  # noqa: SLF001
                        bar._bar.set_postfix_str(f"{c.failed} failed, {c.remaining} left",
                                                 refresh=False)
                line(c, rec)

            counts = run_batch(client, specs, opts, args.out, force=args.force,
                               retry_failed=args.retry_failed, on_progress=on_progress)
    from ..batch.fleet import with_outliers

    rows = with_outliers(fleet_rows(specs, args.out))
    paths = write_table(rows, args.out, attrs)
    if not args.no_view:
        from ..batch.fleet import write_view

        paths["html"] = write_view(rows, args.out, attrs, trend_unit=args.trend)
    if args.trend is not None:
        from ..batch.fleet import trends

        found = trends(rows, args.trend)
        if not found:
            print(f"trend {args.trend}: fewer than two dated ok runs", file=sys.stderr)
        for t in found:
            ci = t["slope_ci"]
            print(f"trend {t['unit']} {t['parameter']}: {t['slope_per_year']:.6g} per year"
                  + (f" (95 % interval {ci[0]:.6g} … {ci[1]:.6g}, {t['runs']} runs)" if ci
                     else f" ({t['runs']} runs: no interval)"))
    bad = sum(1 for r in rows if r.get("status") != "ok")
    print(f"{counts.total} runs: {counts.done} done now, {counts.failed} failed now, "
          f"{counts.skipped} done before; {len(rows)} rows ({bad} not ok)")
    for kind, path in paths.items():
        print(f"{kind + ':':<8} {path}")
    return 0
