"""``gyrostand allan RUN|CSV [--gyro G] [--model TERMS] [--unit U] [--json]``: the Allan
deviation of a gyro's drift and its IEEE Std 952 figures (angle random walk, bias
instability with its τ, rate random walk, rate ramp) with confidence intervals, for the
raw drift and for the residual after the thermal model (fitted by ML)."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core.names import VOCABULARY

if TYPE_CHECKING:
    from ..core.allan import AllanTable
    from ..workbench import Subject

log = logging.getLogger(__name__)

#: conventional units of the figures for a drift in deg/h or deg/s: (unit, factor)
CONVENTIONAL = {
    "deg/h": {"angle_random_walk": ("deg/√h", 1 / 60), "rate_random_walk": ("deg/h/√h", 60.0)},
    "deg/s": {"angle_random_walk": ("deg/√h", 60.0),
              "rate_random_walk": ("deg/h/√h", 3600.0 * 60.0)},
}
ORDER = ("angle_random_walk", "bias_instability", "rate_random_walk", "rate_ramp")
TITLES = {"angle_random_walk": "angle random walk", "bias_instability": "bias instability",
          "rate_random_walk": "rate random walk", "rate_ramp": "rate ramp"}


def add_parser(sub: Any) -> None:
    p = sub.add_parser("allan", help="Allan-variance table (IEEE Std 952: ARW, bias "
                                     "instability, RRW) of the raw drift and the residual",
                       description=__doc__)
    p.add_argument("run", help="a run folder, or a CSV with columns t, drift, temp")
    p.add_argument("--gyro", default=None, help="which gyro of a multi-gyro run")
    p.add_argument("--model", default=None,
                   help="thermal model of the residual (comma-separated terms of: "
                        f"{', '.join(VOCABULARY)}); default the run's current model")
    p.add_argument("--unit", default=None,
                   help="the drift's unit (default: the DBC signal's unit from the run's "
                        "session file, else 'y'); deg/h and deg/s add deg/√h, deg/h/√h")
    p.add_argument("--level", type=float, default=0.95, help="confidence level (0.95)")
    p.add_argument("--json", action="store_true", help="print the tables as JSON")
    p.set_defaults(func=run)


def _drift_unit(subject: Subject) -> str:
    """The drift signal's unit from the run's session file, when it can be read."""
    if subject.run_dir is None:
        return "y"
    try:
        from ..config import load_config

        info = json.loads((subject.run_dir / "result.json").read_text())
        cfg = load_config(Path(info["config"]))
        return cfg.gyro(subject.gyro).drift.signal.unit or "y"
    except Exception as exc:  # the session file moved, changed, ...: a generic unit
        log.info("drift unit unknown (%s): using 'y'", exc)
        return "y"


def run(args: argparse.Namespace) -> int:
    from ..core.allan import allan_table, thermal_residual
    from ..core.ml import ml
    from ..workbench import open_subject

    subject = open_subject(args.run, gyro=args.gyro, model=args.model)
    unit = args.unit or _drift_unit(subject)
    s = subject.samples
    fit = ml(s, subject.model)
    raw = allan_table(s.drift, s.dt, unit=unit, label="raw drift", level=args.level)
    resid = allan_table(thermal_residual(fit.model, fit.values, s), s.dt, unit=unit,
                        label=f"residual after {','.join(subject.model.names)}",
                        level=args.level)
    if args.json:
        json.dump({"gyro": subject.gyro, "source": s.source, "unit": unit, "dt": s.dt,
                   "model": list(subject.model.names), "level": args.level,
                   "raw": raw.to_dict(), "residual": resid.to_dict()},
                  sys.stdout, indent=2, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(render([raw, resid], subject.gyro, s.dt))
    return 0


def _fmt(table: AllanTable, name: str) -> list[str]:
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


def render(tables: list[AllanTable], gyro: str, dt: float) -> str:
    """The figures of each table side by side, with units and the reading τ."""
    t0 = tables[0]
    out = [f"Allan variance (IEEE Std 952 figures), gyro {gyro}: {t0.n} samples at "
           f"Δt = {dt:g} s, τ {t0.tau[0]:g}..{t0.tau[-1]:g} s, "
           f"{t0.level:.0%} confidence intervals (overlapping ADEV, EDF)", ""]
    width = 46
    out.append(f"{'':<22}" + "".join(f"{t.label:<{width}}" for t in tables))
    for name in ORDER:
        cells = [_fmt(t, name) for t in tables]
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
