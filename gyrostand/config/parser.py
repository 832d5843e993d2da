"""Loading and validating a session file: YAML with duplicate-key checks, then the parser."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

import yaml

from gyrostand.can.dbc import MessageRef, load_dbc
from gyrostand.can.units import DEFAULT_DRIFT_UNIT, UnitError, rate_conversion
from gyrostand.errors import CanEdgeError, ConfigError, SessionFileNotFoundError
from gyrostand.runfolder.layout import DATA_FORMATS

from .gyros import GyroSections
from .schema import (
    ACK_SIGNALS,
    COMMAND_SIGNALS,
    MATCHES,
    MAX_DT,
    MAX_EPOCH,
    MAX_GAP_BINS,
    MIN_DT,
    NAME_RE,
    STATUS_SIGNALS,
    GyroConfig,
    ReconnectConfig,
    ResponsesConfig,
    SamplingConfig,
    SessionConfig,
    clip,
    kind_of,
)
from .simulate import SimulateSection


def load_config(path: str | Path) -> SessionConfig:
    """Read and validate a YAML session file. Raises :class:`ConfigError`."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise SessionFileNotFoundError(f"{path}: cannot read config: {exc.strerror or exc}"
                                       ) from exc
    return parse_text(decode_text(raw, path), path)


def parse_text(text: str, path: str | Path) -> SessionConfig:
    """Validate a session file's text as if read from ``path`` (its relative paths
    resolve against ``path``'s folder), e.g. an edit before it is written. Raises
    :class:`ConfigError`."""
    path = Path(path)
    try:
        data = yaml.load(text, Loader=_StrictLoader)  # noqa: S506 (a SafeLoader)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: invalid YAML: {clip(str(exc), 600)}") from exc
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


def missing_packages(formats: tuple[str, ...]) -> str:
    """What is missing to write ``formats`` (of :data:`DATA_FORMATS`): a sentence naming
    each absent package and how to install it, or ``""``."""
    import importlib.util

    absent = [f"{f} needs the {DATA_FORMATS[f]} package" for f in formats
              if importlib.util.find_spec(DATA_FORMATS[f]) is None]
    return "; ".join(absent) + " (pip install 'gyrostand[formats]')" if absent else ""


class _StrictLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses aliases (``*name``: a few lines of them expand to
    gigabytes, the "billion laughs") and duplicate keys (YAML's last-one-wins would
    silently drop the first)."""

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            ev = self.peek_event()
            raise yaml.composer.ComposerError(
                None, None, f"aliases (*{clip(str(ev.anchor), 40)}) are not accepted in a "
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
                    f"duplicate key {clip(repr(key), 60)}", key_node.start_mark)
        return super().construct_mapping(node, deep)


def parse_config(data: Any, source: str | Path = "<config>",
                 base_dir: str | Path | None = None) -> SessionConfig:
    """Validate an already parsed mapping (``base_dir`` resolves relative paths)."""
    return _Parser(str(source), Path(base_dir) if base_dir else Path.cwd()).session(data)


class _Parser(GyroSections, SimulateSection):
    """The validating parser: the top-level sections (the primitives in
    :class:`~.reader.Reader`, the gyro and simulate sections in their mixins)."""

    def session(self, data: Any) -> SessionConfig:
        top = self.mapping(data, "<top>", ("session", "bus", "dbc", "gyros"),
                           ("sampling", "responses", "simulate", "reconnect", "match",
                            "plugins"))
        self.match = top.get("match", "id")  # the default of every channel's `match`
        if self.match not in MATCHES:
            raise self.fail("match", f"{self.match!r} is not one of: {', '.join(MATCHES)}")
        sess = self.mapping(top["session"], "session", ("name",),
                            ("output", "fsync", "formats", "drift_unit"))
        name = self.string(sess["name"], "session.name")
        if not NAME_RE.match(name):
            raise self.fail("session.name", f"{name!r}: use letters, digits, '_', '-', '.'")
        output = (self.base / self.string(sess.get("output", "runs"), "session.output")).resolve()
        fsync = bool(self.boolean(sess.get("fsync", True), "session.fsync"))
        formats: tuple[str, ...] = ()
        if sess.get("formats") not in (None, []):
            formats = self.names(sess["formats"], "session.formats", tuple(DATA_FORMATS))
            missing = missing_packages(formats)
            if missing:
                raise self.fail("session.formats", missing)
        # session.drift_unit; left out: the drift signals' own unit when they share one
        # (no conversion), else deg/h (decided once the gyros are read)
        self.drift_unit = self.string(sess.get("drift_unit", DEFAULT_DRIFT_UNIT),
                                      "session.drift_unit")
        try:
            rate_conversion(self.drift_unit, self.drift_unit)
        except UnitError as exc:
            raise self.fail("session.drift_unit", str(exc)) from None
        bus = self.bus(top["bus"])
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
            raise self.fail("gyros", f"expected a non-empty list, got {kind_of(gyros_raw)}")
        gyros = tuple(self.gyro(g, f"gyros[{i}]") for i, g in enumerate(gyros_raw))
        if "drift_unit" not in sess:
            gyros = self.common_drift_unit(gyros)
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
            self.check_profile_range(simulate.temperature, gyros)
        reconnect = self.reconnect(top.get("reconnect") or {})
        return SessionConfig(
            path=Path(self.source), name=name, output=output, fsync=fsync, formats=formats,
            bus=MappingProxyType(dict(bus)), dbc_path=dbc_path, sampling=sampling,
            gyros=gyros, responses=responses, simulate=simulate, db=self.db,
            reconnect=reconnect, drift_unit=self.drift_unit,
        )

    def common_drift_unit(self, gyros: tuple[GyroConfig, ...]) -> tuple[GyroConfig, ...]:
        """Without ``session.drift_unit``: the drift signals' unit when every one has the
        same (known) unit, so nothing is converted; else deg/h, each converted."""
        units = {(g.drift.convert.source if g.drift.convert else g.drift.signal.unit)
                 for g in gyros}
        units.discard("")
        if len(units) != 1:
            return gyros
        (unit,) = units
        self.drift_unit = unit
        return tuple(dataclasses.replace(g, drift=dataclasses.replace(
            g.drift, convert=None, unit=unit))
                     for g in gyros)

    def check_profile_range(self, points, gyros: tuple[GyroConfig, ...]) -> None:
        """A simulated temperature the DBC signal cannot carry would be saturated at its
        range without a word: refused, naming the breakpoint and the range (°C)."""
        for g in gyros:
            ch = g.temperature
            lo, hi = ch.signal.minimum, ch.signal.maximum
            if ch.convert is not None:
                lo = None if lo is None else ch.convert(lo)
                hi = None if hi is None else ch.convert(hi)
            for i, (_, temp) in enumerate(points):
                if (lo is not None and temp < lo) or (hi is not None and temp > hi):
                    raise self.fail(f"simulate.temperature[{i}]", f"{temp:g} degC is outside "
                                    f"the range of {ch.signal.message.name}."
                                    f"{ch.signal.name} ({lo:g} .. {hi:g} degC): the "
                                    "simulated stand would saturate it")

    def bus(self, value: Any) -> dict[str, Any]:
        """``bus:``, the ``can.Bus`` arguments: a mapping, maybe empty (``bus: {}``; a key
        it lacks comes from the command line or python-can's own config, resolved by
        :func:`gyrostand.can.busconfig.resolve_bus`); ``interface``, when given, a string."""
        if value is None:
            value = {}
        if not isinstance(value, Mapping):
            raise self.fail("bus", f"expected a mapping of can.Bus arguments, got "
                                   f"{kind_of(value)}")
        for key in value:
            if not isinstance(key, str) or not key.isidentifier():
                raise self.fail(f"bus.{clip(str(key), 40)}",
                                "not a can.Bus argument name (expected an identifier)")
        if "interface" in value:
            self.string(value["interface"], "bus.interface")
        return dict(value)

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
            raise self.fail("plugins", f"expected a list of module names, got {kind_of(value)}")
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
                for key, ref in (("message", g.result.values), ("summary", g.result.summary)):
                    if ref is None:
                        continue
                    if ref.key in own:  # two gyros' results in one frame: unreadable
                        raise self.fail(f"gyros[{i}].result.{key}", f"{ref.name} is "
                                        f"already {own[ref.key]}")
                    own[ref.key] = f"gyros[{i}].result.{key}"
        for i, g in enumerate(gyros):
            for ch, c in (("drift", g.drift), ("temperature", g.temperature)):
                where = own.get(c.signal.message.key)
                if where is not None:
                    raise self.fail(f"gyros[{i}].{ch}.message", f"{c.signal.message.name} is "
                                    f"the daemon's own message ({where})")

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

