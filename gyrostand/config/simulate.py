"""The parser's ``simulate:`` section (the stand simulator's truth)."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

from .reader import Reader
from .schema import (
    MAX_EPOCH,
    MAX_RATE_HZ,
    MIN_RATE_HZ,
    PARAM_RE,
    SimGyroConfig,
    SimulateConfig,
)


class SimulateSection(Reader):
    """Mixin of :class:`~gyrostand.config.parser.Parser`: ``simulate:``."""

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
                mt = PARAM_RE.match(str(k))
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
                if kind in ("rate", "time", "width"):  # positive, resolvable on the bins
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


