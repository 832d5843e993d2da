"""``gyrostand diagnose RUN``: where the current model fails and which effect is missing."""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING, Any

from .workbench_args import add_subject_args, fmt_estimate, subject_of

if TYPE_CHECKING:
    from ..core.candidates import Report
    from ..core.prederror import ModelError


def add_parser(sub: Any) -> None:
    p = sub.add_parser("diagnose", help="diagnose the current model of a run and rank the "
                                        "missing effects")
    add_subject_args(p)
    p.add_argument("--json", action="store_true", help="print the diagnosis as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..workbench import run_diagnose

    subject = subject_of(args)
    rep = run_diagnose(subject)
    if args.json:
        json.dump(rep.to_dict(), sys.stdout, indent=2, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(render(rep, f"{subject.samples.source} (gyro {subject.gyro})"))
        print(f"\nledger: {subject.ledger_path}")
    return 0


def render(rep: Report, source: str) -> str:
    d = rep.diagnosis
    u = rep.unit
    lines = [f"model    {','.join(rep.model.names)}", f"data     {source}",
             f"verdict  {'ADEQUATE' if rep.adequate else 'NOT ADEQUATE'}"]
    lines += [f"         - {r}" for r in rep.reasons]
    lines += [f"note     {n}" for n in rep.notes]
    if rep.model_error is not None:
        lines.append("")
        lines += render_model_error(rep.model_error)
    lines.append("")
    lines.append("parameters (ML)")
    for k, e in rep.fit.parameters.items():
        lines.append(f"  {k:<16} {fmt_estimate(e.value, e.std, e.unit, e.fixed, u)}")
    lines.append("")
    lines.append(f"residuals: RMS {d.rms:.4g} {u} (smoothed {d.smoothed_rms:.4g}), Ljung–Box "
                 f"p = {d.ljung_box_p:.3g} over {d.lags} lags, normalized innovations "
                 f"{d.nis_mean:.3f} (95 % band {d.nis_band[0]:.3f}–{d.nis_band[1]:.3f})")
    lines.append("")
    lines.append(f"per segment of the temperature profile (innovations, {u})")
    lines.append(f"  {'kind':<8} {'t from':>8} {'t to':>8} {'T from':>7} {'T to':>7} "
                 f"{'mean':>10} {'RMS':>10} {'smoothed':>10}")
    for s in d.segments:
        lines.append(f"  {s['kind']:<8} {s['t_start']:8.0f} {s['t_stop']:8.0f} "
                     f"{s['temp_start']:7.2f} {s['temp_stop']:7.2f} {s['mean']:10.3g} "
                     f"{s['rms']:10.3g} {s['smoothed_mean']:10.3g}")
    lines.append("")
    m = max(len(rep.candidates), 1)
    lines.append(f"candidates, best first (significant: p < {rep.alpha / m:.2g}, "
                 f"Bonferroni over {m})")
    lines.append(f"  {'term':<12} {'LR':>8} {'df':>3} {'p':>9} {'ΔAIC':>8} {'ΔBIC':>8} "
                 f"{'RMS after':>10}  effect")
    for c in rep.candidates:
        eff = "; ".join(f"{k} = {fmt_estimate(e.value, e.std, e.unit, False, u)}"
                        for k, e in c.effect.items())
        star = "*" if c.ranked and c.p_value < rep.alpha / m else " "
        lines.append(f"{star} {c.term:<12} {c.lr_stat:8.2f} {c.df:3d} {c.p_value:9.2g} "
                     f"{c.delta_aic:8.1f} {c.delta_bic:8.1f} {c.rms_after:10.4g}  {eff}")
        if c.note:
            lines.append(f"  {'':<12} ({c.note})")
    for la in rep.look_alikes:
        lines.append("")
        lines.append(f"look-alikes: {' and '.join(la['terms'])} explain the data about "
                     f"equally well here (ΔAIC {la['delta_aic'][0]:.1f} vs "
                     f"{la['delta_aic'][1]:.1f}); to separate them: {la['advice']}")
    if rep.candidates and not rep.adequate and rep.significant:
        best = rep.significant[0]
        lines.append("")
        lines.append(f"next: gyrostand fit RUN --add {best.term}")
    for w in rep.fit.warnings:
        lines.append(f"warning: {w}")
    return "\n".join(lines)


def render_model_error(err: ModelError) -> list[str]:
    """The headline model error and its table: open loop and h-step, per window."""
    h = err.headline()
    u = err.unit

    def f(x: float | None, fmt: str = ".3g") -> str:
        return "—" if x is None else format(x, fmt)

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
    rows = err.entries[(0.0, w)]
    if len(rows) > 1:
        lines.append(f"  open loop per segment ({w:g}-s means, {u}): " + "; ".join(
            f"{err.ranges[i]['kind']} {err.ranges[i]['t_start']:.0f}–"
            f"{err.ranges[i]['t_stop']:.0f} s {f(rows[i]['rms'])}"
            for i in range(1, len(rows)) if rows[i]["rms"] is not None))
    return lines
