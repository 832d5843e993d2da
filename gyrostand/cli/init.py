"""``gyrostand init DBC [-o session.yaml] [BUS] [--id-base ID | --listen-only]``: list a
DBC's messages and signals, propose each gyro's drift and temperature signals and
counters, and write a commented session file that ``run --check`` accepts."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import UsageError
from .common import add_bus_args, bus_overrides

if TYPE_CHECKING:
    from ..can.survey import Survey


def _int(text: str) -> int:
    try:
        return int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an id (e.g. 0x700)") from None


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "init", help="write a session file for a DBC (the first step for a new stand)",
        description=__doc__)
    p.add_argument("dbc", help="the stand's DBC (or any database cantools reads)")
    p.add_argument("-o", "--output", default="session.yaml", metavar="FILE",
                   help="session file to write (default session.yaml)")
    p.add_argument("--name", default=None, help="session name (default: the DBC's stem)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--id-base", type=_int, default=None, metavar="ID",
                   help="put the daemon's frames (command, ack, status, result and summary "
                        "per gyro) at consecutive standard ids from ID (default: "
                        "dbc/gyrostand.dbc's ids, or the DBC's own daemon messages)")
    g.add_argument("--listen-only", action="store_true",
                   help="no response frames, no command channel")
    p.add_argument("--force", action="store_true", help="overwrite existing files")
    add_bus_args(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..advice import command_line
    from ..config import load_config
    from ..session.scaffold import scaffold, try_it_command, write_scaffold

    bus = bus_overrides(args)
    if bus and "interface" not in bus:
        raise UsageError("init: give -i/--interface with the other bus options (or none "
                         "of them: socketcan can0 is written where this machine has it, "
                         "else the virtual bus)")
    out = Path(args.output)
    sc = scaffold(args.dbc, out, bus=bus or None, name=args.name, id_base=args.id_base,
                  listen_only=args.listen_only)
    print(render_survey(sc.survey, Path(args.dbc).name))
    paths = write_scaffold(sc, out, force=args.force)
    cfg = load_config(out)  # what init writes, run --check accepts
    for p in paths:
        print(f"wrote {p}")
    print(f"check it, then: {command_line('run', out, '--check')}")
    print(f"try it without the stand (its simulate: section): "
          f"{try_it_command(out, cfg.bus)}")
    return 0


def render_survey(sv: Survey, name: str) -> str:
    """The DBC's messages and signals, with the proposed roles marked."""
    from ..can.survey import unit_kind

    role: dict[tuple[str, str], str] = {}
    for g in sv.gyros:
        role[(g.drift.message, g.drift.signal)] = f"<- drift of {g.name}"
        role[(g.temperature.message, g.temperature.signal)] = f"<- temperature of {g.name}"
        for msg, cnt in ((g.drift.message, g.drift_counter),
                         (g.temperature.message, g.temperature_counter)):
            if cnt:
                role.setdefault((msg, cnt), "<- counter")
    own = {n: r for r, names in sv.daemon_messages.items() for n in names}
    lines = [f"{name}: {len(sv.messages)} messages"]
    for m in sv.messages:
        kind = "ext" if m.is_extended_frame else "std"
        fd = " FD" if m.is_fd else ""
        tag = f"   (the daemon's {own[m.name]} frame)" if m.name in own else ""
        lines.append(f"  0x{m.frame_id:X} {kind}{fd} {m.name} ({m.length} B){tag}")
        for s in m.signals:
            mux = "M" if s.is_multiplexer else (
                "m" + "/".join(str(i) for i in s.multiplexer_ids) if s.multiplexer_ids else "")
            kindname = unit_kind(s.unit) or ""
            lines.append(f"      {s.name:<20} {s.unit or '':<8} {mux:<5} {kindname:<11} "
                         f"{role.get((m.name, s.name), '')}".rstrip())
    for w in sv.warnings:
        lines.append(f"check: {w}")
    for d, why in sv.left_out:
        lines.append(f"left out: {d.describe()}: {why}")
    lines.append("proposed: " + "; ".join(
        f"{g.name}: drift {g.drift.describe()}, temperature {g.temperature.describe()}"
        for g in sv.gyros))
    return "\n".join(lines)
