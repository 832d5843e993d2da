"""Survey of a DBC for a new stand: which signals carry a gyro's drift and temperature,
their rolling counters, and which messages are the daemon's own (results, status, commands).

The proposal is made from what a DBC says about a signal, never from our frame ids:

* **unit** (strongest): an angular rate (deg/h, °/h, dph, deg/s, °/s, dps, rad/s, mrad/s,
  mdeg/s, arcsec/s) is a drift candidate; a temperature (°C, degC, C, K, °F) a
  temperature candidate;
* **name**: words such as drift, rate, gyro, omega (drift) and temp, tmp, therm
  (temperature) add to the score; a signal without a unit whose own name says so
  (``YawRate``, ``GyroRate``, ``ZTemp``) is proposed by its name alone (and flagged), as is,
  without any unit-matched signal, one whose message name says so; a status, mode or
  checksum word, or a small raw integer, is no measurement;
* **counter**: an unsigned integer signal (scale 1, offset 0, 2–16 bits, unitless) of the
  same message whose name says counter/cnt/seq/alive/rolling, present under the same
  multiplexer values as the signal it counts;
* **pairing**: each drift signal is paired with the temperature signal that shares its
  message (and multiplexer), or failing that its axis letter (x/y/z) or number; an
  ambient, board, CPU, ... temperature loses to any other (a case or sensor temperature)
  wherever it sits; ties go to the DBC's order; a
  temperature signal is mapped to one gyro only (the session maps each signal once), so a
  second gyro sharing it is reported as left out.

Messages that carry the signal sets of the daemon's own frames (``dbc/README.md``) are
recognised as such and never proposed as measurements. A message the DBC marks
``VFrameFormat`` ``J1939PG`` (cantools' ``protocol == "j1939"``) is a J1939 parameter
group: :attr:`SignalInfo.j1939` (the session matches it by PGN).
"""

from __future__ import annotations

import copy
import logging
import re
from dataclasses import dataclass, field
from pathlib import Path

import cantools
from cantools.database.can import Database, Message, Node, Signal

from gyrostand.can.dbc import frame_key
from gyrostand.errors import CanEdgeError

__all__ = [
    "DAEMON_SIGNALS",
    "SignalInfo",
    "GyroProposal",
    "Survey",
    "survey",
    "unit_kind",
    "temperature_unit",
    "daemon_frame_ids",
    "with_daemon_frames",
    "dump_dbc",
]

MAX_STANDARD_ID = 0x7FF

log = logging.getLogger(__name__)

#: signals each of the daemon's own messages carries (as the session loader requires)
DAEMON_SIGNALS: dict[str, tuple[str, ...]] = {
    "result": ("Kind", "Identifier", "Param", "Value", "Std", "NParams", "Counter"),
    "summary": ("Identifier", "Status", "ModelTerms", "Samples", "ResidualRms"),
    "status": ("Page", "Counter", "State", "Bins", "Gaps", "FramesDecoded",
               "FramesRejected", "BusErrors", "LateFrames"),
    "command": ("Command", "Sequence", "Target"),
    "ack": ("Command", "Sequence", "Result", "Reason"),
}

_RATE_UNITS = {"deg/h", "deg/hr", "dph", "deg/s", "dps", "rad/s", "mrad/s", "mdeg/s",
               "urad/s", "arcsec/s", "arcsec/h", "rpm"}
_TEMP_UNITS = {"degc": "degC", "c": "degC", "celsius": "degC", "k": "K", "kelvin": "K", "degk": "K",
               "degf": "degF", "f": "degF"}
_DRIFT_WORDS = ("drift", "rate", "gyro", "gyr", "omega", "angvel", "angrate", "rot")
_TEMP_WORDS = ("temp", "tmp", "temperature", "therm")
_OTHER_TEMP_WORDS = ("ambient", "amb", "board", "brd", "pcb", "cpu", "mcu", "oil",
                     "coolant", "water", "air", "outside", "cabin", "env", "ecu")
#: a temperature of the gyro itself: its case, housing, sensor
_OWN_TEMP_WORDS = ("gyro", "gyr", "sensor", "imu", "rate", "case", "housing", "fog", "die")
#: words of a signal that is no measurement (a blank-unit signal named by them is skipped)
_NOT_MEASURED_WORDS = ("status", "stat", "state", "mode", "valid", "flag", "flags", "error",
                       "err", "crc", "checksum", "chk", "diag", "fault", "qual", "quality")
_COUNTER_WORDS = ("counter", "count", "cnt", "ctr", "seq", "sequence", "alive", "rolling",
                  "roll", "rc", "msgcnt", "sqc")


def _norm_unit(unit: str | None) -> str:
    u = (unit or "").strip().lower().replace(" ", "")
    u = u.replace("°", "deg").replace("º", "deg").replace("degree", "deg").replace("degs", "deg")
    u = u.replace("/sec", "/s").replace("/hour", "/h").replace("/hr", "/h")
    return u.replace("per", "/")


def temperature_unit(unit: str | None) -> str | None:
    """``'degC'``, ``'K'`` or ``'degF'`` for a DBC temperature unit, else None.

    >>> temperature_unit("°C"), temperature_unit("kelvin"), temperature_unit("V")
    ('degC', 'K', None)
    """
    return _TEMP_UNITS.get(_norm_unit(unit))


def unit_kind(unit: str | None) -> str | None:
    """``'rate'``, ``'temperature'`` or None for a DBC unit string.

    >>> unit_kind("°/h"), unit_kind("rad/s"), unit_kind("degC"), unit_kind("K"), unit_kind("V")
    ('rate', 'rate', 'temperature', 'temperature', None)
    """
    u = _norm_unit(unit)
    if u in _RATE_UNITS:
        return "rate"
    if u in _TEMP_UNITS:
        return "temperature"
    return None


def _words(name: str) -> list[str]:
    """``'IMU_Y_RATE'`` -> imu, y, rate; ``'YRate'`` -> y, rate; ``'Gyro1Temp'`` -> gyro, 1, temp."""
    parts = re.findall(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|\d+", name)
    return [p.lower() for p in parts]


def _tags(*names: str) -> set[str]:
    """Axis letters and numbers in names: what pairs GYRO_DRIFT_1 with GYRO_TEMP_1."""
    out: set[str] = set()
    for n in names:
        for w in _words(n):
            if w in ("x", "y", "z") or w.isdigit():
                out.add(w)
    return out


@dataclass(frozen=True)
class SignalInfo:
    """One signal of the DBC as the survey saw it."""

    message: str
    frame_id: int
    is_extended: bool
    signal: str
    unit: str
    kind: str | None            # 'rate', 'temperature' or None (by unit)
    mux_ids: tuple[int, ...]    # multiplexer values that select it (empty: always there)
    score: float = 0.0
    j1939: bool = False         # its message is a J1939 parameter group (VFrameFormat)

    def describe(self) -> str:
        return f"{self.message}.{self.signal}"


@dataclass
class GyroProposal:
    """A proposed gyro: its drift and temperature signals and their counters."""

    name: str
    drift: SignalInfo
    temperature: SignalInfo
    drift_counter: str | None
    temperature_counter: str | None
    notes: list[str] = field(default_factory=list)


@dataclass
class Survey:
    """Everything :func:`survey` found in a DBC."""

    messages: list[Message]
    gyros: list[GyroProposal]
    #: drift signals that found no temperature signal at all (with the reason)
    left_out: list[tuple[SignalInfo, str]]
    #: role -> message names of the daemon's own frames found in the DBC
    daemon_messages: dict[str, list[str]]
    warnings: list[str]


def _is_daemon_message(msg: Message) -> str | None:
    names = {s.name for s in msg.signals}
    for role, needed in DAEMON_SIGNALS.items():
        if set(needed) <= names:
            return role
    return None


def _drift_score(msg: Message, sig: Signal) -> float:
    words = set(_words(sig.name)) | set(_words(msg.name))
    kind = unit_kind(sig.unit)
    score = 10.0 if kind == "rate" else 0.0
    score += 3.0 * any(w in words for w in _DRIFT_WORDS)
    score += 2.0 * ("drift" in words)
    return score


def _temp_score(msg: Message, sig: Signal) -> float:
    sig_words = set(_words(sig.name))
    words = sig_words | set(_words(msg.name))
    kind = unit_kind(sig.unit)
    score = 10.0 if kind == "temperature" else 0.0
    score += 3.0 * any(w in words for w in _TEMP_WORDS)
    score += 2.0 * any(w in words for w in _OWN_TEMP_WORDS)
    score -= 5.0 * any(w in sig_words for w in _OTHER_TEMP_WORDS)
    return score


def _is_counter(sig: Signal) -> bool:
    if sig.is_float or sig.is_signed or sig.is_multiplexer:
        return False
    if float(sig.scale) != 1.0 or float(sig.offset) != 0.0 or not 2 <= sig.length <= 16:
        return False
    if (sig.unit or "").strip():
        return False
    words = _words(sig.name)
    return any(w in _COUNTER_WORDS for w in words) or sig.name.lower() in _COUNTER_WORDS


def _mux_ids(sig: Signal) -> tuple[int, ...]:
    return tuple(int(i) for i in (sig.multiplexer_ids or ()))


def _counter_for(msg: Message, info: SignalInfo) -> str | None:
    """The rolling counter of ``info``'s message present whenever ``info`` is."""
    for sig in msg.signals:
        if sig.name == info.signal or not _is_counter(sig):
            continue
        ids = _mux_ids(sig)
        if not ids or (info.mux_ids and set(info.mux_ids) <= set(ids)):
            return sig.name
    return None


def _measured(sig: Signal) -> bool:
    """Whether a signal can be a measurement: no value table (a state), no status, mode or
    checksum word in its name, not a small raw integer (unsigned, scale 1, offset 0, at
    most 8 bits: a flag or code)."""
    if sig.choices or any(w in _NOT_MEASURED_WORDS for w in _words(sig.name)):
        return False
    raw = not sig.is_float and not sig.is_signed and float(sig.scale) == 1.0 \
        and float(sig.offset) == 0.0
    return not (raw and sig.length <= 8)


def _named(sig: Signal, kind: str) -> bool:
    """A signal without a unit whose own name says ``kind`` (``YawRate``, ``ZTemp``)."""
    if (sig.unit or "").strip() or not _measured(sig):
        return False
    words = _DRIFT_WORDS if kind == "rate" else _TEMP_WORDS
    return any(w in words for w in _words(sig.name))


def _candidates(db: Database, daemon: set[str], kind: str) -> list[SignalInfo]:
    """The signals that may carry ``kind``, best first: those with its unit, then those
    whose own name says it (no unit); failing both, those whose message name says it
    strongly. A stable sort: equal scores keep the DBC's order."""
    scorer = _drift_score if kind == "rate" else _temp_score
    found: list[SignalInfo] = []
    named: set[tuple[str, str]] = set()
    measured: set[tuple[str, str]] = set()
    for msg in db.messages:
        if msg.name in daemon:
            continue
        for sig in msg.signals:
            if sig.is_multiplexer or _is_counter(sig):
                continue
            score = scorer(msg, sig)
            found.append(SignalInfo(msg.name, msg.frame_id, bool(msg.is_extended_frame),
                                    sig.name, sig.unit or "", unit_kind(sig.unit),
                                    _mux_ids(sig), score, msg.protocol == "j1939"))
            if _named(sig, kind):
                named.add((msg.name, sig.name))
            if _measured(sig):
                measured.add((msg.name, sig.name))
    by_unit = [s for s in found if s.kind == kind]
    by_name = [s for s in found if (s.message, s.signal) in named]
    if by_unit or by_name:
        return sorted(by_unit + by_name, key=lambda s: -s.score)
    # no unit nor signal name says it: fall back to names (with the message's) that say
    # it strongly (flagged by the caller)
    strong = 5.0 if kind == "rate" else 3.0
    return sorted([s for s in found if s.kind is None and s.score >= strong
                   and (s.message, s.signal) in measured], key=lambda s: -s.score)


def _pair_score(d: SignalInfo, t: SignalInfo) -> float:
    score = t.score
    if d.message == t.message:  # (under other multiplexer values too: one message)
        score += 6.0
    dt, tt = _tags(d.message, d.signal), _tags(t.message, t.signal)
    if dt and tt:
        score += 4.0 if dt & tt else -4.0
    return score


def _gyro_name(d: SignalInfo, taken: set[str]) -> str:
    tags = sorted(_tags(d.message, d.signal))
    letters = [t for t in tags if not t.isdigit()]
    digits = [t for t in tags if t.isdigit()]
    if letters:
        base = letters[0]
    elif digits:
        base = f"gyro{digits[0]}"
    else:
        base = re.sub(r"[^A-Za-z0-9_.-]", "_", d.signal.lower()) or "gyro"
    name, i = base, 2
    while name in taken:
        name, i = f"{base}_{i}", i + 1
    return name


def survey(db: Database, source: str = "DBC") -> Survey:
    """Propose the drift/temperature mapping of every gyro in ``db``.

    Raises :class:`CanEdgeError` (naming ``source``) when no signal can carry a drift rate
    or no signal a temperature."""
    daemon: dict[str, list[str]] = {}
    for msg in db.messages:
        role = _is_daemon_message(msg)
        if role is not None:
            daemon.setdefault(role, []).append(msg.name)
    own = {n for names in daemon.values() for n in names}
    warnings: list[str] = []
    drifts = _candidates(db, own, "rate")
    temps = _candidates(db, own, "temperature")
    if not drifts:
        raise CanEdgeError(f"{source}: no signal looks like a gyro drift rate (no unit of "
                           "deg/h, deg/s, rad/s, ... and no name with drift/rate/gyro); "
                           "write the session's gyros: by hand")
    if not temps:
        raise CanEdgeError(f"{source}: no signal looks like a temperature (no unit of degC, "
                           "K, ... and no name with temp); write the session's gyros: by hand")
    if drifts[0].kind is None:
        warnings.append("no signal has an angular-rate unit: drift signals proposed by name "
                        "only; check them")
    if temps[0].kind is None:
        warnings.append("no signal has a temperature unit: temperature signals proposed by "
                        "name only; check them")
    # best first: a gyro's own temperature before an ambient/board/CPU one wherever it
    # sits, then by score; ties in the DBC's order
    other = {j for j, t in enumerate(temps)
             if any(w in _OTHER_TEMP_WORDS for w in _words(t.signal))}
    pairs = sorted(((_pair_score(d, t), i, j) for i, d in enumerate(drifts)
                    for j, t in enumerate(temps)),
                   key=lambda p: (p[2] in other, -p[0], p[1], p[2]))
    chosen: dict[int, int] = {}
    used_t: set[int] = set()
    for score, i, j in pairs:
        if i in chosen or j in used_t or score < 0:
            continue
        chosen[i] = j
        used_t.add(j)
    shared: set[int] = set()  # a drift left without a sensor of its own takes its best one
    for score, i, j in pairs:  # (one sensor on a multi-axis board serves several gyros)
        if i not in chosen and score >= 0:
            chosen[i] = j
            shared.add(i)
    msgs = {m.name: m for m in db.messages}
    gyros: list[GyroProposal] = []
    left_out: list[tuple[SignalInfo, str]] = []
    taken: set[str] = set()
    for i, d in enumerate(drifts):
        if i not in chosen:
            left_out.append((d, "no temperature signal fits"))
            continue
        t = temps[chosen[i]]
        name = _gyro_name(d, taken)
        taken.add(name)
        g = GyroProposal(name, d, t, _counter_for(msgs[d.message], d),
                         _counter_for(msgs[t.message], t))
        if d.kind is None:
            g.notes.append(f"{d.describe()} has no rate unit ({d.unit!r}): proposed by name")
        if t.kind is None:
            g.notes.append(f"{t.describe()} has no temperature unit ({t.unit!r}): proposed "
                           "by name")
        if i in shared:
            g.notes.append(f"shares {t.describe()} with another gyro (no sensor of its own "
                           "fits better)")
        gyros.append(g)
    gyros.sort(key=lambda g: (g.drift.frame_id, g.drift.signal))
    return Survey(list(db.messages), gyros, left_out, daemon, warnings)


def daemon_frame_ids(n_gyros: int, id_base: int | None) -> dict[str, int]:
    """Standard ids of the daemon's frames for ``n_gyros``: ours (command 0x0F0, ack
    0x0F1, status 0x500, result i 0x300 + i - 1, summary i 0x310 + i - 1), or consecutive
    from ``id_base`` (command, ack, status, then result/summary of each gyro)."""
    if id_base is None:
        ids = {"GS_COMMAND": 0x0F0, "GS_ACK": 0x0F1, "GS_STATUS": 0x500}
        for i in range(1, n_gyros + 1):
            ids[f"GS_RESULT_{i}"] = 0x300 + i - 1
            ids[f"GS_SUMMARY_{i}"] = 0x310 + i - 1
        if n_gyros > 16:
            raise CanEdgeError(f"{n_gyros} gyros: our default ids hold 16; give --id-base")
        return ids
    ids = {"GS_COMMAND": id_base, "GS_ACK": id_base + 1, "GS_STATUS": id_base + 2}
    for i in range(1, n_gyros + 1):
        ids[f"GS_RESULT_{i}"] = id_base + 1 + 2 * i
        ids[f"GS_SUMMARY_{i}"] = id_base + 2 + 2 * i
    top = max(ids.values())
    if id_base < 0 or top > MAX_STANDARD_ID:
        raise CanEdgeError(f"--id-base 0x{id_base:X}: the daemon's {len(ids)} frames need "
                          f"standard ids 0x{id_base:X}..0x{top:X} (at most 0x7FF)")
    return ids


def with_daemon_frames(db: Database, own: Database, drift_units: list[str],
                       id_base: int | None, source: str = "DBC") -> Database:
    """A copy of ``db`` with the daemon's messages copied from ``own`` (our
    ``dbc/gyrostand.dbc``) for ``len(drift_units)`` gyros, at :func:`daemon_frame_ids`;
    each summary's ``ResidualRms`` takes its gyro's drift unit. Raises
    :class:`CanEdgeError` naming the message an id or name clashes with."""
    merged = copy.deepcopy(db)
    used = {frame_key(m.frame_id, bool(m.is_extended_frame)): m.name for m in db.messages}
    names = {m.name for m in db.messages}
    ids = daemon_frame_ids(len(drift_units), id_base)
    for name, frame_id in ids.items():
        template = re.sub(r"_\d+$", "_1", name)
        msg: Message = copy.deepcopy(own.get_message_by_name(template))
        if frame_id in used:
            hint = "give --id-base ID (a free range of standard ids) or --listen-only"
            raise CanEdgeError(f"{source}: the daemon's {name} would take standard id "
                              f"0x{frame_id:X}, which is {used[frame_id]} there; {hint}")
        if name in names:
            raise CanEdgeError(f"{source}: already has a message named {name} (not one of "
                              "the daemon's: its signals differ); give --listen-only")
        msg.name, msg.frame_id = name, frame_id
        if name.startswith("GS_SUMMARY_"):  # the residual RMS is in the gyro's drift unit
            unit = drift_units[int(name.rsplit("_", 1)[1]) - 1]
            for sig in msg.signals:
                if sig.name == "ResidualRms":
                    sig.unit = unit
        merged.messages.append(msg)
    have = {n.name for n in merged.nodes}
    for node in ("GYROSTAND", "STAND"):
        if node not in have:
            merged.nodes.append(Node(name=node, comment=None))
    merged.refresh()
    return merged


def dump_dbc(db: Database, path: str | Path, encoding: str = "cp1252") -> None:
    """Write ``db`` as a DBC file (cantools' writer) in ``encoding`` (cantools' default
    cp1252; the encoding the user's DBC was read in keeps every character it had)."""
    try:
        cantools.database.dump_file(db, str(path), encoding=encoding)
    except Exception as exc:  # cantools' writer raises a zoo of errors
        raise CanEdgeError(f"{path}: cannot write DBC: {exc}") from exc
