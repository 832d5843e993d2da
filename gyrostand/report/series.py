"""What the report plots, prepared from a subject and its diagnosis (no plotting here).

* :func:`envelope` thins a long noisy series for drawing (min/max per bucket, so spikes
  survive), :func:`moving_mean` shows the systematic part of the residuals,
  :func:`binned_means` their dependence on dT/dt or T;
* :func:`convergence` returns estimates over time with their stds: the run's online
  estimates (``<gyro>/estimates.csv``) when the run has them, otherwise one pass of the
  paper's LKF linearised at the ML estimate with the noise levels held there, otherwise
  (terms the LKF cannot represent) ML fits on growing windows of the data;
* :func:`ledger_points` turns the ledger into one point per model change.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..core.data import Samples
from ..core.diagnose.results import DiagnoseResult
from ..core.diagnose.verdict import fit_error
from ..core.lkf.filter import estimated_names, held_names, lkf, lkf_layout
from ..core.ml.fit import ml
from ..errors import GyrostandError
from ..runfolder import estimates_path, read_estimates_csv, read_result_or_none
from ..workbench import Subject, read_ledger

log = logging.getLogger(__name__)

#: growing windows of the ML convergence fallback (fractions of the run)
ML_WINDOWS = 8
#: shortest window of the ML convergence fallback, samples
ML_MIN_WINDOW = 300


def envelope(t: np.ndarray, y: np.ndarray, buckets: int = 1500) -> tuple[np.ndarray, np.ndarray]:
    """``(t, y)`` thinned to at most ``2·buckets`` points: per bucket its min and its max.

    Drawn as a line this looks like the full series at screen resolution (peaks kept);
    buckets without a finite value become NaN (a gap in the line).
    """
    n = y.size
    if n <= 2 * buckets:
        return t, y
    m = int(math.ceil(n / buckets))
    pad = m * buckets - n
    yy = np.concatenate([y, np.full(pad, np.nan)]).reshape(buckets, m)
    tt = np.concatenate([t, np.full(pad, t[-1])]).reshape(buckets, m)
    finite = np.isfinite(yy)
    lo = np.where(finite, yy, np.inf).min(axis=1)
    hi = np.where(finite, yy, -np.inf).max(axis=1)
    empty = ~finite.any(axis=1)
    lo[empty] = np.nan
    hi[empty] = np.nan
    t_lo, t_hi = tt[:, 0], tt[:, -1]
    return (np.column_stack([t_lo, t_hi]).ravel(), np.column_stack([lo, hi]).ravel())


def moving_mean(y: np.ndarray, window: int) -> np.ndarray:
    """Centred moving mean over ``window`` samples, NaN skipped (NaN where none is finite)."""
    ok = np.isfinite(y)
    c = np.concatenate([[0.0], np.cumsum(np.where(ok, y, 0.0))])
    k = np.concatenate([[0], np.cumsum(ok)])
    n = y.size
    half = window // 2
    lo = np.clip(np.arange(n) - half, 0, n)
    hi = np.clip(np.arange(n) + half + 1, 0, n)
    cnt = k[hi] - k[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(cnt > 0, (c[hi] - c[lo]) / np.maximum(cnt, 1), np.nan)


@dataclass(frozen=True)
class Binned:
    """Means of ``y`` in equal-width bins of ``x``: centres, means, standard errors, counts."""

    x: np.ndarray
    mean: np.ndarray
    se: np.ndarray
    n: np.ndarray


def binned_means(x: np.ndarray, y: np.ndarray, bins: int = 15,
                 min_count: int = 30) -> Binned:
    """Bin ``x`` over its 1–99 % range; bins with fewer than ``min_count`` values dropped."""
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size == 0:
        e = np.empty(0)
        return Binned(e, e, e, e.astype(int))
    lo, hi = np.quantile(x, [0.01, 0.99])
    if not hi > lo:
        lo, hi = float(x.min()) - 0.5, float(x.max()) + 0.5
    edges = np.linspace(lo, hi, bins + 1)
    idx = np.clip(np.digitize(x, edges) - 1, 0, bins - 1)
    n = np.bincount(idx, minlength=bins)
    s = np.bincount(idx, weights=y, minlength=bins)
    s2 = np.bincount(idx, weights=y * y, minlength=bins)
    keep = n >= min_count
    n, s, s2 = n[keep], s[keep], s2[keep]
    mean = s / n
    var = np.maximum(s2 / n - mean**2, 0.0)
    centres = 0.5 * (edges[:-1] + edges[1:])[keep]
    return Binned(centres, mean, np.sqrt(var / n), n)


@dataclass(frozen=True)
class Convergence:
    """Estimates over time from one identifier.

    Attributes:
        label: what produced them (shown in the legend).
        t: times, s from the first sample, shape (M,).
        values / stds: parameter name -> array (M,) (NaN while unknown).
        points: True for a few discrete fits (drawn as points with error bars).
    """

    label: str
    t: np.ndarray
    values: Mapping[str, np.ndarray]
    stds: Mapping[str, np.ndarray]
    points: bool = False
    held: tuple[str, ...] = field(default_factory=tuple)


def read_estimates(path: Path, t0: float | None = None) -> list[Convergence]:
    """The run's online estimates: ``t, <id>:<param>, <id>:<param>:std, ..., <id>:status``
    (read by :func:`gyrostand.runfolder.read_estimates_csv`: a torn last line is left out).

    Parameters whose std is never positive (held values) are left out (listed in ``held``).
    """
    cols = {k: np.asarray(v, dtype=object if k.endswith(":status") else float)
            for k, v in read_estimates_csv(path).items()}
    if not len(cols["t"]):
        return []
    t = cols["t"] - (t0 if t0 is not None else cols["t"][0])
    header = list(cols)
    idents = list(dict.fromkeys(h.split(":")[0] for h in header[1:] if h.count(":") == 1
                                and not h.endswith(":status")))
    out = []
    for ident in idents:
        values, stds, held = {}, {}, []
        for h in header[1:]:
            parts = h.split(":")
            if len(parts) != 2 or parts[0] != ident or parts[1] == "status":
                continue
            v, s = cols[h], cols.get(h + ":std")
            if s is None or not np.any(np.nan_to_num(s) > 0):
                held.append(parts[1])
                continue
            values[parts[1]], stds[parts[1]] = v, s
        if values:
            out.append(Convergence(f"{ident.upper()} (online, during the run)", t, values,
                                   stds, held=tuple(held)))
    return out


def _lkf_pass(samples: Samples, report: DiagnoseResult) -> Convergence:
    model, p = report.model, report.fit.values
    layout = lkf_layout(model)  # ModelError when the LKF cannot represent the model
    held = {k: abs(p[k]) for k in held_names(model)}
    if held.get("markov.sigma", 1.0) <= 0:
        raise GyrostandError("the LKF needs markov.sigma > 0")
    r = lkf(samples, model, variant="paper", beta0=max(p["markov.beta"], 1e-9),
            gamma0=p.get("temp.gamma", 0.0),
            b0=p.get("bias.b", 0.0), held=held)
    names = [n for n in layout if n in estimated_names(model)]
    return Convergence("LKF (one pass linearised at the ML estimate)", samples.t - samples.t[0],
                       {n: np.asarray(r.history[n]) for n in names},
                       {n: np.asarray(r.history[n + ":std"]) for n in names},
                       held=tuple(held))


def _ml_windows(samples: Samples, report: DiagnoseResult) -> Convergence:
    n = len(samples)
    ends = sorted({int(round(n * k / ML_WINDOWS)) for k in range(1, ML_WINDOWS + 1)})
    ends = [e for e in ends if e >= min(ML_MIN_WINDOW, n)]
    names = [k for k, e in report.fit.parameters.items() if not e.fixed]
    vals = {k: np.full(len(ends), np.nan) for k in names}
    stds = {k: np.full(len(ends), np.nan) for k in names}
    for i, e in enumerate(ends):
        if e == n:
            r = report.fit
        else:
            sub = Samples.from_arrays(samples.t[:e], samples.drift[:e], samples.temp[:e],
                                      dt=samples.dt, source=samples.source)
            try:
                r = ml(sub, report.model, start=report.fit.values, n_local=1)
            except GyrostandError as exc:
                log.info("convergence: ML on the first %d samples failed: %s", e, exc)
                continue
        for k in names:
            vals[k][i], stds[k][i] = r.value(k), r.std(k)
    t = samples.t[np.array(ends) - 1] - samples.t[0]
    return Convergence("ML on the data up to each time", t, vals, stds, points=True)


def convergence(subject: Subject, report: DiagnoseResult) -> tuple[list[Convergence], str]:
    """Estimates over time, and a sentence saying where they come from."""
    if subject.run_dir is not None:
        path = estimates_path(subject.run_dir, subject.gyro)
        if path.exists():
            t0 = None
            try:
                t0 = float(read_result_or_none(subject.run_dir)["gyros"][subject.gyro]["t0"])
            except (ValueError, KeyError, TypeError):
                pass
            try:
                conv = read_estimates(path, t0)
            except GyrostandError as exc:  # damaged: the report shows the LKF pass instead
                log.warning("convergence: the run's online estimates are unreadable (%s)",
                            exc)
                conv = []
            if conv:
                model = _run_model(subject)
                return conv, (f"the run's online estimates ({path.name}) of its configured "
                              f"model {model}")
    try:
        return [_lkf_pass(subject.samples, report)], (
            "one pass of the paper's linearised Kalman filter (Algorithm 2), linearised at "
            "the ML estimate, noise levels held at their ML values")
    except GyrostandError as exc:
        log.info("convergence: no LKF pass (%s); ML on growing windows", exc)
    return [_ml_windows(subject.samples, report)], (
        f"ML fits on the first 1/{ML_WINDOWS}, 2/{ML_WINDOWS}, ... of the data (the LKF "
        f"cannot represent the model {','.join(report.model.names)})")


def _run_model(subject: Subject) -> str:
    try:
        info = read_result_or_none(subject.run_dir)  # type: ignore[arg-type]
        return ",".join(info["gyros"][subject.gyro]["model"])
    except (KeyError, TypeError):
        return "(unknown)"


@dataclass(frozen=True)
class LedgerPoint:
    """One model of the ledger's history: its label (the change), RMS and log-likelihood."""

    label: str
    model: tuple[str, ...]
    rms: float
    loglik: float
    steps: tuple[int, ...]
    what_if: bool = False
    model_error: float = math.nan
    floor: float = math.nan


def _change(before: Sequence[str], after: Sequence[str]) -> str:
    added = [t for t in after if t not in before]
    removed = [t for t in before if t not in after]
    return " ".join([f"+{t}" for t in added] + [f"−{t}" for t in removed]) or "refit"


def ledger_steps(subject: Subject) -> list[dict[str, Any]]:
    return [s for s in read_ledger(subject.ledger_path) if s.get("gyro") == subject.gyro]


def _num(d: Mapping[str, Any], key: str) -> float:
    v = d.get(key)
    return float(v) if isinstance(v, int | float) else math.nan


def ledger_points(steps: list[dict[str, Any]], report: DiagnoseResult,
                  samples: Samples | None = None) -> list[LedgerPoint]:
    """One point per model change (the latest numbers of each model), then the current
    model if it differs, then — when a candidate is significant — what adding it gives
    (its model error too when ``samples`` are given)."""
    pts: list[LedgerPoint] = []

    def push(model: Sequence[str], rms: float, loglik: float, step: int | None,
             err: float = math.nan, floor: float = math.nan) -> None:
        model = tuple(model)
        nums = (step,) if step is not None else ()
        if pts and pts[-1].model == model:
            last = pts[-1]
            pts[-1] = LedgerPoint(last.label, model, rms, loglik, last.steps + nums,
                                  model_error=err if math.isfinite(err) else last.model_error,
                                  floor=floor if math.isfinite(floor) else last.floor)
            return
        label = ",".join(model) if not pts else _change(pts[-1].model, model)
        pts.append(LedgerPoint(label, model, rms, loglik, nums, model_error=err, floor=floor))

    for s in steps:
        try:
            if s.get("action") == "fit":
                b, a = s["before"], s["after"]
                if not pts:
                    push(b["model"], float(b["rms"]), float(b["loglik"]), None,
                         _num(b, "model_error"), _num(b, "model_error_floor"))
                push(a["model"], float(a["rms"]), float(a["loglik"]), s.get("step"),
                     _num(a, "model_error"), _num(a, "model_error_floor"))
            elif s.get("action") == "diagnose":
                push(s["model"], float(s["rms"]), float(s["loglik"]), s.get("step"),
                     _num(s, "model_error"), _num(s, "model_error_floor"))
        except (KeyError, TypeError, ValueError):
            log.warning("ledger step %s is incomplete; left out of the plot", s.get("step"))
    err = getattr(report, "model_error", None)
    push(report.model.names, report.diagnosis.rms, float(report.fit.loglik or np.nan), None,
         err.rms if err is not None else math.nan, err.floor if err is not None else math.nan)
    if not report.adequate and report.significant and not (
            getattr(report, "jump", False) or getattr(report, "cycling", False)):
        c = report.significant[0]
        e_c = f_c = math.nan
        if samples is not None and c.result is not None:
            ce = fit_error(c.result, samples, err.unit if err is not None else "y",
                           getattr(report, "reference", None))
            e_c, f_c = ce.rms, ce.floor
        pts.append(LedgerPoint(f"if +{c.term}", tuple(report.model.names) + (c.term,),
                               c.rms_after, c.loglik_after, (), what_if=True,
                               model_error=e_c, floor=f_c))
    return pts
