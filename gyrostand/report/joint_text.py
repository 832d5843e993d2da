"""Plain text of several runs of one gyro: the joint fit and the joint diagnosis
(byte for byte what the commands printed before, ``tests/render/golden``)."""

from __future__ import annotations

from ..core.diagnose.joint import JointDiagnosis
from ..core.diagnose.repeats import repeats_table
from ..core.ml.joint import JointFit
from ..core.summary import unit_text
from .cells import estimate, law, tests_used

__all__ = ["joint_diagnosis", "joint_fit"]


def joint_fit(j: JointFit, drift_unit: str = "y") -> str:
    """A joint fit of several runs: the shared parameters, each run's own ones and its
    residual check, and the turn-on bias repeatability."""
    lines = [f"method ml (joint, {len(j.runs)} runs)   model {','.join(j.model.names)}   "
             f"samples {j.n_observed}", ""]
    lines.append("shared parameters")
    for k, e in j.shared.items():
        lines.append(f"  {k:<16} {estimate(e.value, e.std, e.unit, e.fixed, drift_unit)}")
    lines.append("")
    own = [k for k in j.parameters if "@" in k]
    names = list(dict.fromkeys(k.split("@", 1)[0] for k in own))
    lines.append(f"{'run':>4} {'LB p':>8} {'NIS':>6}  " + "  ".join(f"{n:>26}" for n in names)
                 + "  data")
    for i, r in enumerate(j.runs):
        chk = r.info.get("residual_check", {})
        vals = "  ".join(f"{j.parameters[f'{n}@{i + 1}'].value:>13.6g} ± "
                         f"{j.parameters[f'{n}@{i + 1}'].std:<10.3g}" for n in names)
        lines.append(f"{i + 1:>4} {chk.get('ljung_box_p', float('nan')):>8.3g} "
                     f"{chk.get('nis_mean', float('nan')):>6.3f}  {vals}  {r.source}")
    rep = j.repeatability
    if rep is not None:
        lo, hi = rep.interval
        u = unit_text(rep.unit, drift_unit)
        lines += ["", f"turn-on repeatability of {rep.parameter}: spread {rep.spread:.4g} {u} "
                  f"({rep.level:.0%} interval {lo:.4g} .. {hi:.4g}), mean {rep.mean:.6g} ± "
                  f"{rep.mean_std:.3g}; equal biases: p = {rep.p:.2g}"]
    lines += ["", f"log-likelihood {j.loglik:.6f} (sum over the runs)",
              f"residual RMS   {j.residual_rms:.6g} {drift_unit}"]
    lines += [f"warning: {w}" for w in j.warnings]
    return "\n".join(lines)


def joint_diagnosis(d: JointDiagnosis) -> str:
    """``diagnose`` of several runs: the verdict, the joint fit, the ranked candidates."""
    lines = [f"model    {','.join(d.fit.model.names)}   ({len(d.fit.runs)} runs, joint)",
             f"verdict  {'ADEQUATE' if d.adequate else 'NOT ADEQUATE'}"]
    lines += [f"         - {r}" for r in d.reasons]
    lines += ["", joint_fit(d.fit, d.unit), "", *repeats_table(d.repeats),
              "missing effects (each refitted on every run jointly; LR = joint LR)",
              f"  {'term':<12} {'LR':>9} {'df':>3} {'p':>9} {'ΔBIC':>9}  note"]
    for c in d.candidates:
        lines.append(f"  {c.term:<12} {c.lr_stat:9.2f} {c.df:3d} {c.p_value:9.2g} "
                     f"{c.delta_bic:9.1f}  {c.note}")
    if d.candidates:
        lines.append(f"  p from: {tests_used(d.candidates)}")
    for x in d.redundant:
        lines.append(f"redundant: {x['term']} no longer earns its place on the runs together "
                     f"(LR {x['lr_stat']:.2f} on {x['df']} df{law(x['test'])}, p = "
                     f"{x['p_value']:.2g}): fit the runs again with --remove {x['term']}")
    return "\n".join(lines)
