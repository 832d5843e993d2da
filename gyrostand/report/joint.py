"""The report of several runs of one gyro: the joint diagnosis as one document (the joint
fit, each run's own parameters and residual check, the bias repeatability and the ranked
candidates), in ``report-<gyro>-joint/`` beside the first run. The HTML page adds the
figures the single-run report shows where they make sense for several runs: each run's
measured drift with the joint open-loop model (stacked), the per-run biases with their
intervals and the repeatability, each run's residual check, and the ranked candidates —
drawn by :mod:`.joint_figures`, written beside the page (or embedded: ``single_file``) as
:mod:`.page` writes the single-run report's."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ..core.diagnose.joint import WHITE_ALPHA, JointDiagnosis
from ..core.model import context
from ..runfolder import write_atomic
from ..workbench import Subject
from ..workbench.joint import run_joint_diagnose
from . import joint_figures, render
from .page import DOCUMENTS, PAGE, default_dir, draw_plots
from .views import Plot

__all__ = ["write_joint_report", "joint_plots"]

#: the joint page's figures, in order
FIGURES = ("joint_measured_vs_model.png", "joint_biases.png", "joint_residual_checks.png",
           "joint_candidates.png")


def joint_plots(subjects: Sequence[Subject], rep: JointDiagnosis
                ) -> list[tuple[Plot, Callable[[], Figure]]]:
    """The joint page's figures: (its :class:`Plot`, the function that draws it)."""
    fit = rep.fit
    model = fit.model
    samples = [s.samples for s in subjects]
    lin = model.names_of_kind("linear")
    dets = []
    titles = []
    for r, (s, run) in enumerate(zip(samples, fit.runs, strict=True)):
        p = run.values
        X = model.regressors(p, context(s, model))
        det = X @ np.array([p[k] for k in lin]) if lin else np.zeros(len(s))
        dets.append(det)
        err = np.asarray(s.drift) - det
        own = ", ".join(f"{k} {run.parameters[k].value:.4g}" for k in model.param_names
                        if f"{k}@{r + 1}" in fit.parameters)
        titles.append(f"run {r + 1}: {s.source} — {own}; open-loop error RMS "
                      f"{float(np.sqrt(np.nanmean(err * err))):.3g}")
    plots: list[tuple[Plot, Callable[[], Figure]]] = [
        (Plot(FIGURES[0],
              "Each run's measured drift with the joint model driven by its temperature "
              "alone (open loop), stacked, temperature overlaid",
              "One panel per run, on the time since its switch-on: measured drift (grey) and "
              "the joint model driven by the run's temperature alone with every noise at zero "
              "(orange: the shared coefficients with the run's own bias and warm-up; what a "
              "thermal compensation built from the joint model would remove); temperature "
              "in red on the right axis. A run the shared physics does not fit stands out."),
         lambda: joint_figures.joint_measured_vs_model(samples, dets, model.names, rep.unit,
                                                 titles)),
    ]
    if fit.repeatability is not None:
        rp = fit.repeatability
        plots.append((Plot(
            FIGURES[1],
            "Each run's turn-on bias with its interval, their mean and the turn-on-to-turn-on "
            "spread",
            f"Orange: each run's own {rp.parameter} with its {rp.level:.0%} interval (the joint "
            "fit's error). Blue line: their random-effects mean; band: ± the spread τ̂ beyond "
            "the estimation errors (REML), the bias repeatability, whose Q-profile interval "
            "is in the title. Biases that differ by far more than their intervals are a "
            "real turn-on-to-turn-on spread."),
            lambda: joint_figures.joint_biases(rp, [s.source for s in samples], rep.unit)))
    alpha = WHITE_ALPHA / max(len(fit.runs), 1)
    plots.append((Plot(
        FIGURES[2],
        "Each run's residual check at the joint estimate: Ljung–Box p and NIS",
        f"Top: −log₁₀ of each run's Ljung–Box p on its standardized innovations; a bar past "
        f"the dashed line (p = {alpha:.2g}, Bonferroni over the runs) is a run the joint "
        "model leaves structure in. Bottom: the mean squared standardized innovation (NIS) "
        "with ±2 standard errors; 1 when the predicted variances are right."),
        lambda: joint_figures.joint_residual_checks(fit, alpha)))
    plots.append((Plot(
        FIGURES[3],
        "The missing effects ranked by their joint likelihood ratio, with the critical "
        "values",
        "Each candidate effect refitted on every run jointly (a per-run effect's parameters "
        "counted once per run): its likelihood ratio against the current model, best first, "
        f"and a tick at its χ² critical value at {rep.alpha:g} (Bonferroni over the "
        "candidates). Orange: significant on the runs together; grey: not identified."),
        lambda: joint_figures.joint_candidates(rep.candidates, rep.alpha)))
    return plots


def write_joint_report(subjects: Sequence[Subject], out_dir: str | Path | None = None, *,
                       format: str = "html", single_file: bool = False) -> Path:
    """Diagnose the runs jointly (no ledger step: a report only reads) and write the
    document in ``format`` (HTML: with the figures of :func:`joint_plots`, beside the page
    or, with ``single_file``, embedded in it); return its path."""
    from .html import e, figure, page

    if format != "html" and format not in DOCUMENTS:
        raise ValueError(f"unknown report format {format!r}")
    first = subjects[0]
    out = (Path(out_dir) if out_dir is not None
           else default_dir(first).with_name(f"report-{first.gyro}-joint"))
    out.mkdir(parents=True, exist_ok=True)
    rep = run_joint_diagnose(subjects, record=False)
    if format != "html":
        doc = render(rep, format)
        path = out / DOCUMENTS[format]
        write_atomic(path, doc, sync=True)
        return path
    plots = joint_plots(subjects, rep)
    drawn = draw_plots(plots, out, single_file)
    from .text import joint_diagnosis

    title = f"gyrostand report: {first.gyro}, {len(subjects)} runs (joint)"
    body = (f"<h1>{e(title)}</h1><pre>{e(joint_diagnosis(rep))}</pre>"
            + "<h2>Figures</h2>" + "".join(figure(p) for p in drawn))
    html = page(title, body)
    path = out / PAGE
    write_atomic(path, html, sync=True)
    return path
