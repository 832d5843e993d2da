"""The model's prediction error, as an engineer measures it (MATLAB's ``compare``).

For a fitted model with deterministic part ``d_k = X_k(η) θ`` (everything the temperature
and time drive: bias, γ·T through the drift dynamics, dT/dt terms, warm-up, ...) and
stochastic part ``s_k`` (Markov, random-walk states and the white noise):

* **open-loop (simulation) error** ``e_k = y_k − d_k``: the model driven by the temperature
  alone, every noise set to zero — what a thermal compensation built from the model leaves;
* **h-step-ahead prediction error** ``e_k = y_k − d_k − Σ_i φ_i^h x̂_{i,k−h|k−h}``: the
  Kalman filter's state h samples back, propagated h steps (h = 1 is the innovation).

Each is summarised by the means of consecutive windows of ``W`` seconds (sensor noise
averages out), per segment of the profile and over the run: the RMS and the largest
absolute window mean, in the drift's unit, and MATLAB's fit percentage

    fit % = 100 · (1 − ‖ȳ_w − ŷ_w‖ / ‖ȳ_w − mean(ȳ_w)‖)

on the window means ȳ_w of the measurement and ŷ_w of the prediction.

Beside each RMS, the **floor**: the same statistic for data that follow the fitted model
exactly (its stochastic part — in a diagnosis, that of the saturated reference, which a
misfit cannot inflate — window-averaged, on the same gaps and bin weights), from
seeded replicates of that part, and the 99 % point of its sampling distribution. The part
of the error the model does not explain is ``√max(e² − floor², 0)``; the error is *at its
floor* when it lies below that 99 % point.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..data import Samples
from ..kalman import first_order_response, kf_filtered_states
from ..model import Model, context

#: window lengths of the means (s)
WINDOWS_S: tuple[float, ...] = (60.0, 600.0)
#: prediction horizons (s)
HORIZONS_S: tuple[float, ...] = (1.0, 60.0, 600.0)
#: the headline: open-loop RMS of the means over this window (s)
HEADLINE_WINDOW_S = 60.0
#: replicates of the model's stochastic part behind each floor
FLOOR_REPLICATES = 60
#: quantile of the floor's sampling distribution below which the error is at its floor
FLOOR_QUANTILE = 0.99
#: a window mean needs at least this fraction of its samples observed
MIN_FILL = 0.5


def deterministic_part(model: Model, p: Mapping[str, float], samples: Samples) -> np.ndarray:
    """``d = X(η) θ``: the model driven by the temperature (and time) alone, shape (N,)."""
    X = model.regressors(p, context(samples, model))
    theta = np.array([p[n] for n in model.names_of_kind("linear")])
    return X @ theta if theta.size else np.zeros(len(samples))


def _window_index(n: int, m: int, segs: Sequence[tuple[int, int]]) -> list[np.ndarray]:
    """Start indices of the whole windows of ``m`` samples inside each range of ``segs``."""
    return [np.arange(a, b - m + 1, m) for a, b in segs]


def _prefix(x: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Prefix sums of the finite values of ``x`` (along its last axis: a series, or one
    series a row) and of their count (``ok`` is every row's)."""
    c = np.zeros((*x.shape[:-1], x.shape[-1] + 1))
    np.cumsum(np.where(ok, x, 0.0), axis=-1, out=c[..., 1:])
    return c, np.concatenate([[0], np.cumsum(ok)])


def _means(x: np.ndarray, ok: np.ndarray, starts: np.ndarray, m: int,
           pre: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Mean of the finite values of each window ``[s, s+m)`` (of each row of ``x``); NaN
    if too few are finite."""
    c, k = pre if pre is not None else _prefix(x, ok)
    cnt = k[starts + m] - k[starts]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(cnt >= MIN_FILL * m,
                        (c[..., starts + m] - c[..., starts]) / np.maximum(cnt, 1), np.nan)


def _predictions(y: np.ndarray, det: np.ndarray, model: Model, p: Mapping[str, float],
                 samples: Samples, steps: Sequence[int]) -> dict[int, np.ndarray]:
    """h-step predictions ``d_k + Σ φ^h x̂_{k−h|k−h}`` for every h in ``steps`` (0: d)."""
    phi, q, p0, r = model.stochastic(p, samples.dt)
    xf = kf_filtered_states(phi, q, p0, r, samples.noise_weights,
                            np.ascontiguousarray(y - det))
    out = {}
    for h in steps:
        if h == 0:
            out[h] = det
            continue
        s = np.zeros(y.size)
        if h < y.size:
            s[h:] = xf[:-h] @ (phi ** h)
        out[h] = det + s
    return out


@dataclass(frozen=True)
class _Layout:
    """Where the windows are: over the run and per segment, for each window length."""

    n: int
    m: dict[float, int]
    ranges: tuple[tuple[int, int], ...]  # (0, N) first, then the segments

    def starts(self, w: float) -> list[np.ndarray]:
        return _window_index(self.n, self.m[w], self.ranges)


#: replicates whose window statistics are taken together (one (block, N) array per
#: horizon: 60 replicates' 240 one-series passes were 0.18 s of a 6-h diagnosis). 10, not
#: 20: the same numbers and CPU, half the memory (a 24-h record's model error 118 -> 63 MB)
REPLICATE_BLOCK = 10


def _stats(E: np.ndarray, ok: np.ndarray, lay: _Layout) -> dict[float, np.ndarray]:
    """RMS of the window means per range (run first), for each window length, of each row
    of ``E`` (rows: replicates, each with the missing samples ``ok``): shape (rows,
    ranges). The prefix sums run along each row and each RMS over a row's own windows,
    so a row's numbers are those of that series alone."""
    pre = _prefix(E, ok)
    out = {}
    for w in lay.m:
        m = lay.m[w]
        vals = np.full((E.shape[0], len(lay.ranges)), np.nan)
        for j, st in enumerate(lay.starts(w)):
            mm = _means(E, ok, st, m, pre)
            # the windows enough samples fill, each row contiguous: its RMS sums pairwise
            # as a single series' does
            mm = np.ascontiguousarray(mm[:, np.isfinite(mm).all(axis=0)])
            if mm.size:
                vals[:, j] = np.sqrt(np.mean(mm * mm, axis=1))
        out[w] = vals
    return out


def _replicates(model: Model, p: Mapping[str, float], samples: Samples, ok: np.ndarray,
                steps: Sequence[int], lay: _Layout, reps: int,
                seed: int) -> dict[int, dict[float, np.ndarray]]:
    """Window-mean RMS of the h-step errors of replicates that follow the model exactly:
    shape (reps, ranges) per horizon and window."""
    phi, q, p0, r = model.stochastic(p, samples.dt)
    w = samples.noise_weights
    rv = r * (w if w.size else np.ones(len(samples)))
    rng = np.random.default_rng(seed)
    N = len(samples)
    out: dict[int, dict[float, list[np.ndarray]]] = {h: {x: [] for x in lay.m} for h in steps}
    zero = np.zeros(N)
    for first in range(0, reps, REPLICATE_BLOCK):
        block = min(REPLICATE_BLOCK, reps - first)
        errs = {h: np.empty((block, N)) for h in steps}
        for b in range(block):
            s = rng.standard_normal(N) * np.sqrt(rv)
            for i in range(phi.size):
                e = rng.standard_normal(N) * np.sqrt(q[i])
                e[0] = rng.standard_normal() * np.sqrt(p0[i])
                # x_0 = e_0, x_k = φ x_{k−1} + e_k (the Gauss–Markov state; scipy.signal's
                # lfilter([1], [1, −φ]) gives the same numbers, at 0.9 s of import)
                s = s + first_order_response(e, float(phi[i]), 0.0, 1.0, float(e[0]))
            s = np.where(ok, s, np.nan)
            preds = _predictions(s, zero, model, p, samples, steps)
            for h in steps:
                errs[h][b] = s - preds[h]
        for h in steps:
            st = _stats(errs[h], ok, lay)
            for x in lay.m:
                out[h][x].append(st[x])
    return {h: {x: np.vstack(v) for x, v in d.items()} for h, d in out.items()}


def _unexplained(rms: float, floor: float, limit: float) -> float:
    """√(rms² − floor²) where the error lies beyond the floor's sampling spread (above
    ``limit``, its :data:`FLOOR_QUANTILE` point), else 0: within it the data show no part
    the model leaves unexplained. (The positive part alone is biased up: for data that
    follow the model it is positive in about half the runs, 0.3-0.6 × the floor on a 4-h
    run's 600-s means, which is noise, not a missing effect.)"""
    if not (np.isfinite(rms) and np.isfinite(floor)):
        return np.nan
    if np.isfinite(limit) and rms <= limit:
        return 0.0
    return float(np.sqrt(max(rms * rms - floor * floor, 0.0)))


def _num(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


@dataclass(frozen=True)
class ModelError:
    """Open-loop and h-step prediction errors of a fit, summarised by window means.

    ``entries[(h, window)]`` (h in seconds, 0 = open loop) holds one dict per range (the
    run first, then each segment) with ``rms``, ``max``, ``fit_percent``, ``n_windows``,
    ``floor`` (RMS for data following the model), ``floor_limit`` (its 99 % point) and
    ``unexplained`` = √max(rms² − floor², 0) where rms is above its floor limit, 0 at floor
    (:func:`_unexplained`). ``open_loop`` (N,) is y − d, ``simulated`` the open-loop
    model d.
    """

    unit: str
    windows_s: tuple[float, ...]
    horizons_s: tuple[float, ...]
    ranges: tuple[dict[str, Any], ...]
    entries: Mapping[tuple[float, float], tuple[dict[str, Any], ...]]
    open_loop: np.ndarray
    simulated: np.ndarray

    def headline(self, window: float = HEADLINE_WINDOW_S) -> dict[str, Any]:
        """Open-loop window-mean RMS over the run, its floor, limit, unexplained part."""
        run = self.entries[(0.0, window)][0]
        return {"window_s": window, "rms": run["rms"], "floor": run["floor"],
                "floor_limit": run["floor_limit"], "unexplained": run["unexplained"],
                "fit_percent": run["fit_percent"], "at_floor": self.at_floor(window),
                "unit": self.unit}

    @property
    def rms(self) -> float:
        v = self.entries[(0.0, HEADLINE_WINDOW_S)][0]["rms"]
        return float("nan") if v is None else float(v)

    @property
    def floor(self) -> float:
        v = self.entries[(0.0, HEADLINE_WINDOW_S)][0]["floor"]
        return float("nan") if v is None else float(v)

    def misfit_shown(self) -> ModelError:
        """This error where another test has shown a misfit (a significant candidate):
        each run row's unexplained part is √max(rms² − floor², 0) without the floor's
        limit. The limit tests whether the data show a part the model leaves unexplained at
        all; once a candidate has shown one, the part's size is the estimate (a hidden
        hysteresis with the candidate at p < 1e-6: the open-loop error 0.0532 deg/h, just
        inside its floor's 99 % point 0.0533, floor 0.0458: unexplained 0.027 against the
        reference's own deterministic misfit 0.024, where the limit said 0). The segments'
        rows and :meth:`at_floor` (the verdict's test) stay as they are."""
        entries = {}
        for key, rows in self.entries.items():
            run = dict(rows[0])
            rms, floor = run["rms"], run["floor"]
            if rms is not None and floor is not None:
                run["unexplained"] = _num(_unexplained(rms, floor, np.nan))
            entries[key] = (run, *rows[1:])
        return replace(self, entries=entries)

    def at_floor(self, window: float = HEADLINE_WINDOW_S) -> bool:
        """True when the run's open-loop error lies within the floor's sampling spread."""
        run = self.entries[(0.0, window)][0]
        if run["rms"] is None or run["floor_limit"] is None:
            return True
        return bool(run["rms"] <= run["floor_limit"])

    def to_dict(self) -> dict[str, Any]:
        def block(h: float) -> dict[str, Any]:
            d = {}
            for w in self.windows_s:
                rows = self.entries[(h, w)]
                d[f"{w:g}"] = {"run": dict(rows[0]),
                               "segments": [{**self.ranges[i], **rows[i]}
                                            for i in range(1, len(rows))]}
            return d

        return {
            "unit": self.unit, "windows_s": list(self.windows_s),
            "horizons_s": list(self.horizons_s),
            "headline": self.headline(),
            "open_loop": block(0.0),
            "k_step": {f"{h:g}": block(h) for h in self.horizons_s},
        }


def model_error(model: Model, p: Mapping[str, float], samples: Samples,
                segments: Sequence[Mapping[str, Any]] = (), *, unit: str = "y",
                windows_s: Sequence[float] = WINDOWS_S,
                horizons_s: Sequence[float] = HORIZONS_S,
                replicates: int = FLOOR_REPLICATES, seed: int = 0,
                noise: tuple[Model, Mapping[str, float]] | None = None) -> ModelError:
    """Open-loop and h-step prediction errors of ``model`` at ``p`` on ``samples``.

    ``noise``: the model and parameters whose random part the floors are drawn from and
    the h-step predictions of those draws filtered with (default: ``model`` at ``p``);
    the diagnosis passes its saturated reference (:mod:`.reference`), whose random part
    a misfit of ``model`` cannot inflate.

    ``segments``: dicts with ``kind``, ``start``, ``stop`` (sample indices) and optional
    ``t_start``/``t_stop`` (the profile's heating / cooling / soak segments). Spikes and
    gaps are whatever ``samples`` holds (pass the samples the fit used).
    """
    y = np.asarray(samples.drift, dtype=float)
    ok = np.isfinite(y)
    N = y.size
    dt = samples.dt
    windows = tuple(float(w) for w in windows_s)
    horizons = tuple(float(h) for h in horizons_s)
    steps = [0] + [max(1, int(round(h / dt))) for h in horizons]
    ranges_idx = [(0, N)] + [(int(s["start"]), int(s["stop"])) for s in segments]
    lay = _Layout(N, {w: max(1, int(round(w / dt))) for w in windows}, tuple(ranges_idx))
    det = deterministic_part(model, p, samples)
    preds = _predictions(np.where(ok, y, np.nan), det, model, p, samples, steps)
    nm, npar = noise if noise is not None else (model, p)
    reps = _replicates(nm, npar, samples, ok, steps, lay, replicates, seed)
    entries: dict[tuple[float, float], tuple[dict[str, Any], ...]] = {}
    for h_s, h in zip((0.0, *horizons), steps, strict=True):
        err = np.where(ok, y - preds[h], np.nan)
        for w in windows:
            m = lay.m[w]
            rows = []
            for j, st in enumerate(lay.starts(w)):
                em = _means(err, ok, st, m) if st.size else np.zeros(0)
                ym = _means(y, ok, st, m) if st.size else np.zeros(0)
                good = np.isfinite(em)
                em, ym = em[good], ym[good]
                rep = reps[h][w][:, j]
                rep = rep[np.isfinite(rep)]
                floor = float(np.sqrt(np.mean(rep * rep))) if rep.size else np.nan
                limit = float(np.quantile(rep, FLOOR_QUANTILE)) if rep.size else np.nan
                if em.size:
                    rms = float(np.sqrt(np.mean(em * em)))
                    spread = float(np.linalg.norm(ym - ym.mean()))
                    fit = 100.0 * (1.0 - float(np.linalg.norm(em)) / spread) if spread else np.nan
                    mx = float(np.max(np.abs(em)))
                else:
                    rms = fit = mx = np.nan
                unexpl = _unexplained(rms, floor, limit)
                rows.append({"rms": _num(rms), "max": _num(mx), "fit_percent": _num(fit),
                             "n_windows": int(em.size), "floor": _num(floor),
                             "floor_limit": _num(limit), "unexplained": _num(unexpl)})
            entries[(h_s, w)] = tuple(rows)
    t = samples.t
    ranges = [{"kind": "run", "t_start": float(t[0]), "t_stop": float(t[-1])}]
    for s in segments:
        ranges.append({"kind": str(s["kind"]),
                       "t_start": float(s.get("t_start", t[int(s["start"])])),
                       "t_stop": float(s.get("t_stop", t[int(s["stop"]) - 1]))})
    ol = np.where(ok, y - det, np.nan)
    ol.setflags(write=False)
    det = np.array(det)
    det.setflags(write=False)
    return ModelError(unit=unit, windows_s=windows, horizons_s=horizons,
                      ranges=tuple(ranges), entries=entries, open_loop=ol, simulated=det)
