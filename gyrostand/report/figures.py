"""The report's figures: one function per plot, each returning a matplotlib ``Figure``.

Figures are built without pyplot (no global state, no GUI backend): ``Figure`` draws
through Agg when saved as PNG. Long series are thinned with
:func:`~gyrostand.report.series.envelope` before drawing; scatter clouds are subsampled.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..core.data import Samples
from ..core.diagnose.diagnostics import allan_deviation
from ..core.diagnose.results import DiagnoseResult
from ..core.summary import DRIFT_UNIT, unit_text
from .series import Convergence, LedgerPoint, binned_means, envelope, moving_mean

WIDTH = 10.0  # in; at DPI 100 -> 1000 px
DATA = "#444444"
MODEL = "#d95f02"
PRED = "#1f78b4"
TEMP = "#b2182b"
BAND = "#9ecae1"
SEGMENT_COLOURS = {"heating": "#fde0dd", "cooling": "#deebf7"}
IDENT_COLOURS = ("#1f78b4", "#33a02c", "#6a3d9a", "#ff7f00")
SCATTER_MAX = 4000
#: line widths (pt) of the first figure: the measured trace wider than the model over it
MEASURED_LW = 1.2
MODEL_LW = 0.9


def pretty_unit(unit: str, drift: str = DRIFT_UNIT) -> str:
    """A parameter's unit as printed, in the drift's unit: ``y/(s*degC^2)`` ->
    ``(deg/h)/(s·°C²)``."""
    return unit_text(unit, drift)


def time_axis(t: np.ndarray) -> tuple[np.ndarray, str]:
    """Times in s -> (times in a readable unit, axis label)."""
    span = float(t[-1] - t[0]) if t.size else 0.0
    if span > 3 * 3600:
        return t / 3600.0, "time (h)"
    if span > 180:
        return t / 60.0, "time (min)"
    return t, "time (s)"


def temp_twin(ax: Axes, tt: np.ndarray, temp: np.ndarray) -> Axes:
    tw = ax.twinx()
    tw.plot(*envelope(tt, temp), color=TEMP, lw=1.0, alpha=0.7)
    tw.set_ylabel("temperature (°C)", color=TEMP)
    tw.tick_params(axis="y", colors=TEMP)
    return tw


def _shade_segments(ax: Axes, report: DiagnoseResult, scale: float) -> None:
    for s in report.diagnosis.segments:
        c = SEGMENT_COLOURS.get(s["kind"])
        if c:
            ax.axvspan(s["t_start"] * scale, s["t_stop"] * scale, color=c, lw=0, zorder=0)


def measured_vs_model(samples: Samples, report: DiagnoseResult, deterministic: np.ndarray
                      ) -> Figure:
    """(a) Measured drift and the open-loop model (driven by the temperature alone), the
    one-step prediction faintly; beneath, the open-loop error's 60-s moving mean with the
    ±floor band the model's own noise predicts.

    The measured trace is drawn first, opaque and wider (:data:`MEASURED_LW`); the model
    over it, thinner (:data:`MODEL_LW`): where the model fits, the measured band still
    shows on both sides of the model's line (tests/report/test_figures.py counts the
    measured trace's pixels left visible)."""
    t = samples.t - samples.t[0]
    tt, xlabel = time_axis(t)
    unit = report.unit
    fig = Figure(figsize=(WIDTH, 6.0), layout="constrained")
    ax, ax_e = fig.subplots(2, 1, sharex=True, height_ratios=[3, 2])
    ax.plot(*envelope(tt, samples.drift), color=DATA, lw=MEASURED_LW, alpha=1.0, zorder=2,
            label="measured", gid="measured")
    ax.plot(*envelope(tt, report.diagnosis.fitted), color=PRED, lw=0.5, alpha=0.35,
            zorder=2.5, label="one-step prediction ŷ(k|k−1)", gid="prediction")
    ax.plot(tt, deterministic, color=MODEL, lw=MODEL_LW, zorder=3, gid="model",
            label="model driven by the temperature alone (open loop, no noise)")
    ax.set_ylabel(f"drift ({pretty_unit(unit)})")
    ax.set_xlim(tt[0], tt[-1])
    ax.grid(alpha=0.3)
    tw = temp_twin(ax, tt, samples.temp)
    err = samples.drift - deterministic
    w = max(1, int(round(60.0 / samples.dt)))
    ax_e.plot(*envelope(tt, moving_mean(err, w)), color=MODEL, lw=1.2,
              label="open-loop error, 60-s moving mean")
    me = report.model_error
    title = f"Measured drift and the model {','.join(report.model.names)}"
    if me is not None and np.isfinite(me.floor):
        ax_e.axhspan(-me.floor, me.floor, color=PRED, alpha=0.15, lw=0,
                     label="± floor (the model's own noise, 60-s means)")
        h = me.headline()
        title += (f": model error {h['rms']:.3g} {pretty_unit(unit)} "
                  f"(floor {h['floor']:.3g}, fit {h['fit_percent'] or 0:.1f} %)")
    ax_e.axhline(0.0, color="black", lw=0.6)
    ax_e.set_ylabel(f"measured − model ({pretty_unit(unit)})")
    ax_e.set_xlabel(xlabel)
    ax_e.grid(alpha=0.3)
    ax_e.legend(loc="upper right", fontsize=8, frameon=False)
    h1, l1 = ax.get_legend_handles_labels()
    fig.legend(handles=h1 + tw.get_lines()[:1], labels=l1 + ["temperature (right axis)"],
               loc="outside lower center", ncols=2, fontsize=8, frameon=False)
    ax.set_title(title)
    return fig


def residuals_over_time(samples: Samples, report: DiagnoseResult) -> Figure:
    """(b) Innovations (±2√f band, moving mean) and smoothed residuals, temperature overlaid."""
    d = report.diagnosis
    t = samples.t - samples.t[0]
    tt, xlabel = time_axis(t)
    scale = tt[-1] / t[-1] if t[-1] else 1.0
    n = t.size
    window = int(max(60, n // 100))
    sd = np.sqrt(np.asarray(report.fit.residual_var, dtype=float))
    fig = Figure(figsize=(WIDTH, 6.0), layout="constrained")
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    for ax in (ax1, ax2):
        _shade_segments(ax, report, scale)
    tb, sb = envelope(tt, 2 * sd)
    ax1.fill_between(tb, -sb, sb, color=BAND, alpha=0.5, lw=0, label="±2σ (predicted)")
    _residual_trace(ax1, tt, d.innovations, window, samples.dt,
                    "innovation e(k) = y(k) − ŷ(k|k−1)", f"innovation ({report.unit})")
    ax1.set_title(f"Residuals over time (RMS {d.rms:.3g}; shading: heating red, cooling blue)")
    ax1.legend(loc="upper left", fontsize=8, framealpha=0.85)
    sig_v = report.fit.parameters.get("white.sigma")
    s_sm = (sig_v.value if sig_v is not None and sig_v.value > 0
            else float(np.nanstd(d.smoothed)))
    ax2.axhspan(-2 * s_sm, 2 * s_sm, color=BAND, alpha=0.5, lw=0,
                label=f"±2σ_v (σ_v = {s_sm:.3g})")
    _residual_trace(ax2, tt, d.smoothed, window, samples.dt,
                    "smoothed residual y(k) − ŷ(k|N)", f"smoothed residual ({report.unit})")
    ax2.set_xlabel(xlabel)
    ax2.set_xlim(tt[0], tt[-1])
    ax2.legend(loc="upper left", fontsize=8, framealpha=0.85)
    for ax in (ax1, ax2):
        temp_twin(ax, tt, samples.temp)
    return fig


def _residual_trace(ax: Axes, tt: np.ndarray, series: np.ndarray, window: int, dt: float,
                    label: str, ylabel: str) -> None:
    """One residual series on ``ax``: its envelope, its moving mean over ``window`` samples
    and the zero line."""
    ax.plot(*envelope(tt, series), color=DATA, lw=0.5, alpha=0.7, label=label)
    ax.plot(tt, moving_mean(series, window), color=MODEL, lw=1.8,
            label=f"moving mean over {window * dt:g} s")
    ax.axhline(0, color="k", lw=0.6)
    ax.set_ylabel(ylabel)


def residual_vs_inputs(samples: Samples, report: DiagnoseResult, rate: np.ndarray,
                       deterministic: np.ndarray) -> Figure:
    """(c) Residuals against dT/dt and T, with binned means.

    Top row: standardized innovations (white N(0,1) if the model is right; error bars ±2
    standard errors are valid then). Bottom row: the drift the model's temperature-driven
    part leaves unexplained, y − (deterministic part): a missing effect shows here plainly,
    though the random drift makes neighbouring points correlated.
    """
    d = report.diagnosis
    rng = np.random.default_rng(0)
    n = samples.t.size
    pick = np.sort(rng.choice(n, SCATTER_MAX, replace=False)) if n > SCATTER_MAX else slice(None)
    xs = {"dT/dt (°C/min)": rate * 60.0, "temperature T (°C)": np.asarray(samples.temp)}
    ys = {"standardized innovation": d.standardized,
          f"y − temperature-driven part ({report.unit})": samples.drift - deterministic}
    fig = Figure(figsize=(WIDTH, 6.6), layout="constrained")
    axes = fig.subplots(2, 2, sharey="row")
    for i, (ylab, y) in enumerate(ys.items()):
        for j, (xlab, x) in enumerate(xs.items()):
            ax = axes[i, j]
            ax.scatter(x[pick], y[pick], s=3, color=DATA, alpha=0.25, lw=0, rasterized=True)
            b = binned_means(x, y)
            if i == 0:
                ax.errorbar(b.x, b.mean, yerr=2 * b.se, color=MODEL, lw=1.6, marker="o",
                            ms=4, capsize=2, label="binned mean ±2 SE")
                lo, hi = np.nanquantile(y, [0.005, 0.995]) if np.isfinite(y).any() else (-4, 4)
                ax.set_ylim(min(lo, -3.5), max(hi, 3.5))
            else:
                ax.plot(b.x, b.mean, color=MODEL, lw=1.6, marker="o", ms=4, label="binned mean")
            ax.axhline(0, color="k", lw=0.6)
            ax.grid(alpha=0.3)
            if i == 1:
                ax.set_xlabel(xlab)
            if j == 0:
                ax.set_ylabel(ylab)
            ax.legend(loc="upper left", fontsize=8, framealpha=0.85)
    fig.suptitle("Residuals against the temperature rate and the temperature")
    return fig


def correlations(report: DiagnoseResult) -> Figure:
    """(d) Residual autocorrelation and cross-correlation with each candidate's regressor."""
    d = report.diagnosis
    terms = list(d.xcorr)
    ncol = 3
    nrow = 1 + int(np.ceil(len(terms) / ncol))
    fig = Figure(figsize=(WIDTH, 2.6 * nrow), layout="constrained")
    gs = fig.add_gridspec(nrow, ncol)
    ax = fig.add_subplot(gs[0, :])
    lags = np.arange(d.acf.size)
    _stems(ax, lags[1:], d.acf[1:], d.band)
    ax.set_title(f"Autocorrelation of the standardized innovations (Ljung–Box p = "
                 f"{d.ljung_box_p:.2g} over {d.lags} lags)")
    ax.set_xlabel("lag (samples)")
    sig = {c.term for c in report.significant}
    for i, term in enumerate(terms):
        a = fig.add_subplot(gs[1 + i // ncol, i % ncol])
        r = d.xcorr[term]
        m = (r.size - 1) // 2
        _stems(a, np.arange(-m, m + 1), r, d.band)
        peak = float(np.max(np.abs(r)))
        a.set_title(f"{term}{' (significant)' if term in sig else ''}: max |r| {peak:.2f}",
                    fontsize=9, color=MODEL if term in sig else "black")
        a.set_xlabel("lag (samples)", fontsize=8)
    return fig


def _stems(ax: Axes, lags: np.ndarray, r: np.ndarray, band: float) -> None:
    out = np.abs(r) > band
    ax.axhspan(-band, band, color=BAND, alpha=0.5, lw=0, label=f"±1.96/√n = ±{band:.3f}")
    ax.vlines(lags, 0, r, color=np.where(out, MODEL, PRED), lw=1.2)
    ax.axhline(0, color="k", lw=0.6)
    lim = max(0.1, 1.3 * float(np.max(np.abs(r))), 2.5 * band)
    ax.set_ylim(-lim, lim)
    ax.set_xlim(lags[0] - 0.5, lags[-1] + 0.5)
    ax.legend(loc="upper right", fontsize=7, framealpha=0.85)
    ax.grid(alpha=0.3)


def convergence(conv: Sequence[Convergence], report: DiagnoseResult) -> Figure:
    """(e) Estimates over time with ±3σ bands; the final ML estimate as reference."""
    names = list(dict.fromkeys(k for c in conv for k in c.values))
    ncol = 2 if len(names) > 3 else 1
    nrow = int(np.ceil(len(names) / ncol)) or 1
    fig = Figure(figsize=(WIDTH, 2.5 * nrow + 0.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrow, ncol, sharex=True, squeeze=False).ravel())
    for ax, name in zip(axes, names, strict=False):
        lims: list[float] = []
        for i, c in enumerate(conv):
            if name not in c.values:
                continue
            col = IDENT_COLOURS[i % len(IDENT_COLOURS)]
            tt, xlabel = time_axis(c.t)
            v, s = c.values[name], c.stds[name]
            if c.points:
                ax.errorbar(tt, v, yerr=3 * s, color=col, marker="o", ms=4, capsize=3,
                            label=f"{c.label} ±3σ")
                late_pts = slice(v.size // 2, None)  # early windows may be ill-determined
                ok = np.isfinite(v[late_pts]) & np.isfinite(s[late_pts])
                lims += list((v - 3 * s)[late_pts][ok]) + list((v + 3 * s)[late_pts][ok])
            else:
                k = max(1, tt.size // 2000)  # smooth curves: every k-th point is enough
                ax.fill_between(tt[::k], (v - 3 * s)[::k], (v + 3 * s)[::k], color=col,
                                alpha=0.18, lw=0)
                ax.plot(tt[::k], v[::k], color=col, lw=1.3, label=f"{c.label}, ±3σ band")
                late = slice(tt.size // 10, None)
                for arr in (v - 3 * s, v + 3 * s):
                    a = arr[late][np.isfinite(arr[late])]
                    if a.size:
                        lims += list(np.quantile(a, [0.02, 0.98]))
            if ax in axes[-ncol:]:
                ax.set_xlabel(xlabel)
        est = report.fit.parameters.get(name)
        if est is not None:
            ax.axhline(est.value, color="k", ls="--", lw=1.1,
                       label=f"ML final {est.value:.4g} ± {est.std:.2g}")
            lims += [est.value - 4 * est.std, est.value + 4 * est.std]
        if lims:
            lo, hi = min(lims), max(lims)
            pad = 0.08 * (hi - lo) if hi > lo else abs(lo) * 0.1 + 1e-12
            ax.set_ylim(lo - pad, hi + pad)
        unit = report.model.unit(name) if name in report.model.param_names else ""
        unit = pretty_unit(unit, report.unit)
        ax.set_title(f"{name}" + (f" ({unit})" if unit else ""), fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize=7, framealpha=0.85)
    for ax in axes[len(names):]:
        ax.set_visible(False)
    fig.suptitle("Estimate convergence with ±3σ bands (truth unknown: the dashed line is the "
                 "final ML estimate)", fontsize=11)
    return fig


def ledger(points: Sequence[LedgerPoint]) -> Figure:
    """(f) Model error (open loop, 60-s means) with its floor, residual RMS and
    log-likelihood per model of the ledger: the error falling."""
    fig = Figure(figsize=(WIDTH, 6.2), layout="constrained")
    ax0, ax1, ax2 = fig.subplots(3, 1, sharex=True, height_ratios=[3, 2, 2])
    x = np.arange(len(points))
    real = np.array([not p.what_if for p in points])
    err = np.array([p.model_error for p in points])
    floor = np.array([p.floor for p in points])
    rms = np.array([p.rms for p in points])
    ll = np.array([p.loglik for p in points])
    for ax, y, col in ((ax0, err, MODEL), (ax1, rms, PRED), (ax2, ll, DATA)):
        ax.plot(x[real], y[real], color=col, marker="o", ms=7, lw=2)
        if not real.all():  # the what-if point: dashed from the current model, open marker
            k = int(np.flatnonzero(~real)[0])
            ax.plot(x[k - 1:k + 1], y[k - 1:k + 1], color=col, ls="--", lw=1.5)
            ax.plot(x[k], y[k], marker="o", ms=8, mfc="white", mec=col, mew=2)
        ax.grid(alpha=0.3)
        ax.margins(x=0.08, y=0.25)
    if np.isfinite(floor).any():
        ax0.plot(x, floor, color=PRED, ls=":", marker="_", ms=12, lw=1.2,
                 label="floor (the model's own noise)")
        ax0.legend(loc="upper right", fontsize=8, frameon=False)
    base = next((v for v in err if np.isfinite(v)), np.nan)
    for xi, r in zip(x, err, strict=True):
        if not np.isfinite(r):
            continue
        change = f" ({(r / base - 1) * 100:+.0f} %)" if xi and np.isfinite(base) else ""
        ax0.annotate(f"{r:.3g}{change}", (xi, r), ha="center", va="bottom", fontsize=8,
                     xytext=(0, 6), textcoords="offset points")
    ax0.set_ylabel("model error\n(open loop, 60-s)")
    ax0.set_title("The ledger: one point per model, in the order tried"
                  + (" (open: what adding the best candidate would give)"
                     if not real.all() else ""))
    ax1.set_ylabel("innovation RMS")
    ax2.set_ylabel("log-likelihood")
    ax2.set_xticks(x, [_wrap(p.label) for p in points], fontsize=8)
    return fig


def _wrap(label: str, width: int = 22) -> str:
    out, line = [], ""
    for part in label.replace(",", ", ").split(" "):
        if line and len(line) + len(part) + 1 > width:
            out.append(line)
            line = part
        else:
            line = f"{line} {part}".strip()
    out.append(line)
    return "\n".join(out).replace(", ", ",")


def allan(report: DiagnoseResult, dt: float) -> Figure:
    """(g) Allan deviation of the innovations and of the smoothed residuals, with the
    white-noise slope τ^−½."""
    d = report.diagnosis
    fig = Figure(figsize=(WIDTH * 0.7, 4.2), layout="constrained")
    ax = fig.add_subplot()
    tau_e, dev_e = allan_deviation(np.asarray(d.innovations), dt)
    for tau, dev, col, label in ((tau_e, dev_e, PRED, "innovations"),
                                 (d.allan_tau, d.allan_dev, MODEL, "smoothed residuals")):
        ok = (dev > 0) & np.isfinite(dev)
        if not ok.any():
            continue
        tau, dev = tau[ok], dev[ok]
        ax.loglog(tau, dev, marker="o", color=col, label=label)
        ax.loglog(tau, dev[0] * np.sqrt(tau[0] / tau), color=col, ls=":", lw=1)
    ax.plot([], [], color="k", ls=":", lw=1, label="white noise (slope −½)")
    ax.legend(loc="best", fontsize=8)
    ax.set_xlabel("averaging time τ (s)")
    ax.set_ylabel(f"σ(τ) ({report.unit})")
    ax.grid(which="both", alpha=0.3)
    ax.set_title("Allan deviation of the residuals")
    return fig
