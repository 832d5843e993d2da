"""The designed chamber program as ``gyrostand design`` writes and prints it: the chamber
limits of the command line, ``design.json``'s ``limits`` and ``program``, the program's
files (``program.csv``, ``profile.csv``, ``simulate.yaml``, ``design.png``) and its lines
of text; shared by :mod:`.design` and :mod:`.design_separate` (``--separate A B``)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

__all__ = ["program_document", "limits_of", "write_files", "program_lines",
           "available_memory", "BYTES_PER_SAMPLE"]


def program_document(program, limits) -> dict[str, Any]:
    """design.json's ``limits`` and ``program``."""
    return {
        "limits": {"t_min": limits.t_min, "t_max": limits.t_max,
                   "max_rate_degC_per_min": limits.max_rate * 60.0,
                   "min_soak_s": limits.min_soak, "duration_s": limits.duration,
                   "legs": limits.legs, "lag_s": limits.lag, "start": limits.t0},
        "program": [{"target_degC": T, "rate_degC_per_min": r * 60.0, "soak_s": s}
                    for T, r, s in program.legs],
    }


#: memory a design holds per sample of its time grid (bytes): ~190 measured (peak RSS of
#: ``design --hours 6/24/96``, 3 parameters), with a margin for more parameters
BYTES_PER_SAMPLE = 400


#: the hottest chamber the design command plans for (°C)
MAX_CHAMBER_C = 1000.0


def limits_of(args: argparse.Namespace, hours: float):
    """The chamber limits of the command line (°C/min and min converted to SI). Raises
    :class:`~gyrostand.errors.ModelError` when the program's time grid could not fit in the
    memory available (checked before anything is allocated)."""
    from ..core.design.search import ChamberLimits
    from ..errors import ModelError

    for opt, v in (("--t-min", args.t_min), ("--t-max", args.t_max),
                   ("--start", args.start)):
        if v is not None and not -273.15 <= v <= MAX_CHAMBER_C:
            raise ModelError(f"{opt} {v:g}: a chamber temperature is between -273.15 and "
                             f"{MAX_CHAMBER_C:g} °C")
    if not args.t_min < args.t_max:
        raise ModelError(f"--t-min {args.t_min:g} must be below --t-max {args.t_max:g}")
    if args.start is not None and not args.t_min <= args.start <= args.t_max:
        raise ModelError(f"--start {args.start:g} is outside --t-min .. --t-max "
                         f"({args.t_min:g} .. {args.t_max:g} °C)")
    if not 1 <= args.legs <= 1000:
        raise ModelError(f"--legs {args.legs}: expected 1 .. 1000")
    limits = ChamberLimits(args.t_min, args.t_max, args.max_rate / 60.0,
                           args.min_soak * 60.0, hours * 3600.0, legs=args.legs,
                           lag=args.lag * 60.0, start=args.start)
    samples = limits.duration / limits.dt + 1
    need, free = samples * BYTES_PER_SAMPLE, available_memory()
    if free is not None and need > free:
        from ..errors import ModelError

        raise ModelError(f"--hours {hours:g}: a {hours:g}-h program on a {limits.dt:g}-s grid "
                         f"({samples:.3g} samples) needs about {need / 2**30:.3g} GiB of "
                         f"memory, {free / 2**30:.3g} GiB is available: give fewer --hours")
    return limits


def available_memory() -> float | None:
    """Bytes of memory available to a new allocation (Linux ``MemAvailable``, else the
    free physical pages), or None when the system does not say."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def write_files(out: Path, program, goal: str, limits, case, ref_case, reference_record,
                 ref_label: str, title: str) -> None:
    import numpy as np

    rows = program.rows()
    with open(out / "program.csv", "w", encoding="utf-8", newline="") as fh:
        fh.write("time_s,setpoint_degC\n")
        for t, T in rows:
            fh.write(f"{t:.1f},{T:.3f}\n")
    grid = limits.grid
    sp = program.setpoint(limits.duration)(grid)
    with open(out / "profile.csv", "w", encoding="utf-8", newline="") as fh:
        fh.write("t,setpoint_degC,case_degC\n")
        for k in range(grid.size):
            fh.write(f"{grid[k]:g},{sp[k]:.4f},{case[k]:.4f}\n")
    # the simulator's profile: the case temperature's breakpoints (every minute with a lag)
    if limits.lag > 0:
        idx = np.unique(np.concatenate([np.arange(0, grid.size, 60), [grid.size - 1]]))
        pts = [[float(grid[i]), round(float(case[i]), 4)] for i in idx]
    else:
        pts = [[round(t, 1), round(T, 4)] for t, T in rows]
    lines = ["# gyrostand design: paste into a session file's simulate: section to rehearse",
             f"# the designed run ({goal}); the case temperature the model sees.",
             "simulate:", f"  duration: {limits.duration:g}", "  temperature:"]
    lines += [f"    - [{t:g}, {T:g}]" for t, T in pts]
    (out / "simulate.yaml").write_text("\n".join(lines) + "\n", encoding="utf-8")
    _plot(out / "design.png", grid, sp, case, ref_case, reference_record, ref_label, title)


def _plot(path: Path, grid, sp, case, ref_case, reference_record, ref_label, title) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 4))
    h = grid / 3600.0
    ax.plot(h, sp, lw=1.0, color="C0", ls="--", label="designed set-point")
    ax.plot(h, case, lw=1.6, color="C0", label="designed, case")
    if reference_record is not None:
        ax.plot(reference_record[0] / 3600.0, reference_record[1], lw=1.2, color="C1",
                label=ref_label)
    else:
        ax.plot(h, ref_case, lw=1.2, color="C1", label=ref_label)
    ax.set_title(title)
    ax.set_xlabel("time, h")
    ax.set_ylabel("temperature, °C")
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def program_lines(goal: str, res, limits) -> list[str]:
    """The header (goal, evaluations, limits) and the designed program's legs."""
    lines = [f"design ({goal}; {res.evaluations} evaluations), "
             f"{limits.duration / 3600:g} h, {limits.t_min:g}..{limits.t_max:g} °C, "
             f"≤ {limits.max_rate * 60:g} °C/min, soaks ≥ {limits.min_soak / 60:g} min, "
             f"lag {limits.lag / 60:g} min",
             "", f"program (from {res.program.start:.1f} °C):"]
    if res.program is res.reference:
        lines.insert(1, "no program better than the reference was found: it is proposed")
    for j, (T, r, s) in enumerate(res.program.legs, 1):
        lines.append(f"  leg {j}: ramp at {r * 60:.3g} °C/min to {T:.1f} °C, soak "
                     f"{s / 60:.1f} min")
    return lines
