"""``gyrostand fit RUN --add TERM [--add ...] [--remove TERM]``: refit, before/after."""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING, Any

from ..core.names import VOCABULARY
from .workbench_args import add_subject_args, fmt_estimate, subject_of

if TYPE_CHECKING:
    from ..workbench import FitStep


def add_parser(sub: Any) -> None:
    p = sub.add_parser("fit", help="add or remove model terms, refit, show before/after")
    add_subject_args(p)
    terms = ", ".join(VOCABULARY)
    p.add_argument("--add", action="append", default=[], metavar="TERM",
                   help=f"add a model term (repeatable); one of: {terms}")
    p.add_argument("--remove", action="append", default=[], metavar="TERM",
                   help="remove a term of the current model (repeatable; 'white' stays)")
    p.add_argument("--json", action="store_true", help="print the step as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..workbench import run_fit

    subject = subject_of(args)
    step = run_fit(subject, args.add, args.remove)
    if args.json:
        json.dump(step.to_dict(), sys.stdout, indent=2, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(render(step))
        print(f"\nledger: {subject.ledger_path}")
    return 0


def render(step: FitStep) -> str:
    b, a = step.before, step.after
    u = step.after_error.unit if step.after_error is not None else "y"
    lines = [f"{'':<18} {'before':>30}   {'after':>30}",
             f"{'model':<18} {','.join(b.model.names):>30}   {','.join(a.model.names):>30}"]
    for k in dict.fromkeys(list(b.parameters) + list(a.parameters)):
        eb, ea = b.parameters.get(k), a.parameters.get(k)
        sb = fmt_estimate(eb.value, eb.std, eb.unit, eb.fixed, u) if eb else "—"
        sa = fmt_estimate(ea.value, ea.std, ea.unit, ea.fixed, u) if ea else "—"
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
        lines.append(f"LR = {step.lr_stat:.2f} on {abs(step.df)} df, p = {step.p_value:.3g}"
                     f" (adding {', '.join(step.added)} "
                     f"{'improves' if step.p_value < 0.05 else 'does not significantly improve'}"
                     f" the fit); residual RMS {change:+.2f} %")
    else:
        worse = step.p_value < 0.05
        lines.append(f"LR = {step.lr_stat:.2f} on {abs(step.df)} df, p = {step.p_value:.3g}: "
                     + ("removing it makes the fit significantly worse"
                        if worse else "removing it costs no significant fit")
                     + f"; residual RMS {change:+.2f} %")
    if eb is not None and ea is not None and eb.rms > 0:
        lines.append(f"model error {ea.rms / eb.rms * 100 - 100:+.1f} % "
                     f"({eb.rms:.4g} → {ea.rms:.4g} {ea.unit})")
    for w in a.warnings:
        lines.append(f"warning: {w}")
    return "\n".join(lines)
