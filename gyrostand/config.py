"""YAML session configuration: loaded with ``yaml.safe_load``, validated at load, frozen.

Every problem is a :class:`~gyrostand.errors.ConfigError` whose message starts with the file
and the key path, e.g.::

    configs/demo.yaml: gyros[1].drift.signal: 'Drft' is not a signal of message
    GYRO_DRIFT_1 in dbc/gyrostand.dbc (known: Drift, Counter)

Unknown keys are errors. Relative paths (``dbc``, ``session.output``) resolve against the
folder of the config file. Messages are named by DBC name or frame id (int, e.g. ``0x100``;
add ``extended: true/false`` when a DBC has both kinds with that id); signals are resolved
in the DBC at load, including signals under a multiplexer. Shape (``simulate`` and
``responses`` optional; see ``configs/demo.yaml`` for every key)::

    session: {name: run-42, output: runs}
    bus: {interface: virtual, channel: stand0}     # passed to can.Bus as is
    dbc: dbc/gyrostand.dbc
    sampling: {dt: 1.0}
    gyros:
      - name: az
        drift: {message: GYRO_DRIFT_1, signal: Drift, counter: Counter}
        temperature: {message: GYRO_TEMP_1, signal: Temperature}
        model: [markov, temp, bias]
        identifiers: [lkf, lsq]
        result: {message: GS_RESULT_1, summary: GS_SUMMARY_1}
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import yaml

from gyrostand.can.codes import check_width, role_codes
from gyrostand.can.dbc import MessageRef, SignalRef, find_message, find_signal, load_dbc
from gyrostand.core import registry
from gyrostand.core.names import LKF_VARIANTS, VOCABULARY
from gyrostand.core.registry import LkfOptions
from gyrostand.errors import CanEdgeError, ConfigError

__all__ = [
    "MODEL_TERMS",
    "IDENTIFIERS",
    "ChannelConfig",
    "ResultConfig",
    "LkfConfig",
    "GyroConfig",
    "SamplingConfig",
    "ResponsesConfig",
    "ReconnectConfig",
    "SimGyroConfig",
    "SimulateConfig",
    "SessionConfig",
    "load_config",
    "parse_config",
]

log = logging.getLogger(__name__)

#: The model-term vocabulary of PRODUCT.md (the contract shared by config, CLI, JSON).
MODEL_TERMS = VOCABULARY
#: every identifier a gyro's ``identifiers:`` may name (the registry's)
IDENTIFIERS = registry.names()

#: Signals the daemon writes or reads in its own response/command messages.
RESULT_SIGNALS = ("Kind", "Identifier", "Param", "Value", "Std", "NParams", "Counter")
SUMMARY_SIGNALS = ("Identifier", "Status", "ModelTerms", "Samples", "ResidualRms")
STATUS_SIGNALS = ("Page", "Counter", "State", "Bins", "Gaps", "FramesDecoded",
                  "FramesRejected", "BusErrors", "LateFrames")
COMMAND_SIGNALS = ("Command", "Sequence")
ACK_SIGNALS = ("Command", "Sequence", "Result", "Reason")

_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
_PARAM_RE = re.compile(r"^([a-z_0-9]+)\.([A-Za-z_][A-Za-z_0-9]*)$")
MIN_RATE_HZ, MAX_RATE_HZ = 10.0, 1000.0
#: bounds of sampling.dt (s): frames at up to 1000 Hz in bins of at least 10 ms, at most 1 h
MIN_DT, MAX_DT = 0.01, 3600.0
#: sampling.max_gap / dt at most: the gap bins one forward jump may emit
MAX_GAP_BINS = 1_000_000
#: |sampling.epoch| and simulate.start at most (s; ~ year 5138): beyond, doubles of frame
#: time are coarser than 1e-5 s
MAX_EPOCH = 1e11
#: how frames are matched to a mapped message: full id, or J1939 PGN (see ChannelConfig)
MATCHES = ("id", "pgn")


@dataclass(frozen=True)
class ChannelConfig:
    """One measured channel: the DBC signal carrying it and, optionally, its rolling counter."""

    signal: SignalRef
    counter: SignalRef | None = None
    #: "id": frames match on the full id; "pgn": J1939, on the PGN whatever the priority
    #: and source address (extended ids only)
    match: str = "id"


@dataclass(frozen=True)
class ResultConfig:
    """Messages the daemon sends a gyro's results in (see ``dbc/README.md``)."""

    values: MessageRef
    summary: MessageRef | None = None


#: The online LKF of a gyro (its ``lkf:`` section): the lkf identifier's typed options
#: (:class:`~gyrostand.core.registry.LkfOptions`; a value left out is estimated from a
#: warm-up of ``warmup`` bins).
LkfConfig = LkfOptions


@dataclass(frozen=True)
class GyroConfig:
    name: str
    drift: ChannelConfig
    temperature: ChannelConfig
    model: tuple[str, ...]
    identifiers: tuple[str, ...]
    result: ResultConfig | None = None
    lkf: LkfConfig = field(default_factory=LkfConfig)

    def options(self, identifier: str) -> Any:
        """The typed options of ``identifier`` for this gyro: its section of the session
        file where it has one (``lkf:``), else the identifier's defaults."""
        ident = registry.get(identifier)
        section = getattr(self, ident.name, None)
        return section if isinstance(section, ident.Options) else ident.Options()


@dataclass(frozen=True)
class SamplingConfig:
    """Binning: ``dt`` bin width (s); ``epoch`` bin grid origin (s, None: the first frame's
    timestamp floored to a multiple of dt); ``buffer`` capacity of the decoded-sample buffer
    (samples); ``max_gap`` largest forward jump of frame time accepted (s)."""

    dt: float = 1.0
    epoch: float | None = None
    buffer: int = 65536
    max_gap: float = 3600.0


@dataclass(frozen=True)
class ResponsesConfig:
    """Frames the daemon sends and the command channel it listens to. ``period`` (s) between
    result rounds and ``heartbeat`` (s) between status frames, in frame time; ``node`` is
    this daemon's id in the command's ``Target`` (255 addresses every daemon)."""

    period: float = 10.0
    heartbeat: float = 1.0
    status: MessageRef | None = None
    ack: MessageRef | None = None
    command: MessageRef | None = None
    node: int = 1
    command_rate: float = 10.0


@dataclass(frozen=True)
class ReconnectConfig:
    """What the daemon does when the bus goes away (e.g. a ``remote`` server stops):
    retry opening it, waiting ``first_delay`` s, then twice as long each time up to
    ``max_delay`` s; after ``max_time`` s without a bus it stops in state ``fault``
    (0: at once). ``at_start``: s to keep trying, with the same backoff, when the bus
    cannot be opened at startup (an adapter not plugged in yet, a server not up yet;
    default 0: fail at once); a bus that can never open (unknown interface, a driver
    that is not installed, bad arguments) fails at once anyway."""

    max_time: float = 600.0
    first_delay: float = 0.25
    max_delay: float = 10.0
    at_start: float = 0.0


@dataclass(frozen=True)
class SimGyroConfig:
    """True model of a simulated gyro: terms and ``<term>.<param>`` values."""

    model: tuple[str, ...]
    params: Mapping[str, float]


@dataclass(frozen=True)
class SimulateConfig:
    """Stand simulator: temperature breakpoints ``(t s, T degC)``, linear between; frame
    rates (Hz); uniform timestamp jitter half-width (s); drop probability; sensor
    quantization step (physical units, 0 = only the DBC's resolution); ``start`` absolute
    timestamp of t = 0 (s since the Unix epoch: BLF stores absolute time)."""

    temperature: tuple[tuple[float, float], ...]
    gyros: Mapping[str, SimGyroConfig]
    seed: int = 0
    start: float = 1_700_000_000.0
    duration: float | None = None
    drift_rate: float = 100.0
    temperature_rate: float = 10.0
    interpolation: str = "hold"
    jitter: float = 0.0
    drop: float = 0.0
    drift_quantization: float = 0.0
    temperature_quantization: float = 0.0
    realtime: bool = False


@dataclass(frozen=True)
class SessionConfig:
    """A validated session. ``db`` is the loaded cantools database (not compared)."""

    path: Path
    name: str
    output: Path
    bus: Mapping[str, Any]
    dbc_path: Path
    sampling: SamplingConfig
    gyros: tuple[GyroConfig, ...]
    responses: ResponsesConfig
    simulate: SimulateConfig | None = None
    db: Any = field(default=None, repr=False, compare=False)
    reconnect: ReconnectConfig = field(default_factory=ReconnectConfig)
    #: live runs: each once-a-second acknowledgement is fdatasync'ed (raw log first,
    #: then samples and estimates), so it survives a power cut, not only a crash
    fsync: bool = True

    def gyro(self, name: str) -> GyroConfig:
        for g in self.gyros:
            if g.name == name:
                return g
        raise KeyError(name)


def load_config(path: str | Path) -> SessionConfig:
    """Read and validate a YAML session file. Raises :class:`ConfigError`."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config: {exc.strerror or exc}") from exc
    text = decode_text(raw, path)
    try:
        data = yaml.load(text, Loader=_StrictLoader)  # noqa: S506 (a SafeLoader)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: invalid YAML: {_clip(str(exc), 600)}") from exc
    return parse_config(data, source=path, base_dir=path.resolve().parent)


def decode_text(raw: bytes, path: str | Path) -> str:
    """A session file's bytes as text: UTF-8 (a leading BOM is dropped). UTF-16/32 and
    other encodings are refused with the byte offset. Raises :class:`ConfigError`."""
    for bom, name in ((b"\xff\xfe\x00\x00", "UTF-32"), (b"\x00\x00\xfe\xff", "UTF-32"),
                      (b"\xff\xfe", "UTF-16"), (b"\xfe\xff", "UTF-16")):
        if raw.startswith(bom):
            raise ConfigError(f"{path}: the file is {name} text; save it as UTF-8")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (byte {exc.start}: "
                          f"{raw[exc.start:exc.start + 4]!r}); save it as UTF-8") from None


class _StrictLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses aliases (``*name``: a few lines of them expand to
    gigabytes, the "billion laughs") and duplicate keys (YAML's last-one-wins would
    silently drop the first)."""

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            ev = self.peek_event()
            raise yaml.composer.ComposerError(
                None, None, f"aliases (*{_clip(str(ev.anchor), 40)}) are not accepted in a "
                "session file: write the value out", ev.start_mark)
        return super().compose_node(parent, index)

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                dup = key in seen
                seen.add(key)
            except TypeError:  # an unhashable key: SafeLoader says so below
                continue
            if dup:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping", node.start_mark,
                    f"duplicate key {_clip(repr(key), 60)}", key_node.start_mark)
        return super().construct_mapping(node, deep)


def parse_config(data: Any, source: str | Path = "<config>",
                 base_dir: str | Path | None = None) -> SessionConfig:
    """Validate an already parsed mapping (``base_dir`` resolves relative paths)."""
    return _Parser(str(source), Path(base_dir) if base_dir else Path.cwd()).session(data)


class _Parser:
    def __init__(self, source: str, base_dir: Path) -> None:
        self.source = source
        self.base = base_dir
        self.db: Any = None
        self.dbc_name = "DBC"
        self.dt = 1.0  # sampling.dt once parsed (bounds of rates given in 1/s)
        self.terms: tuple[str, ...] = MODEL_TERMS  # + plugin terms once loaded
        self.match = "id"  # the session's default channel `match` once parsed

    # -- helpers ---------------------------------------------------------------------
    def fail(self, path: str, msg: str) -> ConfigError:
        return ConfigError(f"{self.source}: {_clip(path, 200)}: {_clip(msg, 600)}")

    def mapping(self, value: Any, path: str, required: tuple[str, ...],
                optional: tuple[str, ...]) -> dict[str, Any]:
        if not isinstance(value, Mapping):
            raise self.fail(path, f"expected a mapping, got {_kind(value)}")
        unknown = [k for k in value if k not in required and k not in optional]
        if unknown:
            allowed = ", ".join(required + optional)
            raise self.fail(_join(path, str(unknown[0])),
                            f"unknown key (allowed here: {allowed})")
        for k in required:
            if k not in value:
                raise self.fail(_join(path, k), "missing required key")
        return dict(value)

    def number(self, value: Any, path: str, *, lo: float | None = None,
               hi: float | None = None, lo_open: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(path, f"expected a number, got {_kind(value)}")
        try:
            x = float(value)
        except OverflowError:
            raise self.fail(path, f"too large ({len(str(abs(value)))}-digit integer)") from None
        if not math.isfinite(x):
            raise self.fail(path, f"must be finite, got {value!r}")
        if lo is not None and (x < lo or (lo_open and x == lo)):
            raise self.fail(path, f"must be {'>' if lo_open else '>='} {lo:g}, got {value!r}")
        if hi is not None and x > hi:
            raise self.fail(path, f"must be <= {hi:g}, got {value!r}")
        return x

    def integer(self, value: Any, path: str, lo: int | None = None,
                hi: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(path, f"expected an integer, got {_kind(value)}")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise self.fail(path, f"must be in [{lo}, {hi}], got {value}")
        return value

    def string(self, value: Any, path: str) -> str:
        if not isinstance(value, str) or not value:
            raise self.fail(path, f"expected a non-empty string, got {_kind(value)}")
        return value

    def names(self, value: Any, path: str, vocabulary: tuple[str, ...]) -> tuple[str, ...]:
        if isinstance(value, str):
            value = [v.strip() for v in value.split(",")]
        if not isinstance(value, list) or not value:
            raise self.fail(path, f"expected a non-empty list, got {_kind(value)}")
        out: list[str] = []
        for i, v in enumerate(value):
            if v not in vocabulary:
                raise self.fail(f"{path}[{i}]", f"{v!r} is not one of: {', '.join(vocabulary)}")
            if v in out:
                raise self.fail(f"{path}[{i}]", f"{v!r} is listed twice")
            out.append(v)
        return tuple(out)

    def message(self, value: Any, path: str) -> MessageRef:
        ref, extended = value, None
        if isinstance(value, Mapping):
            m = self.mapping(value, path, ("message",), ("extended",))
            ref, extended = m["message"], self.boolean(m.get("extended"), f"{path}.extended")
            path = f"{path}.message"
        try:
            return find_message(self.db, ref, extended, source=self.dbc_name)[0]
        except CanEdgeError as exc:
            raise self.fail(path, str(exc)) from None

    def boolean(self, value: Any, path: str) -> bool | None:
        if value is None or isinstance(value, bool):
            return value
        raise self.fail(path, f"expected true or false, got {_kind(value)}")

    def require_signals(self, ref: MessageRef, path: str, needed: tuple[str, ...],
                        role: str | None = None) -> None:
        """``ref`` must carry the signals ``needed``; for a message of the daemon's in
        ``role`` (``result``, ``summary``, ``status``, ``ack``, ``command``) also the value
        tables of its codes (:func:`gyrostand.can.codes.role_codes`)."""
        msg = self.db.get_message_by_name(ref.name)
        have = {s.name for s in msg.signals}
        missing = [s for s in needed if s not in have]
        if missing:
            raise self.fail(path, f"message {ref.name} lacks signal(s) {', '.join(missing)} "
                                  f"needed here (see dbc/README.md)")
        if role is not None:
            try:
                role_codes(msg, role, self.dbc_name)
            except CanEdgeError as exc:
                raise self.fail(path, str(exc)) from None

    def require_width(self, ref: MessageRef, path: str, model: tuple[str, ...]) -> None:
        """The summary's ``ModelTerms`` must have a bit for every term of ``model``."""
        from gyrostand.can.bus import model_terms_mask

        try:
            check_width(self.db.get_message_by_name(ref.name), "ModelTerms",
                        model_terms_mask(model), f"the model {', '.join(model)}",
                        self.dbc_name)
        except CanEdgeError as exc:
            raise self.fail(path, str(exc)) from None

    # -- sections --------------------------------------------------------------------
    def session(self, data: Any) -> SessionConfig:
        top = self.mapping(data, "<top>", ("session", "bus", "dbc", "gyros"),
                           ("sampling", "responses", "simulate", "reconnect", "match",
                            "plugins"))
        self.match = top.get("match", "id")  # the default of every channel's `match`
        if self.match not in MATCHES:
            raise self.fail("match", f"{self.match!r} is not one of: {', '.join(MATCHES)}")
        sess = self.mapping(top["session"], "session", ("name",), ("output", "fsync"))
        name = self.string(sess["name"], "session.name")
        if not _NAME_RE.match(name):
            raise self.fail("session.name", f"{name!r}: use letters, digits, '_', '-', '.'")
        output = (self.base / self.string(sess.get("output", "runs"), "session.output")).resolve()
        fsync = bool(self.boolean(sess.get("fsync", True), "session.fsync"))
        bus = top["bus"]
        if not isinstance(bus, Mapping) or not bus:
            raise self.fail("bus", f"expected a mapping of can.Bus arguments, got {_kind(bus)}")
        if "interface" not in bus:
            raise self.fail("bus.interface", "missing required key")
        self.string(bus["interface"], "bus.interface")
        self.dbc_name = self.string(top["dbc"], "dbc")
        dbc_path = (self.base / self.dbc_name).resolve()
        try:
            self.db = load_dbc(dbc_path)
        except CanEdgeError as exc:
            raise self.fail("dbc", str(exc)) from None
        sampling = self.sampling(top.get("sampling", {}))
        self.terms = self.plugins(top.get("plugins"))
        gyros_raw = top["gyros"]
        if not isinstance(gyros_raw, list) or not gyros_raw:
            raise self.fail("gyros", f"expected a non-empty list, got {_kind(gyros_raw)}")
        gyros = tuple(self.gyro(g, f"gyros[{i}]") for i, g in enumerate(gyros_raw))
        seen: dict[str, int] = {}
        for i, g in enumerate(gyros):
            if g.name in seen:
                raise self.fail(f"gyros[{i}].name", f"{g.name!r} repeats gyros[{seen[g.name]}]")
            seen[g.name] = i
        self.check_channel_clashes(gyros)
        responses = self.responses(top.get("responses", {}))
        self.check_own_messages(gyros, responses)
        simulate = None
        if top.get("simulate") is not None:
            simulate = self.simulate(top["simulate"], [g.name for g in gyros])
        reconnect = self.reconnect(top.get("reconnect") or {})
        return SessionConfig(
            path=Path(self.source), name=name, output=output, fsync=fsync,
            bus=MappingProxyType(dict(bus)), dbc_path=dbc_path, sampling=sampling,
            gyros=gyros, responses=responses, simulate=simulate, db=self.db,
            reconnect=reconnect,
        )

    def plugins(self, value: Any) -> tuple[str, ...]:
        """Load the term plugins (installed entry points, then ``plugins: [module, ...]``):
        the model terms the rest of the file may use."""
        from gyrostand.errors import ModelError
        from gyrostand.plugins import known_terms, load_entry_points, load_modules

        try:
            load_entry_points()
        except ModelError as exc:
            raise self.fail("plugins", str(exc)) from None
        mods = [] if value is None else value
        if not isinstance(mods, list) or not all(isinstance(m, str) and m for m in mods):
            raise self.fail("plugins", f"expected a list of module names, got {_kind(value)}")
        for i, m in enumerate(mods):
            try:
                load_modules([m])
            except ModelError as exc:
                raise self.fail(f"plugins[{i}]", str(exc)) from None
        return known_terms()

    def reconnect(self, value: Any) -> ReconnectConfig:
        m = self.mapping(value, "reconnect", (), ("max_time", "first_delay", "max_delay",
                                                  "at_start"))
        max_time = self.number(m.get("max_time", 600.0), "reconnect.max_time", lo=0.0)
        first = self.number(m.get("first_delay", 0.25), "reconnect.first_delay", lo=0.0,
                            lo_open=True)
        most = self.number(m.get("max_delay", 10.0), "reconnect.max_delay", lo=first)
        at_start = self.number(m.get("at_start", 0.0), "reconnect.at_start", lo=0.0)
        return ReconnectConfig(max_time, first, most, at_start)

    def sampling(self, value: Any) -> SamplingConfig:
        m = self.mapping(value, "sampling", (), ("dt", "epoch", "buffer", "max_gap"))
        dt = self.number(m.get("dt", 1.0), "sampling.dt", lo=MIN_DT, hi=MAX_DT)
        epoch = m.get("epoch")
        if epoch is not None:
            # far from 0 a double cannot tell frame times a bin apart (1e20 s: 16 384 s)
            epoch = self.number(epoch, "sampling.epoch", lo=-MAX_EPOCH, hi=MAX_EPOCH)
        buffer = self.integer(m.get("buffer", 65536), "sampling.buffer", 16, 100_000_000)
        max_gap = self.number(m.get("max_gap", 3600.0), "sampling.max_gap", lo=dt,
                              hi=MAX_GAP_BINS * dt)
        self.dt = dt
        return SamplingConfig(dt, epoch, buffer, max_gap)

    def channel(self, value: Any, path: str) -> ChannelConfig:
        m = self.mapping(value, path, ("message", "signal"), ("extended", "counter", "match"))
        ext = self.boolean(m.get("extended"), f"{path}.extended")
        msg = self.message({"message": m["message"], "extended": ext}, path)
        match = m.get("match", self.match)
        if match not in MATCHES:
            raise self.fail(f"{path}.match", f"{match!r} is not one of: {', '.join(MATCHES)}")
        if match == "pgn" and not msg.is_extended:
            raise self.fail(f"{path}.match", f"match: pgn needs a 29-bit (J1939) id; "
                                             f"{msg.describe()} is standard")
        dbc_msg = self.db.get_message_by_name(msg.name)
        if msg.length > 8 and not dbc_msg.is_fd:
            raise self.fail(f"{path}.message", f"{msg.describe()} is {msg.length} bytes: "
                            "classic CAN carries at most 8 in one frame, and multi-frame "
                            "messages (J1939 TP, ISO-TP) are not reassembled; if the device "
                            "sends it as one CAN FD frame, say so in the DBC "
                            "(BA_ \"VFrameFormat\" BO_ ... 14)")
        sig = self.string(m["signal"], f"{path}.signal")
        try:
            ref = find_signal(self.db, msg.name, sig, source=self.dbc_name)
        except CanEdgeError as exc:
            raise self.fail(f"{path}.signal", str(exc)) from None
        counter = None
        if m.get("counter") is not None:
            cname = self.string(m["counter"], f"{path}.counter")
            try:
                counter = find_signal(self.db, msg.name, cname, source=self.dbc_name)
            except CanEdgeError as exc:
                raise self.fail(f"{path}.counter", str(exc)) from None
        return ChannelConfig(ref, counter, match)

    def gyro(self, value: Any, path: str) -> GyroConfig:
        m = self.mapping(value, path, ("name", "drift", "temperature", "model"),
                         ("identifiers", "result", "lkf"))
        name = self.string(m["name"], f"{path}.name")
        if not _NAME_RE.match(name):
            raise self.fail(f"{path}.name", f"{name!r}: use letters, digits, '_', '-', '.'")
        drift = self.channel(m["drift"], f"{path}.drift")
        temp = self.channel(m["temperature"], f"{path}.temperature")
        model = self.names(m["model"], f"{path}.model", self.terms)
        self.model_of(model, f"{path}.model")
        idents = self.names(m.get("identifiers", ["lkf", "lsq"]), f"{path}.identifiers",
                            IDENTIFIERS)
        # an identifier needing a term the model lacks (lkf linearises the markov state's
        # dynamics, lsq regresses on it) cannot identify it at all; terms it cannot
        # represent otherwise are reported at run time (status failed, with the reason)
        lacking = {t: [i for i in idents if t in registry.get(i).requires]
                   for t in dict.fromkeys(t for i in idents for t in registry.get(i).requires)
                   if t not in model}
        for term, need in lacking.items():
            if "identifiers" in m:
                raise self.fail(f"{path}.identifiers", f"{', '.join(need)} need(s) {term!r} "
                                f"in the model ({', '.join(model)}); use identifiers: [ml]")
            log.warning("%s: %s: the model (%s) has no %s term: %s need it, so only ml "
                        "identifies this gyro (at the end of the run)",
                        self.source, path, ", ".join(model), term, " and ".join(need))
            idents = tuple(i for i in idents if i not in need)
        result = None
        if m.get("result") is not None:
            r = self.mapping(m["result"], f"{path}.result", ("message",), ("summary",))
            values = self.message(r["message"], f"{path}.result.message")
            self.require_signals(values, f"{path}.result.message", RESULT_SIGNALS, "result")
            summary = None
            if r.get("summary") is not None:
                summary = self.message(r["summary"], f"{path}.result.summary")
                self.require_signals(summary, f"{path}.result.summary", SUMMARY_SIGNALS,
                                     "summary")
                self.require_width(summary, f"{path}.result.summary", model)
            result = ResultConfig(values, summary)
        lkf = self.lkf(m.get("lkf") or {}, f"{path}.lkf", model)
        return GyroConfig(name, drift, temp, model, idents, result, lkf)

    def lkf(self, value: Any, path: str, model: tuple[str, ...]) -> LkfConfig:
        keys = ("beta0", "gamma0", "b0", "sigma", "white_sigma")
        m = self.mapping(value, path, (), keys + ("held", "warmup", "iterate", "variant",
                                                   "relinearize_every", "soaked"))
        vals: dict[str, float | None] = {}
        for k in keys:
            v = m.get(k)
            if v is None or v == "auto":
                vals[k] = None
                continue
            lo, lo_open = {"beta0": (0.0, True), "sigma": (0.0, True),
                           "white_sigma": (0.0, False)}.get(k, (None, False))
            vals[k] = self.number(v, f"{path}.{k}", lo=lo, lo_open=lo_open)
        beta0 = vals.get("beta0")
        if beta0 is not None and beta0 * self.dt >= 1.0:
            raise self.fail(f"{path}.beta0", f"{beta0:g} 1/s must be below 1/sampling.dt = "
                            f"{1.0 / self.dt:g} (a correlation time shorter than one bin "
                            "cannot be identified from the bins)")
        held_in = m.get("held")
        held_raw = self.mapping({} if held_in is None else held_in, f"{path}.held", (),
                                tuple(held_in) if isinstance(held_in, Mapping) else ())
        names = self.model_of(model, path).param_names
        held: dict[str, float] = {}
        for k, v in held_raw.items():
            mt = _PARAM_RE.match(str(k))
            if not mt or mt.group(1) not in model:
                raise self.fail(f"{path}.held.{k}", "expected '<term>.<param>' of a term in "
                                                    "this gyro's model")
            if str(k) not in names:
                raise self.fail(f"{path}.held.{k}", f"not a parameter of this gyro's model "
                                f"(its parameters: {', '.join(names)})")
            held[str(k)] = self.number(v, f"{path}.held.{k}", lo=0.0)
        warmup = self.integer(m.get("warmup", 300), f"{path}.warmup", 10, 10_000_000)
        iterate = bool(self.boolean(m.get("iterate", False), f"{path}.iterate"))
        variant = m.get("variant", "relin")
        if variant not in LKF_VARIANTS:
            raise self.fail(f"{path}.variant", f"expected one of {', '.join(LKF_VARIANTS)}, "
                                               f"got {variant!r}")
        every = m.get("relinearize_every")
        every = None if every is None else self.integer(every, f"{path}.relinearize_every",
                                                        1, 10_000_000)
        soaked = bool(self.boolean(m.get("soaked", True), f"{path}.soaked"))
        return LkfConfig(held=MappingProxyType(held), warmup=warmup, iterate=iterate,
                         variant=variant, relinearize_every=every, soaked=soaked, **vals)

    def check_own_messages(self, gyros: tuple[GyroConfig, ...],
                           responses: ResponsesConfig) -> None:
        """A measured channel on a message the daemon itself sends or obeys (status, ack,
        command, a result or summary) would feed it its own frames, or data as commands."""
        own: dict[int, str] = {}
        for key in ("status", "ack", "command"):
            ref = getattr(responses, key)
            if ref is not None:
                own[ref.key] = f"responses.{key}"
        for i, g in enumerate(gyros):
            if g.result is not None:
                own[g.result.values.key] = f"gyros[{i}].result.message"
                if g.result.summary is not None:
                    own[g.result.summary.key] = f"gyros[{i}].result.summary"
        for i, g in enumerate(gyros):
            for ch, c in (("drift", g.drift), ("temperature", g.temperature)):
                where = own.get(c.signal.message.key)
                if where is not None:
                    raise self.fail(f"gyros[{i}].{ch}.message", f"{c.signal.message.name} is "
                                    f"the daemon's own message ({where})")

    def model_of(self, model: tuple[str, ...], path: str) -> Any:
        """The core :class:`~gyrostand.core.model.Model` of ``model`` (a ConfigError at
        ``path`` when the terms do not make one, so no run folder is started for it)."""
        from gyrostand.core.model import Model
        from gyrostand.errors import ModelError

        try:
            return Model.parse(list(model))
        except ModelError as exc:
            raise self.fail(path, str(exc)) from None

    def check_channel_clashes(self, gyros: tuple[GyroConfig, ...]) -> None:
        """A drift signal belongs to one gyro; a temperature signal may serve several (one
        sensor on a multi-axis IMU's board), but never also as a drift."""
        owner: dict[tuple[int, str], tuple[str, str]] = {}
        for i, g in enumerate(gyros):
            for ch, c in (("drift", g.drift), ("temperature", g.temperature)):
                key = (c.signal.message.key, c.signal.name)
                path = f"gyros[{i}].{ch}.signal"
                if key in owner and (ch == "drift" or owner[key][1] == "drift"):
                    raise self.fail(path, f"{c.signal.message.name}.{c.signal.name} is already "
                                          f"mapped by {owner[key][0]}")
                owner.setdefault(key, (path, ch))
        keys: dict[int, tuple[str, str]] = {}
        for i, g in enumerate(gyros):  # one message, one way of matching it
            for ch, c in (("drift", g.drift), ("temperature", g.temperature)):
                k = c.signal.message.key
                path = f"gyros[{i}].{ch}.match"
                if k in keys and keys[k][1] != c.match:
                    raise self.fail(path, f"{c.signal.message.name} is matched by "
                                          f"{keys[k][1]} at {keys[k][0]}")
                keys.setdefault(k, (path, c.match))

    def responses(self, value: Any) -> ResponsesConfig:
        m = self.mapping(value, "responses", (),
                         ("period", "heartbeat", "status", "ack", "command", "node",
                          "command_rate"))
        period = self.number(m.get("period", 10.0), "responses.period", lo=0.0, lo_open=True)
        beat = self.number(m.get("heartbeat", 1.0), "responses.heartbeat", lo=0.0,
                           lo_open=True)
        refs: dict[str, MessageRef | None] = {}
        for key, needed in (("status", STATUS_SIGNALS), ("ack", ACK_SIGNALS),
                            ("command", COMMAND_SIGNALS)):
            refs[key] = None
            if m.get(key) is not None:
                refs[key] = self.message(m[key], f"responses.{key}")
                self.require_signals(refs[key], f"responses.{key}", needed,  # type: ignore[arg-type]
                                     key)
        node = self.integer(m.get("node", 1), "responses.node", 0, 254)
        rate = self.number(m.get("command_rate", 10.0), "responses.command_rate", lo=0.0,
                           lo_open=True)
        return ResponsesConfig(period, beat, refs["status"], refs["ack"], refs["command"], node,
                               rate)

    def simulate(self, value: Any, gyro_names: list[str]) -> SimulateConfig:
        p = "simulate"
        m = self.mapping(value, p, ("temperature", "gyros"),
                         ("seed", "start", "duration", "rates", "interpolation", "jitter",
                          "drop", "quantization", "realtime"))
        pts = m["temperature"]
        if not isinstance(pts, list) or len(pts) < 2:
            raise self.fail(f"{p}.temperature", "expected a list of at least 2 [t, T] points")
        bps: list[tuple[float, float]] = []
        for i, pt in enumerate(pts):
            q = f"{p}.temperature[{i}]"
            if not isinstance(pt, list) or len(pt) != 2:
                raise self.fail(q, f"expected [t, T] (s, degC), got {pt!r}")
            t = self.number(pt[0], q, lo=0.0)
            if bps and t <= bps[-1][0]:
                raise self.fail(q, f"times must increase, {t:g} after {bps[-1][0]:g}")
            bps.append((t, self.number(pt[1], q, lo=-273.15)))
        if bps[0][0] != 0.0:
            raise self.fail(f"{p}.temperature[0]", "the profile must start at t = 0")
        rates = self.mapping(m.get("rates", {}), f"{p}.rates", (), ("drift", "temperature"))
        r_drift = self.number(rates.get("drift", 100.0), f"{p}.rates.drift",
                              lo=MIN_RATE_HZ, hi=MAX_RATE_HZ)
        r_temp = self.number(rates.get("temperature", 10.0), f"{p}.rates.temperature",
                             lo=MIN_RATE_HZ, hi=MAX_RATE_HZ)
        jitter = self.number(m.get("jitter", 0.0), f"{p}.jitter", lo=0.0)
        if jitter >= 0.5 / max(r_drift, r_temp):
            raise self.fail(f"{p}.jitter", f"{jitter:g} s must stay below half the shortest "
                            f"frame period ({0.5 / max(r_drift, r_temp):g} s)")
        interp = m.get("interpolation", "hold")
        if interp not in ("hold", "linear"):
            raise self.fail(f"{p}.interpolation", f"{interp!r} is not one of: hold, linear")
        quant = self.mapping(m.get("quantization", {}), f"{p}.quantization", (),
                             ("drift", "temperature"))
        duration = m.get("duration")
        if duration is not None:
            duration = self.number(duration, f"{p}.duration", lo=0.0, lo_open=True)
        sim_gyros = self.mapping(m["gyros"], f"{p}.gyros", (), tuple(gyro_names))
        truths: dict[str, SimGyroConfig] = {}
        for gname, spec in sim_gyros.items():
            q = f"{p}.gyros.{gname}"
            s = self.mapping(spec, q, ("model", "params"), ())
            model = self.names(s["model"], f"{q}.model", self.terms)
            kinds = {f"{t.name}.{prm.name}": prm.kind
                     for t in self.model_of(model, f"{q}.model").terms for prm in t.params}
            params = self.mapping(s["params"], f"{q}.params", (),
                                  tuple(s["params"]) if isinstance(s["params"], Mapping)
                                  else ())
            vals: dict[str, float] = {}
            for k, v in params.items():
                mt = _PARAM_RE.match(str(k))
                if not mt or mt.group(1) not in self.terms:
                    raise self.fail(f"{q}.params.{k}", "expected '<term>.<param>' with a term "
                                    f"of: {', '.join(self.terms)}")
                if mt.group(1) not in model:
                    raise self.fail(f"{q}.params.{k}", f"term {mt.group(1)!r} is not in "
                                    f"{q}.model")
                kind = kinds.get(str(k))
                if kind is None:
                    raise self.fail(f"{q}.params.{k}", f"not a parameter of {q}.model (its "
                                    f"parameters: {', '.join(kinds)})")
                if kind in ("rate", "time"):  # positive, and resolvable on the bins
                    vals[str(k)] = self.number(v, f"{q}.params.{k}", lo=0.0, lo_open=True)
                    if kind == "rate" and vals[str(k)] * self.dt >= 1.0:
                        raise self.fail(f"{q}.params.{k}", f"{vals[str(k)]:g} 1/s must be "
                                        f"below 1/sampling.dt = {1.0 / self.dt:g}")
                else:
                    vals[str(k)] = self.number(v, f"{q}.params.{k}",
                                               lo=0.0 if kind == "std" else None)
            truths[gname] = SimGyroConfig(model, MappingProxyType(vals))
        return SimulateConfig(
            temperature=tuple(bps), gyros=MappingProxyType(truths),
            seed=self.integer(m.get("seed", 0), f"{p}.seed", 0, 2**63 - 1),
            start=self.number(m.get("start", 1_700_000_000.0), f"{p}.start", lo=0.0,
                              hi=MAX_EPOCH),
            duration=duration, drift_rate=r_drift, temperature_rate=r_temp,
            interpolation=interp, jitter=jitter,
            drop=self.number(m.get("drop", 0.0), f"{p}.drop", lo=0.0, hi=0.99),
            drift_quantization=self.number(quant.get("drift", 0.0),
                                           f"{p}.quantization.drift", lo=0.0),
            temperature_quantization=self.number(quant.get("temperature", 0.0),
                                                 f"{p}.quantization.temperature", lo=0.0),
            realtime=bool(self.boolean(m.get("realtime", False), f"{p}.realtime")),
        )


def _join(path: str, key: str) -> str:
    return key if path == "<top>" else f"{path}.{key}"


def _kind(value: Any) -> str:
    if value is None:
        return "nothing"
    return f"{type(value).__name__} {_clip(repr(value), 80)}" if not isinstance(
        value, (dict, list)) else type(value).__name__


def _clip(text: str, n: int) -> str:
    """``text`` cut to ``n`` characters (an error message quotes input, never all of it)."""
    return text if len(text) <= n else f"{text[:n]}... ({len(text)} characters)"
