"""The HTML page: verdict, tables and the figures, written into one self-contained folder.

::

    <run>/report-<gyro>/          (or report-<csv stem>/ beside a CSV, or --out DIR)
        report.html               valid HTML5, inline CSS, no scripts, no network
        measured_vs_model.png     ... one PNG per figure, linked relatively

Every file is written to a temporary name and renamed into place, the page last, so a
reader never sees a half-written file and the page never links to a missing image.
"""

from __future__ import annotations

import datetime as _dt
import html
import logging
import os
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from matplotlib.figure import Figure

from .. import __version__
from ..core.candidates import Report
from ..core.model import context
from ..workbench import Subject, run_diagnose
from . import figures
from .figures import pretty_unit
from .series import convergence, ledger_points, ledger_steps

log = logging.getLogger(__name__)

PAGE = "report.html"
DPI = 100


@dataclass(frozen=True)
class Plot:
    """One figure of the page."""

    file: str
    alt: str
    caption: str


def default_dir(subject: Subject) -> Path:
    """Where a subject's report goes by default: ``<out_dir>/report-<gyro>``."""
    return subject.out_dir / f"report-{subject.gyro}"


def write_report(subject: Subject, out_dir: str | Path | None = None, *,
                 report: Report | None = None) -> Path:
    """Write the report of ``subject``'s current model; return the path of the HTML page.

    Args:
        subject: from :func:`gyrostand.workbench.open_subject`.
        out_dir: the report's folder (created); default :func:`default_dir`.
        report: an existing diagnosis of ``subject`` (default: diagnosed here, without
            writing a ledger step: a report only reads the ledger).
    """
    out = Path(out_dir) if out_dir is not None else default_dir(subject)
    out.mkdir(parents=True, exist_ok=True)
    rep = report if report is not None else run_diagnose(subject, record=False)
    s = subject.samples
    ctx = context(s)
    p = rep.fit.values
    lin = rep.model.names_of_kind("linear")
    X = rep.model.regressors(p, ctx)
    det = X @ np.array([p[k] for k in lin]) if lin else np.zeros(len(s))
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
    sizes = {}
    for plot, make in plots:
        fig = make()
        _atomic(out / plot.file, _png(fig))
        sizes[plot.file] = png_size(out / plot.file)
    page = render(subject, rep, [pl for pl, _ in plots], sizes, steps, conv_source)
    path = out / PAGE
    _atomic(path, lambda fh: fh.write(page.encode("utf-8")))
    log.info("report written to %s", path)
    return path


def _png(fig: Figure) -> Callable[[IO[bytes]], Any]:
    return lambda fh: fig.savefig(fh, format="png", dpi=DPI)


def _atomic(path: Path, write: Callable[[IO[bytes]], Any]) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with tmp.open("wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def png_size(path: Path) -> tuple[int, int]:
    """Width and height of a PNG from its IHDR chunk."""
    with path.open("rb") as fh:
        head = fh.read(24)
    if head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        raise ValueError(f"{path}: not a PNG file")
    w, h = struct.unpack(">II", head[16:24])
    return int(w), int(h)


# ---- HTML --------------------------------------------------------------------------------

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0 auto;
max-width:1060px;padding:1em 1.5em;color:#222;line-height:1.45}
h1{margin-bottom:.2em}h2{border-bottom:1px solid #ddd;padding-bottom:.2em;margin-top:1.6em}
.meta{color:#555;font-size:.92em}
.verdict{padding:.6em 1em;border-radius:6px;font-weight:600;font-size:1.15em;display:inline-block}
.ok{background:#e5f5e0;color:#1b5e20}.bad{background:#fde0dd;color:#8e0000}
table{border-collapse:collapse;margin:.6em 0;font-size:.9em}
th,td{border:1px solid #ddd;padding:.25em .55em;text-align:right}
th{background:#f4f4f4}td.l,th.l{text-align:left}tr.sig td{background:#fff3e0;font-weight:600}
figure{margin:1.2em 0}figure img{max-width:100%;height:auto;border:1px solid #eee}
figcaption{color:#444;font-size:.9em;margin-top:.3em}
code{background:#f4f4f4;padding:0 .25em;border-radius:3px}
.advice{background:#eef5fb;border-left:4px solid #1f78b4;padding:.4em .8em}
"""


def _e(x: Any) -> str:
    return html.escape(str(x), quote=True)


def _num(x: float | None, fmt: str = ".4g") -> str:
    if x is None or not np.isfinite(x):
        return "—"
    return format(float(x), fmt)


def _unit(u: str, drift: str) -> str:
    return pretty_unit(u, drift)


def _table(head: Sequence[str], rows: Sequence[Sequence[str]], left: int = 1,
           row_class: Sequence[str] | None = None) -> str:
    lc = ' class="l"'
    th = "".join(f"<th{lc if i < left else ''}>{_e(h)}</th>" for i, h in enumerate(head))
    body = []
    for r, row in enumerate(rows):
        cls = f' class="{row_class[r]}"' if row_class and row_class[r] else ""
        tds = "".join(f"<td{lc if i < left else ''}>{c}</td>" for i, c in enumerate(row))
        body.append(f"<tr{cls}>{tds}</tr>")
    return f"<table><thead><tr>{th}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _figure(plot: Plot, size: tuple[int, int]) -> str:
    return (f'<figure><img src="{_e(plot.file)}" alt="{_e(plot.alt)}" width="{size[0]}" '
            f'height="{size[1]}"><figcaption>{_e(plot.caption)}</figcaption></figure>')


def render(subject: Subject, rep: Report, plots: Sequence[Plot],
           sizes: dict[str, tuple[int, int]], steps: Sequence[dict[str, Any]],
           conv_source: str) -> str:
    """The page as a string (HTML5)."""
    s, d, fit = subject.samples, rep.diagnosis, rep.fit
    fig = {p.file: _figure(p, sizes[p.file]) for p in plots}
    dur = float(s.t[-1] - s.t[0]) if len(s) else 0.0
    now = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    model = ",".join(rep.model.names)
    out: list[str] = [
        "<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>gyrostand report: {_e(subject.gyro)} ({_e(model)})</title>",
        f"<style>{CSS}</style>", "</head>", "<body>",
        f"<h1>gyrostand report: gyro {_e(subject.gyro)}</h1>",
        f'<p class="meta">Data: <code>{_e(s.source)}</code> ({_e(subject.origin)}); '
        f"{len(s)} samples every {s.dt:g} s over {dur / 3600:.2f} h, "
        f"{len(s) - s.n_observed} gaps; temperature {float(np.min(s.temp)):.2f} to "
        f"{float(np.max(s.temp)):.2f} °C. Model <code>{_e(model)}</code>. "
        f"Drift unit {_e(rep.unit)}"
        + (" (not named: give it with --unit)" if rep.unit == "y" else " (from the DBC or "
           "--unit)") + f". Written {now} by gyrostand {__version__}.</p>",
    ]
    # verdict
    out.append("<h2>Verdict</h2>")
    cls, word = ("ok", "ADEQUATE") if rep.adequate else ("bad", "NOT ADEQUATE")
    out.append(f'<p><span class="verdict {cls}">{word}</span></p>')
    if rep.reasons:
        out.append("<ul>" + "".join(f"<li>{_e(r)}</li>" for r in rep.reasons) + "</ul>")
    else:
        out.append("<p>The innovations are white and no candidate effect is significant "
                   "after the Bonferroni correction.</p>")
    if not rep.adequate and rep.significant:
        best = rep.significant[0]
        out.append(f"<p>Next step: <code>gyrostand fit RUN --add {_e(best.term)}</code> "
                   f"(residual RMS {_num(d.rms)} → {_num(best.rms_after)}).</p>")
    me = rep.model_error
    if me is not None:
        h = me.headline()
        out.append(
            f"<p><b>Model error</b> (measured − the model driven by the temperature alone, "
            f"RMS of {h['window_s']:g}-s means over the run): {_num(h['rms'])} "
            f"{_e(me.unit)}; the floor the model's own noise leaves: {_num(h['floor'])}; "
            f"unexplained √(error² − floor²): {_num(h['unexplained'])}; fit "
            f"{_num(h['fit_percent'], '.1f')} %.</p>")
    out.append(fig["measured_vs_model.png"])
    # parameters and residual statistics
    out.append("<h2>Parameters (maximum likelihood)</h2>")
    rows = [[f"<code>{_e(k)}</code>", _num(e.value, ".6g"),
             "fixed" if e.fixed else _num(e.std, ".3g"), _e(_unit(e.unit, rep.unit))]
            for k, e in fit.parameters.items()]
    out.append(_table(["parameter", "value", "± std", "unit"], rows, left=1))
    out.append(_table(["residual statistic", "value"], [
        [f"innovation RMS ({_e(rep.unit)})", _num(d.rms)],
        [f"smoothed-residual RMS ({_e(rep.unit)})", _num(d.smoothed_rms)],
        ["log-likelihood", _num(fit.loglik, ".6g")],
        [f"Ljung–Box Q over {d.lags} lags", _num(d.ljung_box_q)],
        ["Ljung–Box p (white when ≥ 0.01)", _num(d.ljung_box_p, ".3g")],
        ["mean normalized innovation²",
         f"{_num(d.nis_mean)} (95 % band {_num(d.nis_band[0])}–{_num(d.nis_band[1])})"],
    ]))
    # residuals
    out.append("<h2>Where the model fails</h2>")
    out.append(fig["residuals.png"])
    out.append("<h3>Per segment of the temperature profile</h3>")
    out.append(_table(
        ["kind", "t from (s)", "t to (s)", "T from (°C)", "T to (°C)", "n",
         "mean innovation", "innovation RMS", "mean smoothed residual"],
        [[_e(g["kind"]), _num(g["t_start"], ".0f"), _num(g["t_stop"], ".0f"),
          _num(g["temp_start"], ".2f"), _num(g["temp_stop"], ".2f"), str(g["n"]),
          _num(g["mean"], ".3g"), _num(g["rms"], ".3g"), _num(g["smoothed_mean"], ".3g")]
         for g in d.segments]))
    out.append(fig["residual_vs_inputs.png"])
    out.append(fig["correlations.png"])
    out.append(fig["allan.png"])
    # candidates
    m = max(len(rep.candidates), 1)
    out.append("<h2>Which effect is missing</h2>")
    out.append(f"<p>Every vocabulary term not in the model, refitted by ML and compared by "
               f"likelihood ratio; ranked best first. Significant (marked ★, highlighted): "
               f"p &lt; {rep.alpha:g}/{m} = {_num(rep.alpha / m, '.2g')} (Bonferroni).</p>")
    sig = {c.term for c in rep.significant}
    rows, classes = [], []
    for i, c in enumerate(rep.candidates, start=1):
        eff = "<br>".join(f"<code>{_e(k)}</code> = {_num(e.value, '.4g')} ± "
                          f"{_num(e.std, '.2g')} {_e(_unit(e.unit, rep.unit))}"
                          for k, e in c.effect.items())
        rows.append([f"{i}. {'★ ' if c.term in sig else ''}<code>{_e(c.term)}</code>",
                     _num(c.lr_stat, ".2f"), str(c.df), _num(c.p_value, ".2g"),
                     _num(c.delta_aic, ".1f"), _num(c.delta_bic, ".1f"),
                     _num(c.rms_after), eff])
        classes.append("sig" if c.term in sig else "")
    out.append(_table(["term", "LR", "df", "p", "ΔAIC", "ΔBIC", "RMS after", "effect"],
                      rows, row_class=classes) if rows else "<p>No candidate terms.</p>")
    for la in rep.look_alikes:
        a, b = la["terms"]
        out.append(f'<p class="advice"><b>Look-alikes:</b> <code>{_e(a)}</code> and '
                   f"<code>{_e(b)}</code> explain these data about equally well (ΔAIC "
                   f"{_num(la['delta_aic'][0], '.1f')} vs {_num(la['delta_aic'][1], '.1f')}). "
                   f"To separate them: {_e(la['advice'])}.</p>")
    # convergence
    out.append("<h2>Estimate convergence</h2>")
    out.append(fig["convergence.png"])
    # ledger
    out.append("<h2>The ledger: model steps</h2>")
    out.append(fig["ledger.png"])
    if steps:
        out.append(_table(["step", "time (UTC)", "action", "change", "model",
                           "model error", "RMS after", "log-likelihood", "adequate"],
                          [_ledger_row(st) for st in steps], left=5))
    else:
        out.append(f"<p>The ledger <code>{_e(subject.ledger_path.name)}</code> has no steps "
                   "yet: <code>gyrostand diagnose RUN</code> and <code>gyrostand fit RUN "
                   "--add TERM</code> record them.</p>")
    warns = list(dict.fromkeys(fit.warnings))
    if warns:
        out.append("<h2>Warnings</h2><ul>" + "".join(f"<li>{_e(w)}</li>" for w in warns)
                   + "</ul>")
    out += ["</body>", "</html>", ""]
    return "\n".join(out)


def _ledger_row(st: dict[str, Any]) -> list[str]:
    act = st.get("action", "?")
    if act == "fit":
        after = st.get("after", {})
        change = " ".join([f"+{t}" for t in st.get("added", [])]
                          + [f"−{t}" for t in st.get("removed", [])])
        rms, ll, adequate = after.get("rms"), after.get("loglik"), "—"
        err = after.get("model_error")
    else:
        change, rms, ll = "", st.get("rms"), st.get("loglik")
        err = st.get("model_error")
        ok = st.get("adequate")
        adequate = "yes" if ok is True else "no" if ok is False else "—"
    return [_e(st.get("step", "")), _e(str(st.get("time", "")).replace("+00:00", "")),
            _e(act), _e(change), f"<code>{_e(','.join(st.get('model', [])))}</code>",
            _num(err) if isinstance(err, int | float) else "—", _num(rms), _num(ll, ".6g"),
            adequate]
