"""HTML documents: one self-contained HTML5 page per result (inline CSS, no scripts, no
network), laid out by the ``string.Template`` files of ``templates/``.

``page.html`` is every page's frame (title, ``style.css``, body); each kind has its body's
template (``report.html``, ``diagnosis.html``, ``fit_result.html``, ``fit_step.html``,
``allan.html``, ``run.html``) whose ``$name`` slots this module fills with escaped text and
with tables (``table.html``) and figures (``figure.html``). Every value is escaped here:
a template holds markup only.
"""

from __future__ import annotations

import html
import math
from collections.abc import Callable, Mapping, Sequence
from functools import cache
from importlib import resources
from string import Template
from typing import TYPE_CHECKING, Any

from ..core.diagnose.joint import JointDiagnosis
from ..core.ml.joint import JointFit
from ..core.results import FitResult
from ..core.summary import shown_warnings, unit_text
from . import ByKind
from . import allan_text as _allan
from . import text as _text
from .views import (
    FIT_RUN,
    AllanView,
    DiagnosisView,
    FitStepView,
    Plot,
    ReportPage,
    RunFinals,
    RunSummary,
)

if TYPE_CHECKING:
    from ..core.diagnose.results import DiagnoseResult
    from .views import GyroFinals

__all__ = ["RENDERER", "page", "table", "figure", "e", "num"]


@cache
def template(name: str) -> Template:
    """``templates/<name>`` of this package."""
    return Template((resources.files(__package__) / "templates" / name).read_text("utf-8"))


def fill(name: str, **slots: Any) -> str:
    """The template ``name`` with its slots filled (every slot must be given)."""
    return template(name).substitute({k: str(v) for k, v in slots.items()})


def page(title: str, body: str) -> str:
    """A whole HTML5 page: ``title`` (text, escaped here) and ``body`` (markup)."""
    return fill("page.html", title=e(title), css=template("style.css").template, body=body)


def e(x: Any) -> str:
    """``x`` as escaped HTML text."""
    return html.escape(str(x), quote=True)


def num(x: float | None, fmt: str = ".4g") -> str:
    """A number as shown (``—`` for none or non-finite)."""
    if x is None or not math.isfinite(x):
        return "—"
    return format(float(x), fmt)


def table(head: Sequence[str], rows: Sequence[Sequence[str]], left: int = 1,
          row_class: Sequence[str] | None = None) -> str:
    """A table: ``head`` text (escaped here), ``rows`` of markup cells; the first ``left``
    columns left-aligned; ``row_class`` a CSS class per row (``""`` for none)."""
    lc = ' class="l"'
    th = "".join(f"<th{lc if i < left else ''}>{e(h)}</th>" for i, h in enumerate(head))
    body = []
    for r, row in enumerate(rows):
        cls = f' class="{row_class[r]}"' if row_class and row_class[r] else ""
        tds = "".join(f"<td{lc if i < left else ''}>{c}</td>" for i, c in enumerate(row))
        body.append(f"<tr{cls}>{tds}</tr>")
    return fill("table.html", head=th, rows="".join(body)).rstrip("\n")


def figure(plot: Plot) -> str:
    """A figure: the PNG beside the page (or embedded), its alt text, size and caption."""
    return fill("figure.html", file=e(plot.src or plot.file), alt=e(plot.alt), width=plot.size[0],
                height=plot.size[1], caption=e(plot.caption)).rstrip("\n")


def warnings(items: Sequence[str]) -> str:
    ws = shown_warnings(list(dict.fromkeys(items)))
    if not ws:
        return ""
    return "<h2>Warnings</h2><ul>" + "".join(f"<li>{e(w)}</li>" for w in ws) + "</ul>"


def _estimate(value: float, std: float, unit: str, fixed: bool, drift: str) -> str:
    sd = "fixed" if fixed else f"± {num(std, '.3g')}"
    return f"{num(value, '.6g')} {sd} {e(unit_text(unit, drift))}"


# ---- a diagnosis: shared by the diagnose page and the report ------------------------------

def verdict(rep: DiagnoseResult, fit_command: str = FIT_RUN, adopt_command: str | None = None
            ) -> str:
    """The verdict, its reasons, and the next step: ``fit_command --add TERM`` when a
    candidate is significant, ``adopt_command`` when the model is ADEQUATE (and its run's
    session file lacks it)."""
    cls, word = ("ok", "ADEQUATE") if rep.adequate else ("bad", "NOT ADEQUATE")
    out = [f'<p><span class="verdict {cls}">{word}</span></p>']
    if rep.reasons:
        out.append("<ul>" + "".join(f"<li>{e(r)}</li>" for r in rep.reasons) + "</ul>")
    else:
        out.append("<p>The innovations are white and no candidate effect is significant "
                   "after the Bonferroni correction.</p>")
    out += [f'<p class="meta">Note: {e(n)}</p>' for n in rep.notes]
    if getattr(rep, "jump", False) or getattr(rep, "cycling", False):
        what = ("the level shift, a step at its instant" if rep.jump else
                "the periodic disturbance, a sine and a cosine at its period")
        out.append(f"<p>Next step: <code>{e(_text.term_new_command(fit_command))}</code> "
                   f"(writes a plugin term of {what}; review it, pip install it, then fit "
                   "--add it: README, plugins).</p>")
    elif not rep.adequate and rep.significant:
        best = rep.significant[0]
        out.append(f"<p>Next step: <code>{e(fit_command)} --add {e(best.term)}</code> "
                   f"(residual RMS {num(rep.diagnosis.rms)} → {num(best.rms_after)}).</p>")
        if rep.tie:
            out.append(f"<p>{e(_text.tie_advice(rep.tie))} "
                       f"<code>{e(_text.second_run_command(fit_command))}</code></p>")
    elif rep.adequate and adopt_command:
        out.append(f"<p>Next step: <code>{e(adopt_command)}</code> (writes this model into "
                   "the run's session file; the daemon uses it from its next run).</p>")
    return "\n".join(out)


def model_error(rep: DiagnoseResult) -> str:
    me = rep.model_error
    if me is None:
        return ""
    h = me.headline()
    return (f"<p><b>Model error</b> (measured − the model driven by the temperature alone, "
            f"RMS of {h['window_s']:g}-s means over the run): {num(h['rms'])} "
            f"{e(me.unit)}; the floor the model's own noise leaves: {num(h['floor'])}; "
            f"unexplained √(error² − floor²), 0 at floor: {num(h['unexplained'])}; fit "
            f"{num(h['fit_percent'], '.1f')} %.</p>")


def parameters(rep: DiagnoseResult) -> str:
    """The ML parameters and the residual statistics."""
    d, fit = rep.diagnosis, rep.fit
    rows = [[f"<code>{e(k)}</code>", num(x.value, ".6g"),
             "fixed" if x.fixed else num(x.std, ".3g"), e(unit_text(x.unit, rep.unit))]
            for k, x in fit.parameters.items()]
    return "\n".join([table(["parameter", "value", "± std", "unit"], rows, left=1), table(
        ["residual statistic", "value"], [
            [f"innovation RMS ({e(rep.unit)})", num(d.rms)],
            [f"smoothed-residual RMS ({e(rep.unit)})", num(d.smoothed_rms)],
            ["log-likelihood", num(fit.loglik, ".6g")],
            [f"Ljung–Box Q over {d.lags} lags", num(d.ljung_box_q)],
            ["Ljung–Box p (white when ≥ 0.01)", num(d.ljung_box_p, ".3g")],
            ["mean normalized innovation²",
             f"{num(d.nis_mean)} (95 % band {num(d.nis_band[0])}–{num(d.nis_band[1])})"],
        ])])


def segments(rep: DiagnoseResult) -> str:
    """Residuals per segment of the profile; times from the run's start (a log's are
    epoch seconds)."""
    segs = rep.diagnosis.segments
    t0 = segs[0]["t_start"] if segs else 0.0
    return table(
        ["kind", "t from (s)", "t to (s)", "T from (°C)", "T to (°C)", "n",
         "mean innovation", "innovation RMS", "mean smoothed residual"],
        [[e(g["kind"]), num(g["t_start"] - t0, ".0f"), num(g["t_stop"] - t0, ".0f"),
          num(g["temp_start"], ".2f"), num(g["temp_stop"], ".2f"), str(g["n"]),
          num(g["mean"], ".3g"), num(g["rms"], ".3g"), num(g["smoothed_mean"], ".3g")]
         for g in segs])


def candidates(rep: DiagnoseResult) -> str:
    """The ranked candidates (significant ones starred and highlighted), the look-alikes."""
    m = max(len(rep.candidates), 1)
    out = [f"<p>Every vocabulary term not in the model, refitted by ML and compared by "
           f"likelihood ratio; ranked best first. Significant (marked ★, highlighted): "
           f"p &lt; {rep.alpha:g}/{m} = {num(rep.alpha / m, '.2g')} (Bonferroni).</p>"]
    sig = {c.term for c in rep.significant}
    rows, classes = [], []
    for i, c in enumerate(rep.candidates, start=1):
        eff = "<br>".join(f"<code>{e(k)}</code> = {num(x.value, '.4g')} ± "
                          f"{num(x.std, '.2g')} {e(unit_text(x.unit, rep.unit))}"
                          for k, x in c.effect.items())
        note = f"<br>({e(c.note)})" if c.note else ""
        rows.append([f"{i}. {'★ ' if c.term in sig else ''}<code>{e(c.term)}</code>",
                     ("LM " if c.screened else "") + num(c.lr_stat, ".2f"), str(c.df),
                     num(c.p_value, ".2g"),
                     *(["—"] * 3 if c.screened else
                       [num(c.delta_aic, ".1f"), num(c.delta_bic, ".1f"), num(c.rms_after)]),
                     (eff + note).removeprefix("<br>")])
        classes.append("sig" if c.term in sig else "")
    out.append(table(["term", "LR", "df", "p", "ΔAIC", "ΔBIC", "RMS after", "effect"],
                     rows, row_class=classes) if rows else "<p>No candidate terms.</p>")
    if rows:
        out.append(f"<p>p from: {e(_text.tests_used(rep.candidates))}.</p>")
    for la in rep.look_alikes:
        a, b = la["terms"]
        out.append(f'<p class="advice"><b>Look-alikes:</b> <code>{e(a)}</code> and '
                   f"<code>{e(b)}</code> explain these data about equally well (ΔAIC "
                   f"{num(la['delta_aic'][0], '.1f')} vs {num(la['delta_aic'][1], '.1f')}). "
                   + (f"To separate them, design the run that does: "
                      f"<code>{e(la['command'])}</code></p>" if "command" in la else
                      f"To separate them: {e(la['advice'])}.</p>"))
    return "\n".join(out)


def diagnosis(view: DiagnosisView) -> str:
    rep = view.report
    model = ",".join(rep.model.names)
    return page(f"gyrostand diagnosis: {model}", fill(
        "diagnosis.html", model=e(model), source=e(view.source), unit=e(rep.unit),
        verdict=verdict(rep, view.fit_command, view.adopt_command),
        parameters=parameters(rep),
        model_error=model_error(rep), segments=segments(rep), candidates=candidates(rep), allan=allan_block(view.allan),
        warnings=warnings(rep.fit.warnings)))


# ---- the report page ----------------------------------------------------------------------

def report_page(view: ReportPage) -> str:
    """The report of a subject's current model, its figures beside it."""
    subject, rep = view.subject, view.report
    s = subject.samples
    fig = {p.file.removesuffix(".png"): figure(p) for p in view.plots}
    dur = float(s.t[-1] - s.t[0]) if len(s) else 0.0
    model = ",".join(rep.model.names)
    meta = (f"Data: <code>{e(s.source)}</code> ({e(subject.origin)}); "
            f"{len(s)} samples every {s.dt:g} s over {dur / 3600:.2f} h, "
            f"{len(s) - s.n_observed} gaps; temperature {float(min(s.temp)):.2f} to "
            f"{float(max(s.temp)):.2f} °C. Model <code>{e(model)}</code>. "
            f"Drift unit {e(rep.unit)}"
            + (" (not named: give it with --unit)" if rep.unit == "y" else " (from the DBC or "
               "--unit)") + f". Written {e(view.written)} by gyrostand {e(view.version)}.")
    if view.steps:
        ledger = table(["step", "time (UTC)", "action", "change", "model", "model error",
                        "RMS after", "log-likelihood", "adequate"],
                       [_ledger_row(st) for st in view.steps], left=5)
    else:
        ledger = (f"<p>The ledger <code>{e(subject.ledger_path.name)}</code> has no steps "
                  f"yet: <code>{e(view.diagnose_command)}</code> and "
                  f"<code>{e(view.fit_command)} --add TERM</code> record them.</p>")
    body = fill("report.html", gyro=e(subject.gyro), meta=meta,
                verdict=verdict(rep, view.fit_command, view.adopt_command) + "\n"
                + model_error(rep),
                parameters=parameters(rep), segments=segments(rep),
                candidates=candidates(rep), ledger=ledger, allan=allan_block(view.allan),
                warnings=warnings(rep.fit.warnings),
                **{f"fig_{k}": v for k, v in fig.items()})
    return page(f"gyrostand report: {subject.gyro} ({model})", body)


def _ledger_row(st: Mapping[str, Any]) -> list[str]:
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
    return [e(st.get("step", "")), e(str(st.get("time", "")).replace("+00:00", "")),
            e(act), e(change), f"<code>{e(','.join(st.get('model', [])))}</code>",
            num(err) if isinstance(err, int | float) else "—", num(rms), num(ll, ".6g"),
            adequate]


# ---- identify, fit, allan -----------------------------------------------------------------

def fit_result(r: FitResult) -> str:
    rows = [[f"<code>{e(k)}</code>", num(x.value, ".6g"),
             "fixed" if x.fixed else num(x.std, ".4g"), e(unit_text(x.unit, r.unit))]
            for k, x in r.parameters.items()]
    stats = [[f"residual RMS ({e(r.unit)})", num(r.residual_rms, ".6g")]]
    if r.loglik is not None:
        stats.insert(0, ["log-likelihood", num(r.loglik, ".6f")])
    model = ",".join(r.model.names)
    return page(f"gyrostand identify: {r.method} ({model})", fill(
        "fit_result.html", method=e(r.method), model=e(model), observed=r.n_observed,
        samples=r.n_samples, dt=f"{r.dt:g}", source=e(r.source),
        parameters=table(["parameter", "value", "± std", "unit"], rows),
        statistics=table(["statistic", "value"], stats), warnings=warnings(r.warnings)))


def fit_step(view: FitStepView) -> str:
    step = view.step
    b, a = step.before, step.after
    eb, ea = step.before_error, step.after_error
    u = ea.unit if ea is not None else "y"
    rows = []
    for k in dict.fromkeys(list(b.parameters) + list(a.parameters)):
        pb, pa = b.parameters.get(k), a.parameters.get(k)
        rows.append([f"<code>{e(k)}</code>",
                     _estimate(pb.value, pb.std, pb.unit, pb.fixed, u) if pb else "—",
                     _estimate(pa.value, pa.std, pa.unit, pa.fixed, u) if pa else "—"])
    rows.append(["log-likelihood", num(b.loglik, ".3f"), num(a.loglik, ".3f")])
    rows.append(["residual RMS", num(b.residual_rms, ".5g"), num(a.residual_rms, ".5g")])
    err = ""
    if eb is not None and ea is not None:
        hb, ha = eb.headline(), ea.headline()
        rows += [[f"model error ({e(u)})", num(eb.rms), num(ea.rms)],
                 ["its floor", num(eb.floor), num(ea.floor)],
                 ["unexplained", num(hb["unexplained"] or 0.0), num(ha["unexplained"] or 0.0)]]
        err = (f'<p class="meta">Model error: open-loop RMS of {hb["window_s"]:g}-s means over '
               f"the run, {e(u)}; floor: what the model's own noise leaves.</p>")
    # the sentence of the likelihood-ratio test: the text's, which says it best
    test = _text.fit_step(view).split("\n\n", 1)[1].split("\n")
    change = " ".join([f"+{t}" for t in step.added] + [f"−{t}" for t in step.removed])
    return page(f"gyrostand fit: {change}", fill(
        "fit_step.html", change=e(change), before=e(",".join(b.model.names)),
        after=e(",".join(a.model.names)), table=table(["", "before", "after"], rows),
        test="<br>".join(e(x) for x in test if not x.startswith("warning: ")),
        model_error=err, warnings=warnings(a.warnings)))


def _allan_slots(view: AllanView) -> dict[str, str]:
    """The slots of ``allan.html`` and ``allan_block.html``: meta line, table, warnings."""
    t0 = view.raw
    meta = (f"{t0.n} samples at Δt = {view.dt:g} s of <code>{e(view.source)}</code>, "
            f"τ {t0.tau[0]:g}..{t0.tau[-1]:g} s; {t0.level:.0%} confidence intervals "
            f"(overlapping ADEV, EDF); IEEE Std 952 figures.")
    rows = [[f"{e(t0.figures[n].symbol)} {e(_allan.TITLES[n])}"]
            + ["<br>".join(e(x) for x in _allan.allan_figure(t, n)) for t in view.tables]
            for n in _allan.ORDER]
    return {"gyro": e(view.gyro), "meta": meta,
            "table": table(["figure", *[t.label for t in view.tables]], rows, left=3),
            "warnings": warnings([f"{t.label}: {w}" for t in view.tables
                                  for w in t.warnings])}


def allan(view: AllanView) -> str:
    return page(f"gyrostand allan: {view.gyro}", fill("allan.html", **_allan_slots(view)))


def allan_block(view: AllanView | None) -> str:
    """A diagnosis's Allan tables as a section of its page (empty when not computed)."""
    if view is None:
        return ""
    return fill("allan_block.html", **_allan_slots(view)).rstrip("\n")


# ---- the end of a run ---------------------------------------------------------------------

def result_table(final: GyroFinals, truth: Mapping[str, float] | None) -> str:
    """One gyro's final fits: a column per method (the online lkf's batch refit left out
    where the text leaves it out), the truth first where known."""
    methods = list(final.fits)
    if _text.same_fit(final.fits.get("lkf"), final.fits.get("lkf_batch")):
        methods.remove("lkf_batch")
    rows, unit = [], {}
    for name in final.model.param_names:
        row = [f"<code>{e(name)}</code>"] + ([num(truth.get(name), ".5g")] if truth else [])
        for m in methods:
            f = final.fits[m]
            if isinstance(f, FitResult) and name in f.parameters:
                x = f.parameters[name]
                unit[name] = unit_text(x.unit, final.unit)
                row.append(f"{num(x.value, '.5g')} (held)" if x.fixed
                           else f"{num(x.value, '.5g')} ± {num(x.std, '.2g')}")
            else:
                row.append("—")
        rows.append(row + [e(unit.get(name, ""))])
    rows.append(["residual RMS"] + ([""] if truth else []) + [
        num(f.residual_rms) if isinstance(f, FitResult) else "—"
        for f in (final.fits[m] for m in methods)] + [""])
    notes = []
    for m in methods:
        f = final.fits[m]
        notes += [f"{m}: failed: {f}"] if isinstance(f, str) else [
            f"{m}: warning: {w}" for w in f.warnings]
    return "\n".join([table(["parameter"] + (["truth"] if truth else []) + methods + ["unit"],
                            rows), *(f'<p class="meta">{e(n)}</p>' for n in notes)])


def _gyros(finals: Sequence[GyroFinals], truths: Mapping[str, Mapping[str, float]]) -> str:
    return "\n".join(
        f"<h2>Gyro {e(f.gyro)}</h2><p>Model <code>{e(','.join(f.model.names))}</code>; "
        f"{f.bins} bins, {f.gaps} gaps, {f.observed} observed.</p>\n"
        + result_table(f, truths.get(f.gyro)) for f in finals)


def _counts(stats: Mapping[str, Any]) -> str:
    dec, b = stats.get("decoder", {}), stats.get("binner", {})
    rows = [[e(k), str(dec.get(k, 0))] for k in ("received", "decoded", "ignored",
                                                 "rejected_total", "bus_errors",
                                                 "counter_jumps")]
    rows += [[f"rejected: {e(k)}", str(v)] for k, v in dec.get("rejected", {}).items() if v]
    rows += [[f"bins: {e(k)}", str(b.get(k, 0))] for k in ("bins", "gaps", "late", "jumps")]
    return table(["frames and bins", "count"], rows)


def run_summary(view: RunSummary) -> str:
    o = view.outcome
    paths = table(["file", "path"], [
        [label, f"<code>{e(p)}</code>" if p.exists() else "not written"]
        for label, p in (("run folder", o.run_dir), ("result", o.result_json),
                         ("report", o.report))] + [
        ["error", e(err)] for err in o.stats.get("unwritten", [])], left=2)
    name = o.run_dir.name
    return page(f"gyrostand run: {name}", fill(
        "run.html", session=e(name), meta=f"Stopped: {e(o.stop_reason)} (state "
        f"{e(o.state)}).", counts=_counts(o.stats), gyros=_gyros(o.finals, view.truths),
        paths=paths))


def run_report(view: RunFinals) -> str:
    return page(f"gyrostand run report: {view.session}", fill(
        "run.html", session=e(view.session), meta=f"Source: {e(view.source)}.",
        counts=_counts(view.stats), gyros=_gyros(view.finals, view.truths), paths=""))


def _joint(title: str, text: str) -> str:
    """Several runs of one gyro: the text tables on a page."""
    return page(title, f"<pre>{e(text)}</pre>")


KINDS: dict[type, Callable[[Any], str]] = {
    FitResult: fit_result,
    JointFit: lambda j: _joint(f"gyrostand identify: ml, {len(j.runs)} runs",
                               _text.joint_fit(j)),
    JointDiagnosis: lambda d: _joint(f"gyrostand diagnose: {len(d.fit.runs)} runs",
                                     _text.joint_diagnosis(d)),
    DiagnosisView: diagnosis,
    FitStepView: fit_step,
    AllanView: allan,
    RunSummary: run_summary,
    RunFinals: run_report,
    ReportPage: report_page,
}

RENDERER = ByKind("html", KINDS)
