"""``gyrostand simulate CONFIG [--out LOG] [--realtime | --fast] [--speed X]``."""

from __future__ import annotations

import argparse
from typing import Any

from ..can.bus import open_bus
from ..can.framesim import send_frames, write_log
from ..config import load_config
from ..errors import ConfigError
from ..session.offline import simulated_frames
from .common import number


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "simulate", help="simulate the stand's frames onto the bus or into a log",
        description="Truth from the core simulator (the config's simulate section: model "
                    "terms, parameters, temperature profile, seed), encoded into frames "
                    "with jitter, drops and quantization, sent on the configured bus or "
                    "written to a log file (suffix picks the format: .blf, .asc, .log, .csv).")
    p.add_argument("config", help="YAML session file with a simulate section")
    p.add_argument("--out", default=None, metavar="LOG", help="write a log file instead")
    pace = p.add_mutually_exclusive_group()
    pace.add_argument("--realtime", action="store_true", default=None,
                      help="send paced to the frame timestamps")
    pace.add_argument("--fast", dest="realtime", action="store_false",
                      help="send as fast as possible")
    p.add_argument("--speed", type=number(positive=True), default=1.0,
                   help="with --realtime: x real time (> 0)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config)
    if cfg.simulate is None:
        raise ConfigError(f"{args.config}: simulate: missing (the simulator needs it)")
    frames = simulated_frames(cfg)
    if args.out:
        n = write_log(args.out, frames)
        print(f"wrote {n} frames to {args.out}")
        return 0
    realtime = cfg.simulate.realtime if args.realtime is None else args.realtime
    bus = open_bus(cfg.bus)
    try:
        n = send_frames(bus, frames, realtime=realtime, speed=args.speed)
    finally:
        bus.shutdown()
    print(f"sent {n} frames on {cfg.bus.get('interface')}:{cfg.bus.get('channel')}")
    return 0
