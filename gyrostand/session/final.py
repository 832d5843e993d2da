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
                          "online": {"lkf": {"status": ..., "parameters": {...}}}}},
     "stats": {decoder, binner, recorder, responses, commands, timing}}
"""

from __future__ import annotations

import json
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
from ..core.results import FitResult, unit_text
from ..errors import GyrostandError
from .online import LkfPoint, OnlineEstimate
from .outputs import write_atomic

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
            "status": e.status, "samples": e.samples, "residual_rms": _finite(e.residual_rms),
            "note": e.note,
            "parameters": {k: {"value": _finite(v), "std": _finite(s)}
                           for k, (v, s) in e.values.items()}} for e in self.online}
        return {"model": list(self.model.names), "t0": _finite(self.t0), "bins": self.bins,
                "gaps": self.gaps, "observed": self.observed, "fits": fits, "online": online}


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
                    unit=gyro.drift.signal.unit or "y")
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
           "gyros": {f.gyro: f.to_dict() for f in finals}, "stats": _clean(stats)}
    write_atomic(path, json.dumps(doc, indent=2, allow_nan=False) + "\n")


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
           "stats": {"stop_reason": None}}
    write_atomic(path, json.dumps(doc, indent=2) + "\n")


#: the batch refit's column is left out of the table when it is the online value within
#: this many stds for every parameter (said in a line below the table)
SAME_SIGMA = 0.05


def result_table(final: GyroFinal, truth: Mapping[str, float] | None = None) -> str:
    """One gyro's parameters: a column per method (value ± std), truth first if known.

    ``lkf`` is the online LKF at stop (what the last CAN round sent), ``lkf_batch`` the
    batch refit: shown only where it differs from ``lkf`` by more than ``SAME_SIGMA``."""
    methods = list(final.fits)
    same = _same_fit(final.fits.get("lkf"), final.fits.get("lkf_batch"))
    if same:
        methods.remove("lkf_batch")
    head = f"{'parameter':<14}" + (f" {'truth':>12}" if truth else "")
    head += "".join(f" {m:>24}" for m in methods) + "  unit"
    lines = [head]
    for name in final.model.param_names:
        row = f"{name:<14}"
        if truth:
            row += f" {truth[name]:>12.5g}" if name in truth else f" {'':>12}"
        unit = ""
        for m in methods:
            f = final.fits[m]
            if isinstance(f, FitResult) and name in f.parameters:
                e = f.parameters[name]
                unit = unit_text(e.unit, final.unit)
                cell = f"{e.value:.5g} (held)" if e.fixed else f"{e.value:.5g} ± {e.std:.2g}"
            else:
                cell = "—"
            row += f" {cell:>24}"
        lines.append(f"{row}  {unit}")
    rms = f"{'residual RMS':<14}" + (f" {'':>12}" if truth else "")
    for m in methods:
        f = final.fits[m]
        rms += f" {f.residual_rms:>24.4g}" if isinstance(f, FitResult) else f" {'—':>24}"
    lines.append(rms)
    lk = final.fits.get("lkf")
    if isinstance(lk, FitResult) and lk.info.get("online"):
        lines.append(f"lkf = the online LKF at stop ({lk.info.get('variant', 'relin')}; "
                     f"status {lk.info.get('status')}), as sent on the bus"
                     + ("; lkf_batch (the same filter rerun over samples.csv) agrees "
                        f"within {SAME_SIGMA:g} std" if same else ""))
    for m in methods:
        f = final.fits[m]
        if isinstance(f, str):
            lines.append(f"{m}: failed: {f}")
        else:
            lines += [f"{m}: warning: {w}" for w in f.warnings]
    return "\n".join(lines)


def _same_fit(a: FitResult | str | None, b: FitResult | str | None) -> bool:
    """Every parameter of ``b`` within ``SAME_SIGMA`` std of ``a``'s (held ones equal to
    3 significant digits)."""
    if not isinstance(a, FitResult) or not isinstance(b, FitResult):
        return False
    for n, e in b.parameters.items():
        o = a.parameters.get(n)
        if o is None:
            return False
        tol = SAME_SIGMA * max(e.std, o.std) if not (e.fixed or o.fixed) else \
            1e-2 * max(abs(e.value), abs(o.value))
        if abs(e.value - o.value) > tol:
            return False
    return True


def write_report(path: Path, cfg: SessionConfig, source: str, finals: Sequence[GyroFinal],
                 stats: Mapping[str, Any], truths: Mapping[str, Mapping[str, float]]) -> None:
    """``report.txt``: the final table per gyro and the counts of the run."""
    dec = stats.get("decoder", {})
    lines = [f"gyrostand run report: session {cfg.name} ({source})", "",
             f"frames received {dec.get('received', 0)}, decoded {dec.get('decoded', 0)}, "
             f"ignored {dec.get('ignored', 0)}, rejected {dec.get('rejected_total', 0)}, "
             f"bus errors {dec.get('bus_errors', 0)}, counter jumps "
             f"{dec.get('counter_jumps', 0)}"]
    rej = {k: v for k, v in dec.get("rejected", {}).items() if v}
    if rej:
        lines.append("rejected by reason: " + ", ".join(f"{k} {v}" for k, v in rej.items()))
    b = stats.get("binner", {})
    lines.append(f"bins {b.get('bins', 0)} (gaps {b.get('gaps', 0)}), late samples "
                 f"{b.get('late', 0)}, refused jumps {b.get('jumps', 0)}")
    segs = stats.get("segments") or []
    if len(segs) > 1:  # a resumed run: the counts above are the last segment's
        tot = stats.get("run_totals", {})
        td, tb = tot.get("decoder", {}), tot.get("binner", {})
        lines.append(f"(the counts above are the last segment's) whole run, {len(segs)} "
                     f"raw segments: frames received {td.get('received', 0)}, decoded "
                     f"{td.get('decoded', 0)}, rejected {td.get('rejected_total', 0)}; bins "
                     f"{tb.get('bins', 0)} (gaps {tb.get('gaps', 0)})")
        for seg in segs:
            sd = seg.get("decoder", {})
            lines.append(f"  {seg.get('raw')}: {seg.get('state')}"
                         f"{' (' + seg['ended_by'] + ')' if seg.get('ended_by') else ''}, "
                         f"decoded {sd.get('decoded', 0)}, rows {seg.get('rows_written', 0)}")
    for f in finals:
        lines += ["", f"gyro {f.gyro}: model {','.join(f.model.names)}; {f.bins} bins, "
                      f"{f.gaps} gaps, {f.observed} observed", ""]
        lines.append(result_table(f, truths.get(f.gyro)))
    lines += ["", "(y = the drift's unit, e.g. deg/h; ± one standard deviation)"]
    write_atomic(path, "\n".join(lines) + "\n")


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _clean(x: Any) -> Any:
    if isinstance(x, float):
        return _finite(x)
    if isinstance(x, Mapping):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    return x
