"""The HTML report: its figures drawn and written, then the page (the HTML renderer's
:func:`gyrostand.report.html.report_page`, from templates), into one self-contained folder.

::

    <run>/report-<gyro>/          (or report-<csv stem>/ beside a CSV, or --out DIR)
        report.html               valid HTML5, inline CSS, no scripts, no network
        measured_vs_model.png     ... one PNG per figure, linked relatively

With ``single_file`` (``report --single-file``) the folder holds ``report.html`` alone:
each PNG is embedded in it as a ``data:image/png;base64,...`` URI, one file to mail.

Every file is written to a temporary name and renamed into place, the page last, so a
reader never sees a half-written file and the page never links to a missing image.
"""

from __future__ import annotations

import base64
import dataclasses
import datetime as _dt
import io
import logging
import struct
from collections.abc import Callable
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from .. import __version__, progress
from ..core.diagnose.results import DiagnoseResult
from ..core.model import context
from ..errors import OutputError
from ..runfolder import write_atomic
from ..workbench import Subject, run_diagnose
from ..workbench.advice import adopt_command, subject_command
from . import figures, render
from .series import convergence, ledger_points, ledger_steps
from .views import AllanView, Plot, ReportPage

log = logging.getLogger(__name__)

PAGE = "report.html"
DPI = 100


def default_dir(subject: Subject) -> Path:
    """Where a subject's report goes by default: ``<out_dir>/report-<gyro>``."""
    return subject.out_dir / f"report-{subject.gyro}"


#: the file of the report in each format but HTML (which is :data:`PAGE` and its figures)
DOCUMENTS = {"text": "report.txt", "json": "report.json"}


def write_report(subject: Subject, out_dir: str | Path | None = None, *,
                 report: DiagnoseResult | None = None, format: str = "html",
                 single_file: bool = False, fit_command: str | None = None,
                 diagnose_command: str | None = None) -> Path:
    """Write the report of ``subject``'s current model; return the path of the HTML page
    (or, with ``format`` ``"text"`` or ``"json"``, of the diagnosis as ``report.txt`` or
    ``report.json``, without figures).

    Args:
        subject: from :func:`gyrostand.workbench.open_subject`.
        out_dir: the report's folder (created); default :func:`default_dir`.
        report: an existing diagnosis of ``subject`` (default: diagnosed here, without
            writing a ledger step: a report only reads the ledger).
        format: ``"html"`` (default), ``"text"`` or ``"json"``.
        single_file: the HTML page with its figures embedded (no PNG files beside it).
        fit_command: the page's ``fit`` step as the user can paste it (default: on the
            data ``subject`` was opened from,
            :func:`~gyrostand.workbench.advice.subject_command`); ``adopt`` is named once
            the model is ADEQUATE and its run's session file lacks it.
        diagnose_command: the page's ``diagnose`` step likewise.
    """
    if format != "html" and format not in DOCUMENTS:
        raise ValueError(f"unknown report format {format!r}")
    out = Path(out_dir) if out_dir is not None else default_dir(subject)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # a file where the folder goes, no permission
        raise OutputError(f"{out}: cannot create the report folder: "
                          f"{exc.strerror or exc}") from exc
    rep = (report if report is not None
           else run_diagnose(subject, record=False, command="report"))
    with progress.stage("report", "Allan tables"):
        allan = AllanView.of_diagnosis(subject, rep)
    now = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    fit = fit_command or subject_command(subject, "fit")
    diag = diagnose_command or subject_command(subject, "diagnose")
    adopt = adopt_command(subject) if rep.adequate else None
    if format != "html":
        doc = render(ReportPage(subject, rep, (), ledger_steps(subject), "", now,
                                __version__, allan, fit, diag, adopt), format)
        path = out / DOCUMENTS[format]
        write_atomic(path, doc, sync=True)
        return path
    s = subject.samples
    ctx = context(s, rep.model)
    p = rep.fit.values
    lin = rep.model.names_of_kind("linear")
    X = rep.model.regressors(p, ctx)
    det = X @ np.array([p[k] for k in lin]) if lin else np.zeros(len(s))
    with progress.stage("report", "estimates over time"):
        conv, conv_source = convergence(subject, rep)
    steps = ledger_steps(subject)
    points = ledger_points(steps, rep, s)

    plots: list[tuple[Plot, Callable[[], Figure]]] = [
        (Plot("measured_vs_model.png",
              "Measured drift over time with the model driven by the temperature alone "
              "(open loop), and the open-loop error beneath with the model's floor",
              "Top: measured drift (grey), the model driven by the temperature alone with "
              "every noise at zero (orange: what a thermal compensation built from this "
              "model would remove) and, faintly, the one-step prediction (blue); "
              "temperature in red on the right axis. Bottom: the open-loop error's 60-s "
              "moving mean; the blue band is the floor the model's own noise predicts — "
              "structure outside it is an effect the model lacks."),
         lambda: figures.measured_vs_model(s, rep, det)),
        (Plot("residuals.png",
              "Innovations and smoothed residuals over time with ±2σ bands and their moving "
              "mean; temperature overlaid",
              "Top: one-step innovations with their predicted ±2σ band. Bottom: smoothed "
              "residuals (the smoothed measurement noise) with ±2σ_v. Orange: moving mean — "
              "it should stay near zero; where it wanders with the temperature (red) the "
              "model misses an effect."),
         lambda: figures.residuals_over_time(s, rep)),
        (Plot("residual_vs_inputs.png",
              "Residuals against dT/dt and against temperature, with binned means",
              "Top: standardized innovations with binned means ±2 standard errors — a flat "
              "row at zero is what a right model gives. Bottom: the drift left after the "
              "model's temperature-driven part, whose binned means show the shape of a "
              "missing effect (a slope against dT/dt: temp_rate or hysteresis; a curve "
              "against T: temp2)."),
         lambda: figures.residual_vs_inputs(s, rep, ctx.temp_rate, det)),
        (Plot("correlations.png",
              "Autocorrelation of the residuals and their cross-correlation with each "
              "candidate effect's regressor, with ±1.96/√n bands",
              "Autocorrelation of the standardized innovations, and their cross-correlation "
              "with each candidate effect's prewhitened regressor (as MATLAB's resid). Bars "
              "outside the band (orange) point at structure the model lacks."),
         lambda: figures.correlations(rep)),
        (Plot("convergence.png",
              "Parameter estimates over time with ±3σ bands and the final ML estimates",
              f"Estimates over time from {conv_source}, with ±3σ bands (as in the paper's "
              "figures). The truth is unknown; the dashed line is the final ML estimate."),
         lambda: figures.convergence(conv, rep)),
        (Plot("ledger.png",
              "Model error with its floor, residual RMS and log-likelihood for each model "
              "of the ledger",
              "The ledger, one point per model in the order tried: the model error "
              "(open-loop RMS of 60-s means; the dotted line is the floor the model's own "
              "noise predicts), the innovation RMS (lower is better) and the "
              "log-likelihood (higher is better)."
              + (" The open point is what adding the best significant candidate gives."
                 if points and points[-1].what_if else "")),
         lambda: figures.ledger(points)),
        (Plot("allan.png", "Allan deviation of the innovations and of the smoothed "
              "residuals, log-log",
              "Allan deviation of the innovations and of the smoothed residuals. White "
              "innovations follow the dotted slope −½; a flattening or a rise at long τ is "
              "slow drift the model does not explain. (Smoothed residuals fall faster: the "
              "smoother removes their slow part.)"),
         lambda: figures.allan(rep, s.dt)),
    ]
    drawn = draw_plots(plots, out, single_file)
    page = render(ReportPage(subject, rep, drawn, steps, conv_source, now, __version__,
                             allan, fit, diag, adopt), "html")
    path = out / PAGE
    write_atomic(path, page, sync=True)
    log.info("report written to %s", path)
    return path


def png_bytes(fig: Figure) -> bytes:
    """``fig`` drawn as a PNG (Agg, at :data:`DPI`)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    return buf.getvalue()


def png_size(path: Path) -> tuple[int, int]:
    """Width and height of a PNG file from its IHDR chunk."""
    with path.open("rb") as fh:
        head = fh.read(24)
    return png_header_size(head, str(path))


def png_header_size(data: bytes, name: str = "image") -> tuple[int, int]:
    """Width and height of the PNG whose bytes start with ``data`` (its IHDR chunk)."""
    if data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR":
        raise ValueError(f"{name}: not a PNG file")
    w, h = struct.unpack(">II", data[16:24])
    return int(w), int(h)


def draw_plots(plots, out: Path, single_file: bool) -> list:
    """Draw each ``(plot, make)`` (``make()`` returns the figure): its PNG written beside
    the page in ``out``, or, with ``single_file``, embedded as a data URI (a PNG an
    earlier folder report left there is removed); the plots with their sizes and
    sources, in order. Shared by the single-run and the joint report."""
    drawn = []
    with progress.stage("report", "figures", total=len(plots), unit="figures") as bar:
        for plot, make in plots:
            fig = make()
            png = png_bytes(fig)
            if single_file:
                drawn.append(dataclasses.replace(plot, size=png_header_size(png), src=(
                    "data:image/png;base64," + base64.b64encode(png).decode("ascii"))))
                (out / plot.file).unlink(missing_ok=True)  # an earlier folder report's
            else:
                write_atomic(out / plot.file, png, sync=True)
                drawn.append(dataclasses.replace(plot, size=png_size(out / plot.file)))
            bar.update()
    return drawn
