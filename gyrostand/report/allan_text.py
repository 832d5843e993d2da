"""The Allan table as text (``gyrostand allan``, the report's Allan block): IEEE Std 952
figures with their intervals, side by side for the raw drift and the residual."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..core.diagnose.allan import AllanTable
    from .views import AllanView

__all__ = ["CONVENTIONAL", "ORDER", "TITLES", "allan_figure", "allan"]


#: conventional units of the figures for a drift in deg/h or deg/s: (unit, factor)
CONVENTIONAL = {
    "deg/h": {"angle_random_walk": ("deg/√h", 1 / 60), "rate_random_walk": ("deg/h/√h", 60.0)},
    "deg/s": {"angle_random_walk": ("deg/√h", 60.0),
              "rate_random_walk": ("deg/h/√h", 3600.0 * 60.0)},
}
ORDER = ("angle_random_walk", "bias_instability", "rate_random_walk", "rate_ramp")
TITLES = {"angle_random_walk": "angle random walk", "bias_instability": "bias instability",
          "rate_random_walk": "rate random walk", "rate_ramp": "rate ramp"}


def allan_figure(table: AllanTable, name: str) -> list[str]:
    """One figure of a table: value [lo, hi] unit at its τ, and in conventional units."""
    f = table.figures[name]
    if f.value == 0.0:
        return ["not seen (its line fits as 0)"]
    where = f"τ = {f.tau_read:g} s" if f.tau_read is not None else ""
    lines = [f"{f.value:.4g} [{f.lo:.4g}, {f.hi:.4g}] {f.unit}" + (f", {where}" if where else "")]
    conv = CONVENTIONAL.get(table.unit, {}).get(name)
    if conv is not None:
        u, k = conv
        lines.append(f"= {f.value * k:.4g} [{f.lo * k:.4g}, {f.hi * k:.4g}] {u}")
    return lines


def allan(view: AllanView) -> str:
    """The figures of each table side by side, with units and the reading τ."""
    tables, gyro, dt = view.tables, view.gyro, view.dt
    t0 = tables[0]
    out = [f"Allan variance (IEEE Std 952 figures), gyro {gyro}: {t0.n} samples at "
           f"Δt = {dt:g} s, τ {t0.tau[0]:g}..{t0.tau[-1]:g} s, "
           f"{t0.level:.0%} confidence intervals (overlapping ADEV, EDF)", ""]
    cells_of = {name: [allan_figure(t, name) for t in tables] for name in ORDER}
    # a column as wide as its longest cell and 2 spaces (46 at least): cells never touch
    width = max([46] + [len(x) + 2 for c in cells_of.values() for cell in c for x in cell])
    out.append(f"{'':<22}" + "".join(f"{t.label:<{width}}" for t in tables))
    for name in ORDER:
        cells = cells_of[name]
        sym = t0.figures[name].symbol
        for row in range(max(len(c) for c in cells)):
            head = f"{sym}  {TITLES[name]}" if row == 0 else ""
            out.append(f"{head:<22}" + "".join(
                f"{(c[row] if row < len(c) else ''):<{width}}" for c in cells).rstrip())
    out.append("")
    out.append("N: the τ^-1/2 line at τ = 1 s; B: the flat minimum / 0.664 at its τ; K: the "
               "τ^+1/2 line at τ = 3 s;")
    out.append("R: the τ^+1 line at τ = √2 s (a trend). Lines fitted jointly to σ²(τ); "
               "intervals: χ² with the EDF")
    out.append("of the τ where the term dominates (B: its minimum).")
    for t in tables:
        for w in t.warnings:
            out.append(f"warning ({t.label}): {w}")
    return "\n".join(out)
