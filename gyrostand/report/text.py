"""Plain-text documents: the tables the commands print and a run folder's ``report.txt``.

Byte for byte what the commands printed before the renderers were one package
(``tests/render/golden``): widths, significant digits and wording are part of the contract
that scripts reading the tables rely on.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from ..core.diagnose.joint import JointDiagnosis
from ..core.ml.joint import JointFit
from ..core.results import FitResult
from ..core.summary import fit_table, shown_warnings, unit_text
from . import ByKind
from .allan_text import allan
from .cells import estimate, law, tests_used
from .joint_text import joint_diagnosis, joint_fit
from .lackfit import level_shift, periodic, reference
from .segments import number, open_loop_by_segment
from .views import FIT_RUN, AllanView, DiagnosisView, FitStepView, ReportPage, RunFinals, RunSummary

if TYPE_CHECKING:
    from ..core.diagnose.prederror import ModelError
    from ..core.diagnose.results import DiagnoseResult
    from .views import GyroFinals

__all__ = ["RENDERER", "fit_result", "diagnosis", "model_error", "fit_step",
           "result_table", "run_summary", "run_report", "estimate", "SAME_SIGMA", "joint_fit",
           "joint_diagnosis"]


# ---- identify ----------------------------------------------------------------------------

def fit_result(r: FitResult) -> str:
    """A readable table with units (``identify``): :meth:`FitResult.summary`'s
    (:func:`gyrostand.core.summary.fit_table`)."""
    return fit_table(r)


# ---- diagnose ----------------------------------------------------------------------------

def diagnosis(rep: DiagnoseResult, source: str, fit_command: str = FIT_RUN,
              adopt_command: str | None = None) -> str:
    """The verdict, model error, parameters, residual statistics, per-segment table and the
    ranked candidates of one diagnosis of the data ``source``; the next step, when a
    candidate is significant, is ``fit_command --add TERM``; when the model is ADEQUATE
    and a run's session file does not hold it yet, ``adopt_command``."""
    d = rep.diagnosis
    u = rep.unit
    lines = [f"model    {','.join(rep.model.names)}", f"data     {source}",
             f"verdict  {'ADEQUATE' if rep.adequate else 'NOT ADEQUATE'}"]
    lines += [f"         - {r}" for r in rep.reasons]
    lines += [f"note     {n}" for n in rep.notes]
    if rep.model_error is not None:
        lines.append("")
        lines += model_error(rep.model_error)
    if rep.reference is not None:
        lines.append("")
        lines += reference(rep.reference, u)
    if rep.level_shift is not None:
        lines += level_shift(rep.level_shift, u)
    if rep.periodic is not None:
        lines += periodic(rep.periodic, u)
    lines.append("")
    lines.append("parameters (ML)")
    for k, e in rep.fit.parameters.items():
        lines.append(f"  {k:<16} {estimate(e.value, e.std, e.unit, e.fixed, u)}")
    lines.append("")
    lines.append(f"residuals: RMS {d.rms:.4g} {u} (smoothed {d.smoothed_rms:.4g}), Ljung–Box "
                 f"p = {d.ljung_box_p:.3g} over {d.lags} lags, normalized innovations "
                 f"{d.nis_mean:.3f} (95 % band {d.nis_band[0]:.3f}–{d.nis_band[1]:.3f})")
    lines.append("")
    lines.append(f"per segment of the temperature profile (innovations, {u}; t from the "
                 "run's start)")
    lines.append(f"  {'kind':<8} {'t from':>8} {'t to':>8} {'T from':>7} {'T to':>7} "
                 f"{'mean':>10} {'RMS':>10} {'smoothed':>10}")
    t0 = d.segments[0]["t_start"] if d.segments else 0.0  # a log's times are epoch s
    for s in d.segments:
        lines.append(f"  {s['kind']:<8} {s['t_start'] - t0:8.0f} {s['t_stop'] - t0:8.0f} "
                     f"{s['temp_start']:7.2f} {s['temp_stop']:7.2f} {s['mean']:10.3g} "
                     f"{s['rms']:10.3g} {s['smoothed_mean']:10.3g}")
    lines.append("")
    m = max(len(rep.candidates), 1)
    lines.append(f"candidates, best first (significant: p < {rep.alpha / m:.2g}, "
                 f"Bonferroni over {m})")
    lines.append(f"  {'term':<12} {'LR':>8} {'df':>3} {'p':>9} {'ΔAIC':>8} {'ΔBIC':>8} "
                 f"{'RMS after':>10}  effect")
    for c in rep.candidates:
        eff = "; ".join(f"{k} = {estimate(e.value, e.std, e.unit, False, u)}"
                        for k, e in c.effect.items())
        star = "*" if c.ranked and c.p_value < rep.alpha / m else " "
        if c.screened:  # no refit: its score (LM) test in place of the LR
            lines.append(f"  {c.term:<12} {'LM ' + format(c.lr_stat, '.2f'):>8} {c.df:3d} "
                         f"{c.p_value:9.2g} {'—':>8} {'—':>8} {'—':>10}")
        else:
            lines.append(f"{star} {c.term:<12} {c.lr_stat:8.2f} {c.df:3d} {c.p_value:9.2g} "
                         f"{c.delta_aic:8.1f} {c.delta_bic:8.1f} {c.rms_after:10.4g}  {eff}")
        if c.note:
            lines.append(f"  {'':<12} ({c.note})")
        if c.traded:
            lines.append(f"  {'':<12} (traded against {', '.join(c.traded)}: its refit "
                         "moved the random part beyond ±3 std)")
    if rep.candidates:
        lines.append(f"  p from: {tests_used(rep.candidates)}")
    for la in rep.look_alikes:
        lines.append("")
        lines.append(f"look-alikes: {' and '.join(la['terms'])} explain the data about "
                     f"equally well here (ΔAIC {la['delta_aic'][0]:.1f} vs "
                     f"{la['delta_aic'][1]:.1f}"
                     + (f"; {la['terms'][1]}: {la['note']}" if "note" in la else "")
                     + "); to separate them: "
                     + (f"design the run that does:\n  {la['command']}" if "command" in la
                        else la["advice"]))
    if rep.candidates and not rep.adequate and rep.significant and not (
            rep.jump or rep.cycling):
        best = rep.significant[0]
        lines.append("")
        lines.append(f"next: {fit_command} --add {best.term}")
        if rep.tie:
            lines.append(f"      ({tie_advice(rep.tie)} {second_run_command(fit_command)})")
    elif rep.outside:
        lines.append("")
        lines.append(f"next: {term_new_command(fit_command)}")
        lines.append("      (writes a plugin term of the "
                     + ("level shift: a step at its instant" if rep.jump
                        else "periodic disturbance: a sine and a cosine at its period"
                        if rep.cycling else "shape the reference shows")
                     + "; review it, pip install it, then fit --add it: README, plugins)")
    elif rep.adequate and rep.redundant:
        lines.append("")
        for x in rep.redundant:
            lines.append(f"redundant: {x['term']} no longer earns its place (LR "
                         f"{x['lr_stat']:.2f} on {x['df']} df{law(x['test'])}, p = "
                         f"{x['p_value']:.2g}): the model is adequate without it")
        lines.append(f"next: {fit_command} --remove {rep.redundant[0]['term']}")
    elif rep.adequate and adopt_command:
        lines.append("")
        lines.append(f"next: {adopt_command}")
        lines.append("      (writes this model into the run's session file; the daemon uses it "
                     "from its next run)")
    for w in shown_warnings(rep.fit.warnings):
        lines.append(f"warning: {w}")
    return "\n".join(lines)


def model_error(err: ModelError) -> list[str]:
    """The headline model error and its table: open loop and h-step, per window."""
    h = err.headline()
    u = err.unit
    f = number
    lines = [f"model error (open loop: measured − model driven by the temperature alone, "
             f"{h['window_s']:g}-s means over the run): RMS {f(h['rms'])} {u}, floor "
             f"{f(h['floor'])} {u} (what the model's own noise leaves), unexplained "
             f"{f(h['unexplained'])} {u}, fit {f(h['fit_percent'], '.1f')} %"
             + ("" if h["at_floor"] else "  << above its floor")]
    lines.append(f"  {'prediction':<12} {'window':>7} {'RMS':>10} {'max':>10} {'floor':>10} "
                 f"{'unexpl.':>10} {'fit %':>7}")
    for hs in (0.0, *err.horizons_s):
        name = "open loop" if hs == 0 else f"{hs:g}-s ahead"
        for w in err.windows_s:
            r = err.entries[(hs, w)][0]
            lines.append(f"  {name:<12} {w:6g}s {f(r['rms']):>10} {f(r['max']):>10} "
                         f"{f(r['floor']):>10} {f(r['unexplained']):>10} "
                         f"{f(r['fit_percent'], '.1f'):>7}")
    w = err.windows_s[0]
    return lines + open_loop_by_segment(err.ranges, err.entries[(0.0, w)], w, u)


def _with_ledger(body: str, view: DiagnosisView | FitStepView) -> str:
    return body + (f"\n\nledger: {view.ledger}" if view.ledger is not None else "")


# ---- fit ---------------------------------------------------------------------------------

def term_new_command(fit_command: str) -> str:
    """``term new --from DATA …`` for the data of ``fit_command`` (``… fit DATA …``)."""
    head, sep, tail = fit_command.partition(" fit ")
    return f"{head} term new --from {tail}" if sep else "gyrostand term new --from RUN"


def tie_advice(tie: tuple[str, str]) -> str:
    """What a tie's line says before its command (text and HTML alike)."""
    return (f"{' and '.join(tie)} tie on this record: a second switch-on of this gyro "
            "tells them apart — record one with the same profile, then:")


def second_run_command(fit_command: str) -> str:
    """``diagnose DATA SECOND_RUN [options]``, the joint diagnosis of the data of
    ``fit_command`` (its options kept: the model, a log's session file, the gyro) and a
    second run still to be recorded (``SECOND_RUN``: its folder)."""
    head, sep, tail = fit_command.partition(" fit ")
    data = tail.split(" --")[0]
    return (f"{head} diagnose {data} SECOND_RUN{tail[len(data):]}" if sep
            else "gyrostand diagnose RUN SECOND_RUN")


def fit_step(view: FitStepView) -> str:
    """Before and after of one model change side by side, the likelihood-ratio test."""
    step = view.step
    b, a = step.before, step.after
    u = step.after_error.unit if step.after_error is not None else "y"
    lines = [f"{'':<18} {'before':>30}   {'after':>30}",
             f"{'model':<18} {','.join(b.model.names):>30}   {','.join(a.model.names):>30}"]
    for k in dict.fromkeys(list(b.parameters) + list(a.parameters)):
        pb, pa = b.parameters.get(k), a.parameters.get(k)
        sb = estimate(pb.value, pb.std, pb.unit, pb.fixed, u) if pb else "—"
        sa = estimate(pa.value, pa.std, pa.unit, pa.fixed, u) if pa else "—"
        lines.append(f"{k:<18} {sb:>30}   {sa:>30}")
    lines.append(f"{'log-likelihood':<18} {b.loglik:>30.3f}   {a.loglik:>30.3f}")
    lines.append(f"{'residual RMS':<18} {b.residual_rms:>30.5g}   {a.residual_rms:>30.5g}")
    eb, ea = step.before_error, step.after_error
    if eb is not None and ea is not None:
        u = ea.unit
        lines.append(f"{'model error':<18} {eb.rms:>30.4g}   {ea.rms:>30.4g}")
        lines.append(f"{'  its floor':<18} {eb.floor:>30.4g}   {ea.floor:>30.4g}")
        hb, ha = eb.headline(), ea.headline()
        lines.append(f"{'  unexplained':<18} {hb['unexplained'] or 0.0:>30.4g}   "
                     f"{ha['unexplained'] or 0.0:>30.4g}")
        lines.append(f"(model error: open-loop RMS of {hb['window_s']:g}-s means over the "
                     f"run, {u}; floor: what the model's own noise leaves)")
    change = (a.residual_rms / b.residual_rms - 1) * 100 if b.residual_rms else 0.0
    lines.append("")
    if step.df == 0:
        lines.append(f"same number of parameters; 2 Δln L = {step.lr_stat:.2f}")
    elif step.bigger_is_after:
        lines.append(f"LR = {step.lr_stat:.2f} on {abs(step.df)} df{law(step.test)}, "
                     f"p = {step.p_value:.3g} (adding {', '.join(step.added)} "
                     f"{'improves' if step.p_value < 0.05 else 'does not significantly improve'}"
                     f" the fit); residual RMS {change:+.2f} %")
    else:
        worse = step.p_value < 0.05
        lines.append(f"LR = {step.lr_stat:.2f} on {abs(step.df)} df{law(step.test)}, "
                     f"p = {step.p_value:.3g}: "
                     + ("removing it makes the fit significantly worse"
                        if worse else "removing it costs no significant fit")
                     + f"; residual RMS {change:+.2f} %")
    if eb is not None and ea is not None and eb.rms > 0:
        lines.append(f"model error {ea.rms / eb.rms * 100 - 100:+.1f} % "
                     f"({eb.rms:.4g} → {ea.rms:.4g} {ea.unit})")
    for w in shown_warnings(a.warnings):
        lines.append(f"warning: {w}")
    if view.next:
        lines += ["", *view.next]
    return "\n".join(lines)


# ---- the end of a run --------------------------------------------------------------------

#: the batch refit's column is left out of the table when it is the online value within
#: this many stds for every parameter (said in a line below the table)
SAME_SIGMA = 0.05


def result_table(final: GyroFinals, truth: Mapping[str, float] | None = None) -> str:
    """One gyro's parameters: a column per method (value ± std), truth first if known.

    ``lkf`` is the online LKF at stop (what the last CAN round sent), ``lkf_batch`` the
    batch refit: shown only where it differs from ``lkf`` by more than ``SAME_SIGMA``."""
    methods = list(final.fits)
    same = same_fit(final.fits.get("lkf"), final.fits.get("lkf_batch"))
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


def same_fit(a: FitResult | str | None, b: FitResult | str | None) -> bool:
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


def run_summary(view: RunSummary) -> str:
    """The final table of every gyro, the counts, and the paths (``run``, ``replay``)."""
    outcome = view.outcome
    dec = outcome.stats.get("decoder", {})
    lines = [f"stopped: {outcome.stop_reason} (state {outcome.state}); frames "
             f"{dec.get('received', 0)} received, {dec.get('decoded', 0)} decoded, "
             f"{dec.get('rejected_total', 0)} rejected"]
    for f in outcome.finals:
        lines.append(f"\ngyro {f.gyro}: {f.bins} bins, {f.gaps} gaps")
        lines.append(result_table(f, view.truths.get(f.gyro)))
    lines.append(f"\nrun folder: {outcome.run_dir}")
    for label, path in (("result:    ", outcome.result_json), ("report:    ", outcome.report)):
        lines.append(f"{label} {path}" if path.is_file() and (
            path != outcome.result_json or getattr(outcome, "result_written", True))
            else f"{label} not written")
    for err in outcome.stats.get("unwritten", []):
        lines.append(f"error: {err}")
    return "\n".join(lines)


def run_report(view: RunFinals) -> str:
    """``report.txt``: the counts of the run and the final table per gyro."""
    stats = view.stats
    dec = stats.get("decoder", {})
    lines = [f"gyrostand run report: session {view.session} ({view.source})", "",
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
    for f in view.finals:
        lines += ["", f"gyro {f.gyro}: model {','.join(f.model.names)}; {f.bins} bins, "
                      f"{f.gaps} gaps, {f.observed} observed", ""]
        lines.append(result_table(f, view.truths.get(f.gyro)))
    lines += ["", "(y = the drift's unit, e.g. deg/h; ± one standard deviation)"]
    return "\n".join(lines)


def _report_page(page: ReportPage) -> str:
    """The report's diagnosis as text (``report --format text``), its Allan tables after."""
    s = page.subject
    return diagnosis(page.report, f"{s.samples.source} (gyro {s.gyro})", page.fit_command,
                     page.adopt_command) + _allan_block(page.allan)


def _allan_block(view: AllanView | None) -> str:
    """A diagnosis's Allan tables (:func:`allan`) after a blank line, when computed."""
    return f"\n\n{allan(view)}" if view is not None else ""


KINDS: dict[type, Callable[[Any], str]] = {
    FitResult: fit_result,
    JointFit: joint_fit,
    JointDiagnosis: joint_diagnosis,
    DiagnosisView: lambda v: _with_ledger(diagnosis(v.report, v.source, v.fit_command,
                                                    v.adopt_command)
                                          + _allan_block(v.allan), v),
    FitStepView: lambda v: _with_ledger(fit_step(v), v),
    AllanView: allan,
    RunSummary: run_summary,
    RunFinals: run_report,
    ReportPage: _report_page,
}


class TextRenderer(ByKind):
    """Text: each kind's table, ending in a newline."""

    def render(self, obj: Any) -> str:
        return super().render(obj) + "\n"


RENDERER = TextRenderer("text", KINDS)
