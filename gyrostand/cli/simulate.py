"""``gyrostand simulate CONFIG [--log LOG] [-i IF] [-c CH] [-b BIT/S] [--fd]
[--data-bitrate BIT/S] [--realtime | --fast] [--speed X]``.

``--log`` was ``--out`` (still accepted, with a warning): everywhere else ``--out`` is the
parent folder of a run folder, here the argument is one log file."""

from __future__ import annotations

import argparse
import logging
from collections.abc import Iterable, Iterator
from typing import Any

from ..errors import ConfigError, UsageError
from .common import add_bus_args, number, with_bus_overrides

log = logging.getLogger(__name__)


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "simulate", help="simulate the stand's frames onto the bus or into a log",
        description="Truth from the core simulator (the config's simulate section: model "
                    "terms, parameters, temperature profile, seed), encoded into frames "
                    "with jitter, drops and quantization, sent on the configured bus or "
                    "written to a log file (suffix picks the format: .blf, .asc, .log, .csv).")
    p.add_argument("config", help="YAML session file with a simulate section")
    p.add_argument("--log", default=None, metavar="LOG",
                   help="write the frames into this log file instead of sending them "
                        "(.blf, .asc, .log, .csv)")
    p.add_argument("--out", dest="out_deprecated", default=None, metavar="LOG",
                   help="deprecated spelling of --log")
    add_bus_args(p)
    pace = p.add_mutually_exclusive_group()
    pace.add_argument("--realtime", action="store_true", default=None,
                      help="send paced to the frame timestamps")
    pace.add_argument("--fast", dest="realtime", action="store_false",
                      help="send as fast as possible")
    p.add_argument("--speed", type=number(positive=True), default=1.0,
                   help="with --realtime: x real time (> 0)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .. import progress
    from ..config import load_config
    from ..session.offline import simulated_frames

    cfg = load_config(args.config)
    sim = cfg.simulate
    if sim is None:
        raise ConfigError(f"{args.config}: simulate: missing (the simulator needs it)")
    path = args.log
    if args.out_deprecated is not None:
        if path is not None:
            raise UsageError("simulate: give --log LOG (--out is its deprecated spelling), "
                             "not both")
        log.warning("simulate --out LOG is deprecated: use --log LOG (--out is a folder "
                    "in every other command)")
        path = args.out_deprecated
    frames = simulated_frames(cfg)
    total = max(round(sim.duration or sim.temperature[-1][0]), 1)
    with progress.stage("simulate", "frames", total=total, unit="s of stand time") as bar:
        said = _emit(args, cfg, sim, path, _timed(frames, bar, total) if bar.lines
                     else frames)
        bar.update_to(total)
    print(said)
    return 0


def _timed(frames: Iterable[Any], bar: Any, total: int) -> Iterator[Any]:
    """``frames`` unchanged, the stage told their time (whole seconds, at most ``total``)
    once per second of it."""
    t0: float | None = None
    done = 0
    for msg in frames:
        if t0 is None:
            t0 = msg.timestamp
        elif msg.timestamp - t0 >= done + 1:
            done = min(int(msg.timestamp - t0), total)
            bar.update_to(done)
        yield msg


def _emit(args: argparse.Namespace, cfg: Any, sim: Any, path: str | None,
          frames: Iterable[Any]) -> str:
    """Write ``frames`` to the log ``path`` or send them on the bus; what was done."""
    from ..can.bus import open_bus
    from ..can.framesim import send_frames, write_log

    if path:
        return f"wrote {write_log(path, frames)} frames to {path}"
    cfg = with_bus_overrides(cfg, args)
    realtime = sim.realtime if args.realtime is None else args.realtime
    bus = open_bus(cfg.bus)
    try:
        n = send_frames(bus, frames, realtime=realtime, speed=args.speed)
    finally:
        bus.shutdown()
    return f"sent {n} frames on {cfg.bus.get('interface')}:{cfg.bus.get('channel')}"
