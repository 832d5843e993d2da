"""``gyrostand replay CONFIG LOG [LOG ...] [--out DIR] [--realtime] [--speed X]
[--reader auto|process|inline] [--per-frame]``; a LOG that is a run folder stands for its raw segments
(``raw.blf``, ``raw-2.blf``, ...). Logs that continue each other make one run; a log of
another switch-on (frames more than ``sampling.max_gap`` after the previous log's end, or
before it: e.g. days apart) starts its own run folder
(:func:`~gyrostand.session.offline.split_runs`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from .. import exitcodes
from ..errors import NoInputError
from .common import (
    add_data_format_args,
    add_format_args,
    decoded_nothing,
    fault_status,
    lost_received,
    number,
    print_outcome,
    with_data_formats,
)


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "replay", help="run a recorded CAN log through the daemon's pipeline",
        description="Replay a log (BLF, ASC, candump .log, CSV, MF4 where python-can reads "
                    "it) through the same pipeline as a live run; all timing from frame "
                    "timestamps; as fast as possible unless --realtime.")
    p.add_argument("config", help="YAML session file")
    p.add_argument("log", nargs="+",
                   help="recorded CAN log(s), replayed one after the other, e.g. a run's "
                        "raw.blf; a run folder stands for all its raw segments in order; "
                        "logs of different runs (frames days apart) give one run folder "
                        "each")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="parent folder of the run folder (default: session.output)")
    p.add_argument("--realtime", action="store_true", help="pace frames to their timestamps")
    p.add_argument("--speed", type=number(positive=True), default=1.0,
                   help="with --realtime: x real time (> 0)")
    p.add_argument("--reader", choices=("auto", "process", "inline"), default="auto",
                   help="where the log is parsed: 'process', a reader process beside the "
                        "decoding (uses a second core); 'inline', in this process; 'auto' "
                        "(default): BLF logs are read as arrays in this process, other logs "
                        "of 1 MiB or more in a process with 2+ CPUs, unless --realtime")
    p.add_argument("--per-frame", action="store_true",
                   help="decode frame by frame instead of whole BLF containers as arrays "
                        "(slower; the same bins and counts: for comparison; also "
                        "GYROSTAND_PER_FRAME=1)")
    add_data_format_args(p)
    add_format_args(p, "the run's summary")
    p.set_defaults(func=run)


def import_can_without_mf4(logs: list[str]) -> None:
    """Import python-can without its MF4 support when no log given is an ``.mf4``.

    ``import can`` imports asammdf (and pandas) for its MF4 reader and writer: ~0.5 s of a
    replay's ~3.5 s CPU, for a format a BLF/ASC/candump replay never reads. Hiding asammdf
    while python-can is first imported leaves ``can.io.mf4`` without it (MF4 logs can then
    not be read in this process, hence only when none is given); asammdf itself stays
    importable afterwards (``gyrostand export --mf4`` imports it as usual). A run folder's
    raw segments are BLF (``raw.blf``, ``raw-2.blf``, ...)."""
    if "can" in sys.modules or "asammdf" in sys.modules:
        return
    if any(Path(item).suffix.lower() == ".mf4" for item in logs):
        return
    sys.modules["asammdf"] = None  # type: ignore[assignment]  # import asammdf: ImportError
    try:
        import can  # noqa: F401
    finally:
        del sys.modules["asammdf"]


def run(args: argparse.Namespace) -> int:
    import_can_without_mf4(args.log)
    from ..config import load_config
    from ..report.views import RunSummary
    from ..runfolder import raw_segments
    from ..session.offline import run_replays
    from .common import emit

    cfg = with_data_formats(load_config(args.config), args)
    if args.per_frame:  # read by gyrostand.can.replay.per_frame_forced() in this process
        import os

        os.environ["GYROSTAND_PER_FRAME"] = "1"
    groups: list[list[Path]] = []
    for item in args.log:
        p = Path(item)
        if p.is_dir():
            segs = raw_segments(p)
            if not segs:
                raise NoInputError(f"{p}: no raw log (raw.blf) in this folder")
            groups.append(list(segs))
        else:
            groups.append([p])
    outcomes = run_replays(cfg, groups, out=args.out, realtime=args.realtime, speed=args.speed,
                           parallel={"auto": None, "process": True,
                                     "inline": False}[args.reader])
    if len(outcomes) == 1:
        print_outcome(outcomes[0], sys.stdout, format=args.format)
    elif args.format == "json":
        import json

        docs = [RunSummary(o, {}).to_dict() for o in outcomes]
        sys.stdout.write(json.dumps({"runs": docs}, indent=2, allow_nan=False) + "\n")
    else:
        for o in outcomes:
            emit(RunSummary(o, {}), args.format, sys.stdout)
    empty = [why for o in outcomes if (why := decoded_nothing(o, cfg, "replay"))]
    for o in outcomes:  # two J1939 devices on one mapping: not one gyro's data
        n = o.stats["decoder"].get("rejected", {}).get("second_source", 0)
        if n:
            empty.append(f"{o.run_dir}: {n} frames of a `match: pgn` message came from a "
                         "second J1939 source address and were not decoded (run.log names "
                         "the ids); map each device with source_address: on its channels")
    for why in empty:  # bad input: the logs hold nothing of this session's messages
        print(f"error: {why}", file=sys.stderr)
    if empty:
        return exitcodes.DATAERR
    faults = [o for o in outcomes if not o.ok]
    for o in faults:  # e.g. the disk filled: a fault, named with its folder
        print(f"error: {o.run_dir}: {o.stop_reason}", file=sys.stderr)
    if faults:
        return fault_status(faults[0])
    lost = [why for o in outcomes if (why := lost_received(o, cfg, "replay"))]
    for why in lost:
        print(f"error: {why}", file=sys.stderr)
    return exitcodes.IOERR if lost else exitcodes.OK
