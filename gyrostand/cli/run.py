"""``gyrostand run CONFIG [--duration S] [--out DIR] [--idle] [--resume [RUN_DIR]]``: the
live daemon."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from ..config import load_config
from ..session.live import run_live
from .common import number, print_outcome


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "run", help="run the daemon on the configured CAN bus",
        description="Listen on the session's bus, record every frame, bin, identify online, "
                    "answer with result/status frames; on SIGINT/SIGTERM, --duration or a "
                    "stop command write the final fit and report. Prints 'ready: RUN_DIR' "
                    "once listening ('waiting: ...' first while the bus cannot be opened "
                    "yet, with reconnect.at_start).")
    p.add_argument("config", help="YAML session file")
    p.add_argument("--duration", type=number(positive=True), default=None, metavar="S",
                   help="stop after S s of frame time from the first frame (or S+5 s of "
                        "wall time when frames stop flowing)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="parent folder of the run folder (default: the config's "
                        "session.output)")
    p.add_argument("--idle", action="store_true",
                   help="bin and record, but identify only after a start command")
    p.add_argument("--resume", nargs="?", const=True, default=None, metavar="RUN_DIR",
                   help="continue a run folder (after a crash or a stop): RUN_DIR, or the "
                        "session's newest run folder under --out / session.output; bins "
                        "are appended after the last one written, the raw log continues "
                        "in raw-2.blf, raw-3.blf, ...")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config)

    def ready(run_dir) -> None:
        print(f"ready: {run_dir}", flush=True)

    def waiting(text: str) -> None:
        print(f"waiting: {text}", flush=True)

    outcome = run_live(cfg, out=args.out, duration=args.duration, start_idle=args.idle,
                       on_ready=ready, resume=args.resume, on_waiting=waiting)
    print_outcome(outcome, sys.stdout)
    return 0 if outcome.ok else 1
