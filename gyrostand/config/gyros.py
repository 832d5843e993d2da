"""The parser's gyro sections: channels (with `match`), the gyro, its `lkf:` section,
its model, and the check that no drift signal is mapped twice."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

from gyrostand.can.dbc import find_signal
from gyrostand.can.units import Conversion, UnitError, rate_conversion, temperature_conversion
from gyrostand.can.validity import status_signals
from gyrostand.core import registry
from gyrostand.core.names import LKF_VARIANTS
from gyrostand.errors import CanEdgeError

from .reader import Reader
from .schema import (
    IDENTIFIERS,
    MATCHES,
    NAME_RE,
    PARAM_RE,
    RESULT_SIGNALS,
    SUMMARY_SIGNALS,
    ChannelConfig,
    GyroConfig,
    LkfConfig,
    ResultConfig,
    kind_of,
    log,
)


class GyroSections(Reader):
    """Mixin of :class:`~gyrostand.config.parser.Parser`: the ``gyros:`` entries."""

    def channel(self, value: Any, path: str, role: str = "drift") -> ChannelConfig:
        m = self.mapping(value, path, ("message", "signal"),
                         ("extended", "counter", "match", "unit", "valid", "source_address"))
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
        scale = getattr(dbc_msg.get_signal_by_name(ref.name), "scale", 1)
        if scale == 0:
            raise self.fail(f"{path}.signal", f"{msg.name}.{sig} has scale 0 in the DBC: "
                            "every raw value decodes to its offset")
        counter = None
        if m.get("counter") is not None:
            cname = self.string(m["counter"], f"{path}.counter")
            if cname == sig:
                raise self.fail(f"{path}.counter", f"{cname} is the channel's own signal, "
                                "not a rolling counter")
            try:
                counter = find_signal(self.db, msg.name, cname, source=self.dbc_name)
            except CanEdgeError as exc:
                raise self.fail(f"{path}.counter", str(exc)) from None
        convert = self.channel_unit(m, path, role, ref)
        valid = self.validity(m.get("valid"), f"{path}.valid", dbc_msg, ref,
                              counter.name if counter else None)
        sa = None
        if m.get("source_address") is not None:
            if match != "pgn":
                raise self.fail(f"{path}.source_address", "needs match: pgn (a full id "
                                "already names its source address)")
            sa = self.integer(m["source_address"], f"{path}.source_address", 0, 0xFF)
        unit = convert.target if convert is not None else (m.get("unit") or ref.unit)
        return ChannelConfig(ref, counter, match, convert, valid, sa, str(unit))

    def channel_unit(self, m: Mapping, path: str, role: str, ref) -> Conversion | None:
        """The conversion of the channel's values to °C / the session's drift unit, from
        the DBC signal's unit (or the channel's ``unit:``, which overrides it); a unit
        the project cannot convert is an error naming the key path."""
        where = f"{path}.unit" if m.get("unit") is not None else f"{path}.signal"
        unit = ref.unit if m.get("unit") is None else self.string(m["unit"], where)
        if not unit.strip():
            log.warning("%s: %s: %s.%s has no unit in the DBC: taken as %s (say `unit:` "
                        "to be sure)", self.source, path, ref.message.name, ref.name,
                        "degC" if role == "temperature" else self.drift_unit)
        try:
            if role == "temperature":
                return temperature_conversion(unit)
            return rate_conversion(unit, self.drift_unit)
        except UnitError as exc:
            raise self.fail(where, f"{ref.message.name}.{ref.name}: {exc}") from None

    def validity(self, value: Any, path: str, dbc_msg, ref, counter: str | None
                 ) -> tuple[str, frozenset, bool] | None:
        """``valid: {signal: NAME, accept: [values]}``: frames whose NAME (a signal of
        the same message) is not one of ``accept`` are dropped; without it, the
        message's own validity signal (status/valid/qualifier with a value table naming
        an invalid state) drops the frames in such a state."""
        if value is None:
            found = status_signals(dbc_msg, [ref.name] + ([counter] if counter else []))
            if not found:
                return None
            name, bad = found[0]
            return (name, bad, False)
        v = self.mapping(value, path, ("signal", "accept"), ())
        name = self.string(v["signal"], f"{path}.signal")
        if name not in {s.name for s in dbc_msg.signals}:
            raise self.fail(f"{path}.signal", f"{dbc_msg.name} has no signal {name!r}")
        acc = v["accept"]
        if not isinstance(acc, list) or not acc:
            raise self.fail(f"{path}.accept", f"expected a non-empty list of values, got "
                                              f"{kind_of(acc)}")
        vals = frozenset(self.number(x, f"{path}.accept[{i}]") for i, x in enumerate(acc))
        return (name, vals, True)

    def gyro(self, value: Any, path: str) -> GyroConfig:
        m = self.mapping(value, path, ("name", "drift", "temperature", "model"),
                         ("identifiers", "result", "lkf"))
        name = self.string(m["name"], f"{path}.name")
        if not NAME_RE.match(name):
            raise self.fail(f"{path}.name", f"{name!r}: use letters, digits, '_', '-', '.'")
        drift = self.channel(m["drift"], f"{path}.drift", "drift")
        temp = self.channel(m["temperature"], f"{path}.temperature", "temperature")
        model = self.names(m["model"], f"{path}.model", self.terms)
        core_model = self.model_of(model, f"{path}.model")
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
        # every identifier left checks the model as it would at its first bin (the lsq of a
        # model with temp_lag, the lkf of a term without a causal regressor): refused here,
        # naming the term, not at every bin of the run
        for ident in idents:
            why = registry.get(ident).refusal(core_model)
            if why is None:
                continue
            if "identifiers" in m:
                raise self.fail(f"{path}.identifiers", f"{ident} cannot identify this model: "
                                f"{why}")
            log.warning("%s: %s: %s cannot identify the model (%s): %s; the others do",
                        self.source, path, ident, ", ".join(model), why)
            idents = tuple(i for i in idents if i != ident)
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
            mt = PARAM_RE.match(str(k))
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
        return LkfConfig(beta0=vals["beta0"], gamma0=vals["gamma0"], b0=vals["b0"],
                         sigma=vals["sigma"], white_sigma=vals["white_sigma"],
                         held=MappingProxyType(held), warmup=warmup, iterate=iterate,
                         variant=variant, relinearize_every=every, soaked=soaked)

    def check_channel_clashes(self, gyros: tuple[GyroConfig, ...]) -> None:
        """A drift signal belongs to one gyro; a temperature signal may serve several (one
        sensor on a multi-axis IMU's board), but never also as a drift."""
        owner: dict[tuple[int, str, int | None], tuple[str, str]] = {}
        for i, g in enumerate(gyros):
            for ch, c in (("drift", g.drift), ("temperature", g.temperature)):
                # one J1939 device per source address: the same signal of another is free
                key = (c.signal.message.key, c.signal.name, c.source_address)
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
                how = c.match + (" with source_address" if c.source_address is not None
                                 else "")
                if k in keys and keys[k][1] != how:
                    where = path if c.match != keys[k][1].split()[0] else \
                        f"gyros[{i}].{ch}.source_address"
                    raise self.fail(where, f"{c.signal.message.name} is matched by "
                                           f"{keys[k][1]} at {keys[k][0]}")
                keys.setdefault(k, (path, how))

