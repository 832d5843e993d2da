"""The parser's gyro sections: channels (with `match`), the gyro, its `lkf:` section,
its model, and the check that no drift signal is mapped twice."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

from gyrostand.can.dbc import find_signal
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
    log,
)


class GyroSections(Reader):
    """Mixin of :class:`~gyrostand.config.parser.Parser`: the ``gyros:`` entries."""

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
        if not NAME_RE.match(name):
            raise self.fail(f"{path}.name", f"{name!r}: use letters, digits, '_', '-', '.'")
        drift = self.channel(m["drift"], f"{path}.drift")
        temp = self.channel(m["temperature"], f"{path}.temperature")
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

