"""``gyrostand demo``: the stand simulator and the daemon in one process on python-can's
``virtual`` bus (``configs/demo.yaml``): the paper's 2000-s scenario sent as fast as the
machine allows (frame timestamps still advance as on a real stand), then a stop command.

By default the simulated gyro has one effect more than the session's model, and the demo
runs the workbench's loop on the run (:mod:`.demo_loop`): diagnose, fit with the missing
effect, the verdict, the daemon's next run on the adopted model, the report. ``--clean``:
the stand as configured, one run, its final table and the workbench's HTML report."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from ..errors import SessionFileNotFoundError, UsageError
from .common import (
    add_bus_args,
    add_data_format_args,
    add_format_args,
    print_outcome,
    progress,
    with_bus_overrides,
    with_data_formats,
)

#: where the demo config lives: the repository next to the package, else the cwd
CANDIDATES = (Path(__file__).resolve().parents[2] / "configs" / "demo.yaml",
              Path("configs") / "demo.yaml")


def find_demo_config() -> Path:
    for p in CANDIDATES:
        if p.is_file():
            return p
    raise SessionFileNotFoundError("cannot find configs/demo.yaml (looked in "
                      f"{', '.join(str(p) for p in CANDIDATES)}); pass --config")


def add_parser(sub: Any) -> None:
    p = sub.add_parser("demo", help="simulator + daemon on a virtual bus (the paper's scenario)",
                       description=__doc__)
    p.add_argument("--config", default=None, help="session file (default configs/demo.yaml)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="parent folder under which the run folder <name>-<UTC time>/ is "
                        "made (default: session.output)")
    p.add_argument("--clean", action="store_true",
                   help="the stand exactly as configured (no hidden effect): one run, its "
                        "table and report, without the workbench's loop")
    add_bus_args(p)
    add_data_format_args(p)
    add_format_args(p, "the run's summary")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .compiling import CompileClock

    with CompileClock() as clock:
        t0 = time.monotonic()
        code = _run(args)
    print(f"{clock.line()}; demo {time.monotonic() - t0:.1f} s in all", file=progress(args))
    return code


def _run(args: argparse.Namespace) -> int:
    from ..config import load_config
    from ..session.offline import truth_params
    from .demo_loop import daemon_run, loop, simulate_section

    cfg = with_data_formats(with_bus_overrides(load_config(args.config or find_demo_config()),
                                               args), args)
    sim = simulate_section(cfg)
    if not args.clean:
        if args.format != "text":
            raise UsageError("demo: the loop prints text; use --clean for --format "
                             f"{args.format}")
        return loop(cfg, args.out, sys.stdout)
    truths = truth_params(cfg)
    print(f"demo: session {cfg.name!r}, {len(cfg.gyros)} gyro(s) on "
          f"{cfg.bus.get('interface')}:{cfg.bus.get('channel')}; profile "
          f"{' -> '.join(f'{T:g}' for _, T in sim.temperature)} degC over "
          f"{sim.duration or sim.temperature[-1][0]:g} s; truth "
          + "; ".join(f"{g}: " + ", ".join(f"{k}={v:g}" for k, v in p.items())
                      for g, p in truths.items()), file=progress(args), flush=True)
    outcome = daemon_run(cfg, args.out, progress(args), "demo")
    print_outcome(outcome, sys.stdout, truths, format=args.format)
    if outcome.ok:
        # the workbench's page on the run: model vs measurements, residuals, candidates
        from ..report import write_report
        from ..workbench import open_subject

        for f in outcome.finals:
            page = write_report(open_subject(outcome.run_dir, gyro=f.gyro))
            print(f"html report ({f.gyro}): {page}", file=progress(args))
    return 0 if outcome.ok else 1
