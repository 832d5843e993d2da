"""``gyrostand init``: a commented session file for a DBC, from :func:`~gyrostand.can.survey.survey`.

The daemon answers on the bus with its own frames (results, summaries, status, acks) and
listens to a command frame (``dbc/README.md``). Their source, in order:

1. the DBC already has them (it is ``dbc/gyrostand.dbc``, or carries messages with their
   signals): the session names them;
2. otherwise they are copied from ``dbc/gyrostand.dbc`` into a new DBC beside the session
   file (``<session stem>.dbc``: the user's messages unchanged plus ours), at our own ids
   (command 0x0F0, ack 0x0F1, status 0x500, result *i* 0x300 + *i* − 1, summary *i*
   0x310 + *i* − 1) or, with ``id_base``, at consecutive standard ids from there; an id the
   user's DBC already uses is refused with the clash named;
3. ``listen_only``: no response frames and no command channel.

The file is written as text (comments are the point), then loaded with the session loader
by the caller, so what ``init`` writes is what ``run --check`` accepts.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gyrostand.advice import command_line
from gyrostand.can.dbc import load_dbc, text_encoding
from gyrostand.can.survey import (
    GyroProposal,
    SignalInfo,
    Survey,
    daemon_frame_ids,
    dump_dbc,
    survey,
    with_daemon_frames,
)
from gyrostand.can.units import (
    DEFAULT_DRIFT_UNIT,
    UnitError,
    rate_conversion,
    temperature_conversion,
)
from gyrostand.can.validity import is_code_name, status_signals
from gyrostand.errors import ConfigError, OutputError

__all__ = ["OWN_DBC", "Scaffold", "scaffold", "write_scaffold", "default_bus",
           "try_it_command"]

log = logging.getLogger(__name__)

#: the project's frame catalogue, next to the package in a source checkout
OWN_DBC = Path(__file__).resolve().parents[2] / "dbc" / "gyrostand.dbc"
DEFAULT_MODEL = ("markov", "temp", "bias")
DEFAULT_IDENTIFIERS = ("lkf", "lsq")


@dataclass
class Scaffold:
    """What :func:`scaffold` made: the session text, the survey, and (when the daemon's
    frames were added) the merged DBC to write beside it."""

    text: str
    survey: Survey
    dbc_path: Path
    merged_dbc: Any = None  # a cantools Database
    responses: dict[str, str] = field(default_factory=dict)
    results: dict[str, tuple[str, str]] = field(default_factory=dict)
    #: the text encoding of the user's DBC (:func:`~gyrostand.can.dbc.text_encoding`),
    #: which the merged DBC is written in
    encoding: str = "cp1252"


def _yaml_str(s: str) -> str:
    return s if re.match(r"^[A-Za-z_][A-Za-z0-9_.-]*$", s) and s.lower() not in (
        "yes", "no", "true", "false", "on", "off", "null") else json.dumps(s)


def _tag_index(name: str) -> str | None:
    m = re.search(r"(\d+)$", name)
    return m.group(1) if m else None


def _match_results(gyros: list[GyroProposal], names: list[str]) -> dict[str, str]:
    """gyro -> daemon message of that role: same trailing number, else in order."""
    out: dict[str, str] = {}
    free = list(names)
    for g in gyros:
        idx = _tag_index(g.name)
        hit = next((n for n in free if idx is not None and _tag_index(n) == idx), None)
        if hit is not None:
            out[g.name] = hit
            free.remove(hit)
    for g in gyros:
        if g.name not in out and free:
            out[g.name] = free.pop(0)
    return out


def _channel_line(key: str, s: SignalInfo, counter: str | None, ref: str, db: Any) -> str:
    counter_part = f", counter: {_yaml_str(counter)}" if counter else ""
    match = ", match: pgn" if s.j1939 else ""  # any priority and source address
    valid = ""
    v = _validity(s, counter, db)
    if v is not None:
        valid = f", valid: {{signal: {_yaml_str(v[0])}, accept: [{', '.join(v[1])}]}}"
    return (f"    {key}: {{message: {ref}, signal: {_yaml_str(s.signal)}{counter_part}{match}"
            f"{valid}}}")


def _validity(s: SignalInfo, counter: str | None, db: Any) -> tuple[str, list[str]] | None:
    """The message's validity signal and the values its value table names valid (a
    state of no measurement, ``invalid``/``error``/``not available``, left out)."""
    msg = db.get_message_by_name(s.message)
    found = status_signals(msg, [s.signal] + ([counter] if counter else []))
    if not found:
        return None
    name = found[0][0]
    sig = msg.get_signal_by_name(name)
    ok = [f"{sig.conversion.raw_to_scaled(int(raw), False):g}"
          for raw, label in sorted(sig.choices.items()) if not is_code_name(str(label))]
    return (name, ok) if ok else None


def _codes_note(s: SignalInfo, counter: str | None, db: Any) -> list[str]:
    """What the DBC's value tables say of a mapped signal's frames: codes counted, never
    binned; the validity signal whose other values drop the frame."""
    msg = db.get_message_by_name(s.message)
    sig = msg.get_signal_by_name(s.signal)
    out = []
    codes = [f"{raw} {label!s}" for raw, label in sorted((sig.choices or {}).items())
             if is_code_name(str(label))]
    if codes:
        out.append(f"{s.message}.{s.signal} codes {', '.join(codes)}: counted "
                   "(not_available), never binned")
    v = _validity(s, counter, db)
    if v is not None:
        out.append(f"{s.message}.{v[0]} marks frames valid at {', '.join(v[1])}; others "
                   "are dropped (invalid)")
    return out


def _describe(s: SignalInfo, counter: str | None, db: Any) -> str:
    kind = "extended" if s.is_extended else "standard"
    msg = db.get_message_by_name(s.message)
    mux = ""
    if s.mux_ids:
        sel = next((x.name for x in msg.signals if x.is_multiplexer), "mux")
        mux = f", when {sel} = {'/'.join(str(i) for i in s.mux_ids)}"
    why = "unit" if s.kind else "name only: check"
    cnt = f"; counter {counter}" if counter else "; no rolling counter found"
    pg = "; a J1939 PG (VFrameFormat J1939PG): matched by PGN" if s.j1939 else ""
    return (f"{s.message}.{s.signal} (0x{s.frame_id:X} {kind}, unit {s.unit or 'none'!r}"
            f"{mux}; by {why}{cnt}{pg})")


def scaffold(dbc: str | Path, out: str | Path, *, bus: Mapping[str, Any] | None = None,
             name: str | None = None, id_base: int | None = None,
             listen_only: bool = False, own_dbc: str | Path = OWN_DBC) -> Scaffold:
    """Survey ``dbc`` and compose the session file to be written at ``out``.

    ``bus`` the ``bus:`` section (default :func:`default_bus`); ``name`` the session name
    (default the DBC's file stem). Raises :class:`~gyrostand.errors.ConfigError` /
    :class:`~gyrostand.errors.CanEdgeError` naming the file on a problem."""
    dbc = Path(dbc).resolve()
    out = Path(out)
    db = load_dbc(dbc)
    sv = survey(db, source=str(dbc))
    if not sv.gyros:
        why = "; ".join(f"{d.describe()}: {w}" for d, w in sv.left_out)
        raise ConfigError(f"{dbc}: no gyro could be mapped ({why})")
    session_name = name or re.sub(r"[^A-Za-z0-9_.-]", "_", dbc.stem).lstrip("_.-") or "stand"
    responses: dict[str, str] = {}
    results: dict[str, tuple[str, str]] = {}
    merged: Any = None
    dbc_for_session = dbc
    origin = ""
    if not listen_only:
        if {"status", "ack", "command"} <= set(sv.daemon_messages) and id_base is None:
            origin = f"the daemon's own frames, found in {dbc.name}"
            for role in ("status", "ack", "command"):
                responses[role] = sv.daemon_messages[role][0]
            res = _match_results(sv.gyros, sv.daemon_messages.get("result", []))
            summ = _match_results(sv.gyros, sv.daemon_messages.get("summary", []))
            results = {g: (res[g], summ.get(g, "")) for g in res}
        else:
            own = load_dbc(own_dbc)
            merged = with_daemon_frames(db, own, [_units(sv)[0]] * len(sv.gyros), id_base,
                                        str(dbc))
            dbc_for_session = out.resolve().with_name(f"{out.stem}+gyrostand.dbc")
            if dbc_for_session == dbc:
                raise ConfigError(f"{out}: the merged DBC would overwrite {dbc}; choose "
                                  "another -o")
            ids = daemon_frame_ids(len(sv.gyros), id_base)
            where = "our own ids" if id_base is None else f"ids from 0x{id_base:X}"
            origin = (f"the daemon's frames copied from dbc/gyrostand.dbc into "
                      f"{dbc_for_session.name} ({dbc.name}'s messages plus ours, at {where})")
            responses = {"status": "GS_STATUS", "ack": "GS_ACK", "command": "GS_COMMAND"}
            results = {g.name: (f"GS_RESULT_{i}", f"GS_SUMMARY_{i}")
                       for i, g in enumerate(sv.gyros, start=1)}
            log.info("daemon frames at %s", ", ".join(f"{k} 0x{v:X}" for k, v in ids.items()))
    text = _render(sv, db, dbc, dbc_for_session, out, session_name, bus, responses, results,
                   origin)
    return Scaffold(text, sv, dbc_for_session, merged, responses, results,
                    encoding=text_encoding(dbc).removesuffix("-sig"))


def _render(sv: Survey, db: Any, dbc: Path, dbc_for_session: Path, out: Path,
            session_name: str, bus: Mapping[str, Any] | None, responses: dict[str, str],
            results: dict[str, tuple[str, str]], origin: str) -> str:
    rel = os.path.relpath(dbc_for_session, out.resolve().parent)
    today = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d")
    bus_note = ["-i/-c/-b override it; a key left out comes from python-can's config "
                "(~/.canrc)"]
    if not bus:
        bus, bus_note = default_bus(session_name)
    bus = dict(bus)
    L = [f"# gyrostand session for {dbc.name}, written by `gyrostand init` on {today}.",
         "# The mapping below was proposed from the DBC's units and names: check every",
         "# line, then validate without opening the bus:",
         f"#     {command_line('run', out.resolve(), '--check')}",
         "# Every key is explained in configs/demo.yaml of the gyrostand repository.", ""]
    for w in sv.warnings:
        L.append(f"# CHECK: {w}")
    drift_unit, unit_notes = _units(sv)
    L += ["session:",
          f"  name: {_yaml_str(session_name)}",
          "  output: runs                    # run folders go here (relative to this file)",
          "  fsync: true                     # each 1-s acknowledgement survives a power cut",
          f"  drift_unit: {json.dumps(drift_unit, ensure_ascii=False)}"
          "              # every drift is binned in this unit",
          "",
          "bus:                              # passed to can.Bus(**bus)"]
    L += [f"  # {line}" for line in bus_note]
    for k, v in bus.items():
        L.append(f"  {k}: {json.dumps(v)}")
    L += ["", f"dbc: {json.dumps(rel)}", "",
          "sampling:",
          "  dt: 1.0                         # s, bin width", "", "gyros:"]
    for g in sv.gyros:
        L.append(f"  - name: {_yaml_str(g.name)}")
        L.append(f"    # drift:       {_describe(g.drift, g.drift_counter, db)}")
        L.append(f"    # temperature: {_describe(g.temperature, g.temperature_counter, db)}")
        codes = (_codes_note(g.drift, g.drift_counter, db)
                 + _codes_note(g.temperature, g.temperature_counter, db))
        for note in g.notes + unit_notes.get(g.name, []) + codes:
            L.append(f"    # CHECK: {note}")
        L.append(_channel_line("drift", g.drift, g.drift_counter, _yaml_str(g.drift.message),
                               db))
        L.append(_channel_line("temperature", g.temperature, g.temperature_counter,
                               _yaml_str(g.temperature.message), db))
        L.append(f"    model: [{', '.join(DEFAULT_MODEL)}]       # terms: see README "
                 "'Model terms'")
        L.append(f"    identifiers: [{', '.join(DEFAULT_IDENTIFIERS)}]  # online; ml always "
                 "runs at the end")
        if g.name in results:
            values, summary = results[g.name]
            summ = f", summary: {_yaml_str(summary)}" if summary else ""
            L.append(f"    result: {{message: {_yaml_str(values)}{summ}}}")
    for d, why in sv.left_out:
        L.append(f"  # left out: drift {d.describe()} ({d.unit or 'no unit'}): {why}")
    L.append("")
    if responses:
        L += [f"responses:                         # {origin}",
              "  period: 10                      # s of frame time between result rounds",
              "  heartbeat: 1.0                  # s between status heartbeats",
              f"  status: {_yaml_str(responses['status'])}",
              f"  ack: {_yaml_str(responses['ack'])}",
              f"  command: {_yaml_str(responses['command'])}",
              "  node: 1                         # this daemon's Target id (255 addresses all)"]
    else:
        L += ["# responses: none (listen only): the daemon records, bins and identifies,",
              "# but sends no result/status frames and takes no commands."]
    L += _simulate_lines(sv, db, try_it_command(out.resolve(), bus))
    return "\n".join(L)


#: the simulated stand's temperature profile (t s, T degC): a warm-up, a soak, a cool-down
_PROFILE_C = ((0, 20.0), (200, 45.0), (400, 45.0), (600, 35.0))


def try_it_command(session: str | Path, bus: Mapping[str, Any]) -> str:
    """The demo on ``session``'s simulated stand as a line to paste: ``gyrostand demo
    --clean --config SESSION``, on python-can's virtual bus (with the simulator's frame
    times kept) when the session's bus is another, so no simulated frame reaches a
    stand's bus."""
    extra: list[str] = []
    if bus.get("interface") != "virtual" or not bus.get("preserve_timestamps"):
        extra = ["-i", "virtual", "-c", "gyrostand-try", "--bus-kwargs",
                 "preserve_timestamps=true"]
    return command_line("demo", "--clean", "--config", session, *extra)


def _simulate_lines(sv: Survey, db: Any, try_it: str) -> list[str]:
    """A ``simulate:`` section for the demo (``run`` ignores it): the profile in °C and
    each gyro's truth in the session's drift unit (the simulator encodes both into the
    DBC's units), the truth scaled to the drift signal's range (σ a two-thousandth of it,
    at least 20 steps of an integer signal), the thermal gain small enough that the drift
    stays in range."""
    drift_unit = _units(sv)[0]
    profile = ", ".join(f"[{t}, {c:g}]" for t, c in _PROFILE_C)
    L = ["", "# A simulated stand of this layout, for trying it without the stand (`run`",
         "# ignores this section; its truth is a guess scaled to the DBC's signals):",
         f"#     {try_it}",
         "simulate:",
         "  seed: 1",
         "  duration: 600                   # s of frame time",
         f"  temperature: [{profile}]   # [t s, T degC]",
         "  rates: {drift: 10, temperature: 10}   # Hz",
         "  gyros:"]
    for g in sv.gyros:
        sig = db.get_message_by_name(g.drift.message).get_signal_by_name(g.drift.signal)
        span = (float(sig.maximum) - float(sig.minimum)
                if sig.maximum is not None and sig.minimum is not None else 0.0)
        step = 0.0 if sig.is_float else abs(float(sig.scale or 0))  # a float has no step
        try:  # the signal's range in the session's drift unit
            conv = rate_conversion(g.drift.unit, drift_unit)
        except UnitError:
            conv = None
        k = abs(conv.scale) if conv is not None else 1.0
        sigma = float(f"{max(k * span / 2000, 20 * k * step) or 0.1:.1g}")
        gamma = float(f"{-0.01 * sigma:.1g}")
        L += [f"    {_yaml_str(g.name)}:",
              "      model: [markov, temp, white]",
              f"      params: {{markov.beta: 0.0333, markov.sigma: {_yaml_float(sigma)}, "
              f"temp.gamma: {_yaml_float(gamma)}, white.sigma: 0.0}}"]
    return L + [""]


def _yaml_float(x: float) -> str:
    """``x`` as a YAML 1.1 float (PyYAML reads ``1e-05`` as a string: its mantissa needs a
    point, ``1.0e-05``)."""
    r = repr(float(x))
    mant, e, exp = r.partition("e")
    return f"{mant}.0e{exp}" if e and "." not in mant else r


def _units(sv: Survey) -> tuple[str, dict[str, list[str]]]:
    """The session's drift unit (the drift signals' own when they share one known unit,
    else deg/h) and, per gyro, the conversions proposed (K/°F/mK to °C, a drift to the
    session's unit) or the unit that cannot be converted."""
    units = {g.drift.unit for g in sv.gyros if g.drift.unit.strip()}
    known = all(_convertible(u) for u in units)
    drift_unit = units.pop() if len(units) == 1 and known else DEFAULT_DRIFT_UNIT
    notes: dict[str, list[str]] = {}
    for g in sv.gyros:
        for role, s in (("drift", g.drift), ("temperature", g.temperature)):
            try:
                conv = (rate_conversion(s.unit, drift_unit) if role == "drift"
                        else temperature_conversion(s.unit))
            except UnitError as exc:
                notes.setdefault(g.name, []).append(
                    f"{role} {s.message}.{s.signal}: {exc}: give its unit (unit: ...)")
                continue
            if conv is not None:
                notes.setdefault(g.name, []).append(
                    f"{role} {s.message}.{s.signal} is converted at decode time: "
                    f"{conv.describe()}")
    return drift_unit, notes


def _convertible(unit: str) -> bool:
    try:
        rate_conversion(unit)
    except UnitError:
        return False
    return True


def default_bus(session_name: str, channel: str = "can0"
                ) -> tuple[dict[str, Any], list[str]]:
    """The ``bus:`` ``init`` writes when none is given, and the comment lines above it:
    SocketCAN's ``can0`` where this machine has it (:func:`socketcan_available`), else
    python-can's ``virtual`` bus on a channel named after the session (``run`` and the
    demo start at once; nothing from the stand arrives on it), with how to switch."""
    from gyrostand.can.busconfig import socketcan_available

    if socketcan_available(channel):
        return ({"interface": "socketcan", "channel": channel},
                [f"SocketCAN's {channel} (found here); -i/-c/-b override it"])
    return ({"interface": "virtual", "channel": session_name, "preserve_timestamps": True},
            ["SocketCAN is absent here (no AF_CAN socket or no can0), so python-can's",
             "virtual bus is written (keeping a sender's frame times, as the demo's",
             "simulated stand needs): the session runs, but no stand frame reaches it.",
             "On the stand write  interface: socketcan  and  channel: can0  (or pcan,",
             "vector, kvaser, ...), run with -i socketcan -c can0, or delete both keys",
             "and let python-can's config (~/.canrc, CAN_INTERFACE) name the bus."])


def write_scaffold(sc: Scaffold, out: str | Path, *, force: bool = False) -> list[Path]:
    """Write the session file (and the merged DBC) at ``out``; refuse to overwrite either
    unless ``force``. Returns the paths written."""
    out = Path(out)
    paths = [out] + ([sc.dbc_path] if sc.merged_dbc is not None else [])
    for p in paths:
        if p.exists() and not force:
            raise OutputError(f"{p}: exists; pass --force to overwrite")
    out.parent.mkdir(parents=True, exist_ok=True)
    if sc.merged_dbc is not None:
        dump_dbc(sc.merged_dbc, sc.dbc_path, sc.encoding)
    out.write_text(sc.text, encoding="utf-8")
    return paths
