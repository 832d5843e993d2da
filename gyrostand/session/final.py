"""The end of a run: batch fits of every gyro's 1-s series, ``result.json`` and the report.

Each gyro is fitted with its configured identifiers plus ``ml`` (always), on the bins of
the whole run (time relative to the gyro's first bin, s). ``lkf`` is the online LKF at
stop (the daemon's filter after a last re-linearisation over every bin: the value the last
CAN round sends, one meaning in every output); ``lkf_batch`` is the same filter run again
over ``samples.csv`` to its fixed point (the paper variant: one pass at the session's
point, values the config leaves out from a fit of the whole record, re-linearised only
with ``lkf.iterate: true``). A method that fails is recorded with its error; it never
stops the others.

``result.json``::

    {"session": ..., "source": "live" | "replay of <log>", "run_dir": ..., "dt": 1.0,
     "gyros": {"<gyro>": {"model": [...], "t0": <first bin start, s>,
                          "bins": n, "gaps": n, "observed": n,
                          "fits": {"lkf": FitResult.to_dict(), "lkf_batch": {...},
                                   "ml": {...},
                                   "lsq": {"error": "..."}},
                          "online": {"lkf": {"status": ..., "parameters": {...}}},
                          "units": {"drift": "deg/h", "temp": "degC", "t": "s",
                                    "parameters": {"temp.gamma": "(deg/h)/(s·°C)", ...}}}},
     "stats": {decoder, binner, recorder, responses, commands, timing}}
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..config import GyroConfig, SessionConfig
from ..core.data import Samples
from ..core.model import Model
from ..core.registry import REGISTRY
from ..core.results import FitResult
from ..core.summary import unit_text
from ..errors import GyrostandError
from ..runfolder import finite, json_safe, write_atomic, write_json
from .online import LkfPoint, OnlineEstimate

__all__ = ["GyroFinal", "fit_gyro", "write_result_json", "write_report", "final_methods",
           "write_provisional_result"]

log = logging.getLogger(__name__)


#: the identifier every final fit runs, whatever the gyro's ``identifiers:``
ALWAYS = "ml"


def final_methods(gyro: GyroConfig) -> tuple[str, ...]:
    """The configured identifiers, then ``ml`` if not among them."""
    return tuple(dict.fromkeys((*gyro.identifiers, ALWAYS)))


@dataclass
class GyroFinal:
    """Final fits of one gyro: ``fits[method]`` a :class:`FitResult` or an error string."""

    gyro: str
    model: Model
    t0: float
    bins: int
    gaps: int
    observed: int
    fits: dict[str, FitResult | str] = field(default_factory=dict)
    online: list[OnlineEstimate] = field(default_factory=list)
    #: the drift's unit (the DBC signal's), printed in place of the model's ``y``
    unit: str = "y"

    def to_dict(self) -> dict[str, Any]:
        fits = {m: (f.to_dict() if isinstance(f, FitResult) else {"error": f})
                for m, f in self.fits.items()}
        online = {e.identifier: {
            "status": e.status, "samples": e.samples, "residual_rms": finite(e.residual_rms),
            "note": e.note,
            "parameters": {k: {"value": finite(v), "std": finite(s)}
                           for k, (v, s) in e.values.items()}} for e in self.online}
        return {"model": list(self.model.names), "t0": finite(self.t0), "bins": self.bins,
                "gaps": self.gaps, "observed": self.observed, "fits": fits, "online": online,
                "units": self.units()}

    def units(self) -> dict[str, Any]:
        """The units of the numbers above: the drift's (the DBC signal's), the
        temperature's, the time's, and each parameter's with the drift's in place of the
        model's ``y`` (as every table prints it)."""
        return {"drift": self.unit, "temp": "degC", "t": "s",
                "parameters": {n: unit_text(q.unit, self.unit) for n, q in self.model.params}}


def samples_of(cols: Mapping[str, Sequence[float]], dt: float,
               source: str) -> tuple[Samples, float]:
    """A gyro's ``samples.csv`` columns as :class:`Samples` with time from its first bin
    (s), each bin's measurement noise weighted by its frame count ``n_drift``; returns the
    first bin's start time ``t0`` (s) too."""
    t = np.asarray(cols["t"], dtype=float)
    t0 = float(t[0])
    rel = np.round((t - t0) / dt) * dt
    counts = np.asarray(cols["n_drift"], dtype=float) if "n_drift" in cols else None
    s = Samples.from_arrays(rel, np.asarray(cols["drift"], dtype=float),
                            np.asarray(cols["temp"], dtype=float), dt=dt, source=source,
                            counts=counts)
    return s, t0


def fit_gyro(gyro: GyroConfig, cols: Mapping[str, Sequence[float]], dt: float, source: str,
             lkf_point: LkfPoint | None = None,
             online: Sequence[OnlineEstimate] = (),
             online_lkf: Callable[[Samples], FitResult] | None = None) -> GyroFinal:
    """Run every final method on one gyro's bins, given as the columns of its
    ``samples.csv`` (errors recorded, never raised).

    Labels (one meaning each, dbc/README.md): ``lkf`` is the *online* LKF at stop
    (``online_lkf``, the daemon's filter after its last re-linearisation: the value the
    last CAN round sends), ``lkf_batch`` the same filter run again over ``samples.csv``
    to its fixed point. Without ``online_lkf`` (an offline refit) ``lkf`` is the batch."""
    model = Model.parse(gyro.model)
    n = len(cols["t"])
    gaps = sum(1 for a, b in zip(cols["n_drift"], cols["n_temp"], strict=True)
               if a == 0 or b == 0)
    out = GyroFinal(gyro.name, model, math.nan, n, gaps, 0, online=list(online),
                    unit=gyro.drift.unit or "y")
    if not n:
        for m in final_methods(gyro):
            out.fits[m] = "no bins were recorded for this gyro"
        return out
    try:
        samples, out.t0 = samples_of(cols, dt, source)
    except GyrostandError as exc:
        for m in final_methods(gyro):
            out.fits[m] = str(exc)
        return out
    out.observed = samples.n_observed
    errors = (GyrostandError, ValueError, KeyError, np.linalg.LinAlgError)
    for method in final_methods(gyro):
        ident = REGISTRY[method]
        label = method
        if ident.reports_online and online_lkf is not None:
            label = f"{method}_batch"
            try:
                out.fits[method] = online_lkf(samples)
            except errors as exc:
                log.warning("gyro %s: the online %s at stop: %s", gyro.name, method, exc)
                out.fits[method] = str(exc)
        try:
            opts = ident.final_options(gyro.options(method), model, samples, lkf_point)
            out.fits[label] = ident.fit(samples, model, opts)
        except errors as exc:
            log.warning("gyro %s: final %s fit failed: %s", gyro.name, label, exc)
            out.fits[label] = str(exc)
    return out


def write_result_json(path: Path, cfg: SessionConfig, source: str, run_dir: Path,
                      finals: Sequence[GyroFinal], stats: Mapping[str, Any]) -> None:
    doc = {"session": cfg.name, "config": str(cfg.path), "source": source,
           "run_dir": str(run_dir), "dt": cfg.sampling.dt,
           "epoch": cfg.sampling.epoch, "state": "finished",
           "gyros": {f.gyro: f.to_dict() for f in finals}, "stats": json_safe(stats),
           "channels": channels_of(cfg)}
    write_json(path, doc)


def channels_of(cfg: SessionConfig) -> dict[str, dict[str, str]]:
    """What each gyro's channels map, as ``result.json`` records it (``run --resume``
    refuses a session that maps another message, signal, id or source address)."""
    out = {}
    for g in cfg.gyros:
        d = {}
        for role, ch in (("drift", g.drift), ("temperature", g.temperature)):
            s = ch.signal
            sa = "" if ch.source_address is None else f" from 0x{ch.source_address:02X}"
            how = " by PGN" if ch.match == "pgn" else ""
            d[role] = f"{s.message.describe()}.{s.name}{how}{sa} in {ch.unit or 'no unit'}"
        out[g.name] = d
    return out


def write_provisional_result(path: Path, cfg: SessionConfig, source: str,
                             run_dir: Path) -> None:
    """``result.json`` while the run is going (``"state": "running"``, no fits yet), so a
    running or crashed run folder is already a run folder for ``diagnose`` / ``report``;
    the final one replaces it (both written atomically)."""
    doc = {"session": cfg.name, "config": str(cfg.path), "source": source,
           "run_dir": str(run_dir), "dt": cfg.sampling.dt,
           "epoch": cfg.sampling.epoch, "state": "running",
           "gyros": {g.name: {"model": list(g.model), "t0": None, "bins": 0, "gaps": 0,
                              "observed": 0, "fits": {}, "online": {}} for g in cfg.gyros},
           "stats": {"stop_reason": None}, "channels": channels_of(cfg)}
    write_json(path, doc, allow_nan=True)


def result_table(final: GyroFinal, truth: Mapping[str, float] | None = None) -> str:
    """One gyro's parameters: a column per method (value ± std), truth first if known
    (:func:`gyrostand.report.text.result_table`)."""
    from ..report.text import result_table as table

    return table(final, truth)


def write_report(path: Path, cfg: SessionConfig, source: str, finals: Sequence[GyroFinal],
                 stats: Mapping[str, Any], truths: Mapping[str, Mapping[str, float]]) -> None:
    """``report.txt``: the final table per gyro and the counts of the run
    (:func:`gyrostand.report.text.run_report`)."""
    from ..report import render
    from ..report.views import RunFinals

    write_atomic(path, render(RunFinals(cfg.name, source, finals, stats, truths), "text"))
