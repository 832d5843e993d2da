"""The saturated reference in text: the lack-of-fit test and, where it is significant, the
shape that is missing (:mod:`gyrostand.core.diagnose.reference`); the level shift and the
periodic line judged against it (:mod:`gyrostand.core.diagnose.shift`,
:mod:`gyrostand.core.diagnose.periodic`)."""

from __future__ import annotations

from ..core.diagnose.periodic import Periodic
from ..core.diagnose.reference import REPORT_ALPHA, Reference
from ..core.diagnose.shift import LevelShift
from ..core.diagnose.verdict import lack_of_fit_text

__all__ = ["level_shift", "periodic", "reference"]


def reference(ref: Reference, unit: str) -> list[str]:
    """The lack-of-fit test against the saturated reference, and where it is significant
    the shape that is missing: each group's partial effect, with its band."""
    lines = [f"reference: {lack_of_fit_text(ref)} — "
             + ("SIGNIFICANT" if ref.significant else "not significant")
             + f" (verdict's level {ref.alpha:g})"]
    if ref.traded:
        lines.append(f"  the misfit moved the random part: {', '.join(ref.traded)} beyond "
                     "±3 std of the reference's (the floor is the reference's)")
    if ref.p_value >= REPORT_ALPHA:
        return lines
    for q in ref.partial:
        flag = "missing" if q.significant else "no clear effect"
        lines.append(f"  partial effect of {q.variable} ({q.group}; Wald {q.wald:.1f} on "
                     f"{q.df} df, p {q.p_value:.2g}): {flag}")
        if not q.significant:
            continue
        step = max(1, (len(q.x) - 1) // 8)
        for i in range(0, len(q.x), step):
            lines.append(f"    {q.variable} = {q.x[i]:10.4g} {q.unit:<6} "
                         f"{q.effect[i]:+10.4g} ± {2 * q.std[i]:.3g} {unit}")
    return lines


def level_shift(shift: LevelShift, unit: str) -> list[str]:
    """The largest level shift of the drift against the reference, and whether it is one."""
    if shift.significant:
        return [f"level shift: {shift.text(unit)} — SIGNIFICANT (level {shift.alpha:g}): a "
                "bias jump no smooth shape holds"]
    return [f"level shift: none (the largest {shift.text(unit)}; level {shift.alpha:g})"]


def periodic(cycle: Periodic, unit: str) -> list[str]:
    """The innovations' strongest periodic line against the reference, and whether it is
    one."""
    if cycle.significant:
        return [f"periodic: {cycle.text(unit)} — SIGNIFICANT (level {cycle.alpha:g}): a "
                "disturbance at that period"]
    return [f"periodic: none (the strongest line {cycle.text(unit)}; level {cycle.alpha:g})"]
