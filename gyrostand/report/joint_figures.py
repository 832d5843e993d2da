"""The joint report's figures (several runs of one gyro): each run's measured drift with
the joint open-loop model (stacked panels), the per-run biases with their repeatability,
each run's residual check, and the ranked candidates; one function per plot, each
returning a matplotlib ``Figure``, drawn as :mod:`.figures` draws the single-run report's
(its colours, widths and helpers)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from ..core.data import Samples
from .figures import (
    BAND,
    DATA,
    MEASURED_LW,
    MODEL,
    MODEL_LW,
    PRED,
    WIDTH,
    pretty_unit,
    temp_twin,
    time_axis,
)
from .series import envelope

#: a joint report stacks at most this many runs' panels (the rest: the tables)
JOINT_PANELS = 8


def joint_measured_vs_model(runs: Sequence[Samples], deterministic: Sequence[np.ndarray],
                            model_names: Sequence[str], unit: str,
                            titles: Sequence[str]) -> Figure:
    """Each run's measured drift with the joint model driven by its temperature alone
    (open loop: the shared coefficients with that run's own bias and warm-up), one panel
    per run stacked on one time unit (time since each switch-on), the temperature on the
    right axis; ``titles`` one line per run."""
    n = min(len(runs), JOINT_PANELS)
    span = max(float(s.t[-1] - s.t[0]) for s in runs[:n])
    _, xlabel = time_axis(np.array([0.0, span]))
    scale = time_axis(np.array([0.0, span]))[0][-1] / span if span > 0 else 1.0
    fig = Figure(figsize=(WIDTH, 1.2 + 2.2 * n), layout="constrained")
    axes = np.atleast_1d(fig.subplots(n, 1, sharex=True))
    tw = None
    for ax, s, det, title in zip(axes, runs, deterministic, titles, strict=False):
        tt = (s.t - s.t[0]) * scale
        ax.plot(*envelope(tt, s.drift), color=DATA, lw=MEASURED_LW, zorder=2,
                label="measured", gid="measured")
        ax.plot(tt, det, color=MODEL, lw=MODEL_LW, zorder=3, gid="model",
                label="joint model driven by the temperature alone (open loop)")
        ax.set_ylabel(f"drift\n({pretty_unit(unit)})", fontsize=8)
        ax.grid(alpha=0.3)
        ax.set_title(title, fontsize=9, loc="left")
        tw = temp_twin(ax, tt, s.temp)
    axes[-1].set_xlabel(f"{xlabel} since each run's switch-on")
    axes[0].set_xlim(0.0, span * scale)
    h1, l1 = axes[0].get_legend_handles_labels()
    extra = tw.get_lines()[:1] if tw is not None else []
    fig.legend(handles=h1 + extra, labels=l1 + ["temperature (right axis)"][:len(extra)],
               loc="outside lower center", ncols=3, fontsize=8, frameon=False)
    more = f" (the first {n} of {len(runs)})" if len(runs) > n else ""
    fig.suptitle(f"Measured drift of each run and the joint model {','.join(model_names)}"
                 f"{more}", fontsize=11)
    return fig


def joint_biases(rep, sources: Sequence[str], unit: str) -> Figure:
    """The per-run turn-on biases with their 95 % intervals (the joint fit's std), their
    random-effects mean μ̂ ± its 95 % interval, and μ̂ ± the spread τ̂ (the turn-on-to-turn-on
    repeatability) with τ's interval in the title. ``rep``: a
    :class:`~gyrostand.core.ml.joint.Repeatability`."""
    from scipy.stats import norm

    z = float(norm.ppf(0.5 + rep.level / 2))
    b, sd = np.asarray(rep.values), np.asarray(rep.stds)
    x = np.arange(1, b.size + 1)
    fig = Figure(figsize=(WIDTH * 0.8, 4.2), layout="constrained")
    ax = fig.add_subplot()
    ax.axhspan(rep.mean - rep.spread, rep.mean + rep.spread, color=BAND, alpha=0.45, lw=0,
               label=f"mean ± spread τ̂ = {rep.spread:.3g}")
    ax.axhline(rep.mean, color=PRED, lw=1.2,
               label=f"mean μ̂ = {rep.mean:.4g} ± {z * rep.mean_std:.2g}")
    ax.errorbar(x, b, yerr=z * sd, fmt="o", color=MODEL, ms=6, capsize=4, lw=1.4,
                label=f"each run's bias, {rep.level:.0%} interval", gid="biases")
    ax.set_xticks(x, [f"run {i}" for i in x], fontsize=8)
    ax.set_xlim(0.4, b.size + 0.6)
    ax.set_ylabel(f"{rep.parameter} ({pretty_unit(rep.unit, unit)})")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8, framealpha=0.85)
    lo, hi = rep.interval
    ax.set_title(f"Turn-on bias repeatability: spread {rep.spread:.3g} "
                 f"({rep.level:.0%} interval {lo:.3g} .. {hi:.3g}); equal biases p = "
                 f"{rep.p:.2g}", fontsize=10)
    return fig


def joint_residual_checks(fit, alpha: float) -> Figure:
    """Each run's residual check at the joint estimate: the Ljung–Box p of its innovations
    (log scale, with the per-run level ``alpha``) and their mean square NIS (1 when the
    predicted variances are right, with its ±2 standard-error band)."""
    checks = [r.info.get("residual_check", {}) for r in fit.runs]
    x = np.arange(1, len(checks) + 1)
    p = np.array([max(c.get("ljung_box_p", np.nan), 1e-300) for c in checks])
    nis = np.array([c.get("nis_mean", np.nan) for c in checks])
    n = np.array([max(c.get("n", 1), 1) for c in checks])
    fig = Figure(figsize=(WIDTH * 0.8, 4.6), layout="constrained")
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    bad = p < alpha
    ax1.bar(x, -np.log10(p), color=np.where(bad, MODEL, PRED), width=0.6)
    ax1.axhline(-np.log10(alpha), color="k", ls="--", lw=1,
                label=f"p = {alpha:.2g} (Bonferroni over the runs)")
    ax1.set_ylim(0.0, 1.3 * max(float(np.nanmax(-np.log10(p))), -np.log10(alpha)))
    ax1.set_ylabel("−log₁₀ Ljung–Box p")
    ax1.legend(loc="upper left", fontsize=8, frameon=False)
    ax1.grid(alpha=0.3)
    ax1.set_title("Each run's innovations at the joint estimate: whiteness and NIS",
                  fontsize=10)
    ax2.errorbar(x, nis, yerr=2 * np.sqrt(2 / n), fmt="o", color=DATA, capsize=4)
    ax2.axhline(1.0, color=PRED, lw=1)
    ax2.set_ylabel("NIS (mean z²)")
    ax2.set_xticks(x, [f"run {i}" for i in x], fontsize=8)
    ax2.grid(alpha=0.3)
    return fig


def joint_candidates(candidates: Sequence, alpha: float) -> Figure:
    """The missing effects ranked by the joint likelihood ratio (each refitted on every
    run), a tick at each one's Bonferroni critical value χ²_df(1 − α/m): bars past it are
    significant on the runs together."""
    from scipy.stats import chi2

    cands = list(candidates)
    m = max(len(cands), 1)
    fig = Figure(figsize=(WIDTH * 0.8, 1.4 + 0.45 * max(len(cands), 1)), layout="constrained")
    ax = fig.add_subplot()
    if not cands:
        ax.text(0.5, 0.5, "no candidate effects", ha="center", va="center",
                transform=ax.transAxes)
        ax.set_axis_off()
        return fig
    y = np.arange(len(cands))[::-1]
    lr = np.array([max(c.lr_stat, 0.0) for c in cands])
    crit = np.array([chi2.ppf(1 - alpha / m, max(c.df, 1)) for c in cands])
    sig = np.array([c.ranked and c.p_value < alpha / m for c in cands])
    colours = [MODEL if s else (PRED if c.ranked else "#bbbbbb")
               for s, c in zip(sig, cands, strict=True)]
    ax.barh(y, np.log1p(lr), color=colours, height=0.6, gid="candidates")
    ax.plot(np.log1p(crit), y, "|", color="k", ms=16, mew=2,
            label=f"critical value at {alpha:g} (Bonferroni over {m})")
    ax.set_yticks(y, [f"{i + 1}. {c.term} (df {c.df})" for i, c in enumerate(cands)],
                  fontsize=8)
    ticks = np.array([0, 1, 3, 10, 30, 100, 300, 1000, 3000, 10000])
    top = float(np.log1p(max(lr.max(), crit.max())))
    ticks = ticks[np.log1p(ticks) <= top * 1.05 + 0.5]
    ax.set_xticks(np.log1p(ticks), [f"{t:g}" for t in ticks], fontsize=8)
    ax.set_xlabel("joint likelihood ratio 2 Δln L (log scale)")
    for yi, v, c in zip(y, lr, cands, strict=True):
        ax.annotate(f"{v:.3g}  p = {c.p_value:.2g}" + ("" if c.ranked else "  (not ranked)"),
                    (np.log1p(v), yi), xytext=(4, 0), textcoords="offset points",
                    va="center", fontsize=7)
    ax.set_xlim(0.0, 1.3 * top + 0.3)
    fig.legend(*ax.get_legend_handles_labels(), loc="outside lower center", fontsize=8,
               frameon=False)
    ax.grid(axis="x", alpha=0.3)
    ax.set_title("Missing effects ranked on the runs together (orange: significant; grey: "
                 "its effect not identified)", fontsize=10)
    return fig
