"""``gyrostand run CONFIG [-i IF] [-c CH] [-b BIT/S] [--fd] [--data-bitrate BIT/S]
[--bus-kwargs KEY=VALUE...] [--app-name NAME] [--duration S] [--out DIR] [--idle] [--resume [RUN_DIR]]``: the live daemon."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from .. import exitcodes
from .common import (
    add_bus_args,
    add_data_format_args,
    add_format_args,
    decoded_nothing,
    fault_status,
    lost_received,
    number,
    print_outcome,
    progress,
    with_bus_overrides,
    with_data_formats,
)

if TYPE_CHECKING:
    from ..config import SessionConfig


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "run", help="run the daemon on the configured CAN bus",
        description="Listen on the session's bus, record every frame, bin, identify online, "
                    "answer with result/status frames; on SIGINT/SIGTERM/SIGHUP, --duration or a "
                    "stop command write the final fit and report. Prints 'ready: RUN_DIR' "
                    "once listening ('waiting: ...' first while the bus cannot be opened "
                    "yet, with reconnect.at_start).")
    p.add_argument("config", help="YAML session file")
    add_bus_args(p)
    p.add_argument("--duration", type=number(positive=True), default=None, metavar="S",
                   help="stop after S s of frame time from the first frame (or S+5 s of "
                        "wall time when frames stop flowing)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="parent folder under which the run folder <name>-<UTC time>/ is "
                        "made (default: the config's session.output)")
    p.add_argument("--idle", action="store_true",
                   help="bin and record, but identify only after a start command")
    p.add_argument("--resume", nargs="?", const=True, default=None, metavar="RUN_DIR",
                   help="continue a run folder (after a crash or a stop): RUN_DIR, or the "
                        "session's newest run folder under --out / session.output; bins "
                        "are appended after the last one written, the raw log continues "
                        "in raw-2.blf, raw-3.blf, ...")
    p.add_argument("--check", action="store_true",
                   help="validate the session file (keys, DBC, signal mapping, response "
                        "frames) and print what it maps, with the source of each bus key "
                        "(session file, command line, env, python-can config), without "
                        "opening the bus")
    add_data_format_args(p)
    add_format_args(p, "the run's summary")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..config import load_config
    from ..session.live import run_live

    cfg = with_data_formats(with_bus_overrides(load_config(args.config), args), args)
    if args.check:
        print(describe_session(cfg))
        return exitcodes.OK

    def ready(run_dir) -> None:
        print(f"ready: {run_dir}", file=progress(args), flush=True)

    def waiting(text: str) -> None:
        print(f"waiting: {text}", file=progress(args), flush=True)

    outcome = run_live(cfg, out=args.out, duration=args.duration, start_idle=args.idle,
                       on_ready=ready, resume=args.resume, on_waiting=waiting)
    print_outcome(outcome, sys.stdout, format=args.format)
    empty = decoded_nothing(outcome, cfg, "run")
    if empty is not None:  # frames none of which fit the session: bad input; none: no bus
        print(f"error: {empty}", file=sys.stderr)
        return (exitcodes.DATAERR if outcome.stats["decoder"].get("received")
                else exitcodes.UNAVAILABLE)
    if not outcome.ok:
        return fault_status(outcome)
    lost = lost_received(outcome, cfg, "run")
    if lost is not None:  # the run went on, but frames it had received were dropped
        print(f"error: {lost}", file=sys.stderr)
        return exitcodes.IOERR
    return exitcodes.OK


def describe_session(cfg: SessionConfig) -> str:
    """What a valid session maps, for ``run --check``."""
    from ..can.busconfig import SESSION_FILE, ResolvedBus

    bus = ResolvedBus(cfg.bus, {k: cfg.bus_sources.get(k, SESSION_FILE) for k in cfg.bus})
    lines = [f"{cfg.path}: valid session {cfg.name!r}",
             "  bus (not opened; after each key, where it came from):",
             *(f"    {line}" for line in bus.describe()),
             f"  dbc: {cfg.dbc_path} ({len(cfg.db.messages)} messages)",
             f"  sampling: dt {cfg.sampling.dt:g} s; drift in {cfg.drift_unit}; runs under "
             f"{cfg.output}"]
    for g in cfg.gyros:
        lines.append(f"  gyro {g.name}: model {','.join(g.model)}; identifiers "
                     f"{','.join(g.identifiers)}")
        for role, ch in (("drift", g.drift), ("temperature", g.temperature)):
            s = ch.signal
            mux = f" when {s.multiplexer} = {'/'.join(map(str, s.multiplexer_ids))}" \
                if s.multiplexer else ""
            cnt = f", counter {ch.counter.name}" if ch.counter else ""
            cnt += ", matched by J1939 PGN" if ch.match == "pgn" else ""
            if ch.source_address is not None:
                cnt += f" from source address 0x{ch.source_address:02X}"
            lines.append(f"    {role:<12} {s.message.describe()}.{s.name} "
                         f"[{s.unit or 'no unit'}]{mux}{cnt}")
            if ch.convert is not None:
                lines.append(f"    {'':<12} converted {ch.convert.describe()}")
            if ch.valid is not None:
                name, vals, accept = ch.valid
                which = "unless" if accept else "when"
                lines.append(f"    {'':<12} frames dropped {which} {name} in "
                             f"{{{', '.join(f'{v:g}' for v in sorted(vals))}}}")
        if g.result is not None:
            summ = f", summary {g.result.summary.describe()}" if g.result.summary else ""
            lines.append(f"    results      {g.result.values.describe()}{summ}")
    r = cfg.responses
    if r.status or r.ack or r.command:
        lines.append("  responses: " + ", ".join(
            f"{k} {m.describe()}" for k, m in (("status", r.status), ("ack", r.ack),
                                               ("command", r.command)) if m is not None))
    else:
        lines.append("  responses: none (listen only)")
    return "\n".join(lines)
