"""``gyrostand export RUN [--parquet] [--mf4] [--gyro G ...] [--out DIR]``: a run's samples
and online estimates as Parquet (pyarrow) and/or MDF4 (asammdf), with signal names and
units (``pip install 'gyrostand[formats]'``)."""

from __future__ import annotations

import argparse
from typing import Any

from ..errors import UsageError


def add_parser(sub: Any) -> None:
    p = sub.add_parser("export", help="export a run as Parquet and/or MDF4 (with units)",
                       description=__doc__)
    p.add_argument("run", help="a run folder")
    p.add_argument("--parquet", action="store_true",
                   help="<gyro>/samples.parquet and <gyro>/estimates.parquet")
    p.add_argument("--mf4", action="store_true", help="<run folder name>.mf4 (MDF 4.10)")
    p.add_argument("--gyro", action="append", default=None, metavar="G",
                   help="only this gyro (repeatable; default every gyro of the run)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="folder to write into (default: the run folder)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..session.export import export_mf4, export_parquet

    if not (args.parquet or args.mf4):
        raise UsageError("export: choose a format: --parquet and/or --mf4")
    written = []
    if args.parquet:
        written += export_parquet(args.run, args.out, args.gyro)
    if args.mf4:
        written.append(export_mf4(args.run, args.out, args.gyro))
    for p in written:
        print(f"wrote {p}")
    return 0
