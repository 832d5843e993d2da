"""``gyrostand design ... --separate A B``: the chamber program that best tells the
look-alike terms A and B apart (:mod:`gyrostand.core.separation`), its files (those of
``design``), the expected likelihood ratio on it beside the reference's, and ``--verify``."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from .design import limits_of, program_document, program_lines, write_files


def run_separate(args: argparse.Namespace, given: dict[str, float]) -> int:
    import numpy as np

    from .. import progress
    from ..core.design import case_temperature, standard_cycle
    from ..core.model import Model
    from ..core.separation import Rivals, rival_models, rivals, separate, verify
    from ..errors import ModelError

    a, b = args.separate
    reference_record = None
    if args.run is not None:
        from ..core.ml import ml
        from ..workbench import open_subject

        subject = open_subject(args.run, gyro=args.gyro, model=args.model)
        ma, mb = rival_models(subject.model, a, b)
        fits = {}
        for m in (ma, mb):
            with progress.stage("design", f"fit of the run with {m}"):
                fits[m] = {**ml(subject.samples, m).values,
                           **{k: v for k, v in given.items() if k in m.param_names}}
        riv = Rivals(a, b, ma, mb, fits[ma], fits[mb])
        t = np.asarray(subject.samples.t - subject.samples.t[0], dtype=float)
        reference_record = (t, np.asarray(subject.samples.temp, dtype=float))
        limits = limits_of(args, args.hours or float(t[-1]) / 3600.0)
    else:
        if args.model is None:
            raise ModelError("design --separate: give a run (its model and fit) or --model "
                             "with --param")
        limits = limits_of(args, args.hours or 6.0)
        ref_case = case_temperature(standard_cycle(limits).setpoint(limits.duration), limits)
        with progress.stage("design", "the look-alike's parameters"):
            riv = rivals(Model.parse(args.model), a, b, {"white.sigma": 0.0, **given},
                         limits.grid, ref_case, limits.dt, seed=args.seed)
    with progress.stage("design", f"search: {a} vs {b}", unit="evaluations") as bar:
        # one start (the best of the standard cycle, zigzags, a random program): 86
        # programs, 83 s CPU for 6 h at 40 evaluations
        res = separate(riv, limits, reference_record=reference_record, starts=1,
                       maxfev=args.evaluations, seed=args.seed, progress=bar.update)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    case = case_temperature(res.program.setpoint(limits.duration), limits)
    ref_case = case_temperature(res.reference.setpoint(limits.duration), limits)
    total, ref_total = sum(res.expected.values()), sum(res.reference_expected.values())
    write_files(out, res.program, f"separate {a} {b}", limits, case, ref_case,
                reference_record, res.reference_label,
                f"{a} vs {b}: expected LR {total:.3g} designed vs {ref_total:.3g} "
                f"({res.reference_label})")
    if args.verify > 0:
        records = {"designed": (limits.grid, case),
                   "reference": reference_record or (limits.grid, ref_case)}
        with progress.stage("design", "verify", total=4 * args.verify, unit="runs") as bar:
            res.verify = verify(riv, records, args.verify, seed=args.seed,
                                progress=bar.update)
    doc = document(res, limits)
    (out / "design.json").write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
    if args.json:
        json.dump(doc, sys.stdout, indent=2, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(render(res, limits, out))
    return 0


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _lr(expected: dict[str, float]) -> dict[str, float | None]:
    return {**{k: _finite(v) for k, v in expected.items()},
            "total": _finite(sum(expected.values()))}


def document(res, limits) -> dict[str, Any]:
    r = res.rivals
    return {
        "goal": "separate", "separate": [r.a, r.b],
        "models": {r.a: list(r.model_a.names), r.b: list(r.model_b.names)},
        "params": {r.a: r.params_a, r.b: r.params_b},
        **program_document(res.program, limits),
        "reference": res.reference_label,
        "expected_lr": {"designed": _lr(res.expected), "reference": _lr(res.reference_expected)},
        "gain": _finite(res.gain),
        "evaluations": res.evaluations,
        "longer_run": None if res.longer is None else {"hours": res.longer[0],
                                                       "expected_lr": _lr(res.longer[1])},
        "verify": res.verify,
    }


def render(res, limits, out: Path) -> str:
    r = res.rivals
    lines = program_lines(f"separate {r.a} from {r.b}", res, limits)
    ref = res.reference_label
    lines += ["", "expected likelihood ratio 2 ln(L_right/L_wrong), the wrong model refitted:",
              f"  {'data from':<30}{'designed':>12}{ref:>20}{'ratio':>8}"]
    rows = [(f"{r.a} (fitted by {r.b})", res.expected[r.a], res.reference_expected[r.a]),
            (f"{r.b} (fitted by {r.a})", res.expected[r.b], res.reference_expected[r.b]),
            ("both (sum)", sum(res.expected.values()), sum(res.reference_expected.values()))]
    for label, d, f in rows:
        lines.append(f"  {label:<30}{d:>12.4g}{f:>20.4g}"
                     f"{d / f if f > 0 else math.inf:>8.2f}")
    if res.longer is not None:
        hours, lam = res.longer
        longer = sum(lam.values())
        lines += ["", f"the profile hardly changes how {r.a} and {r.b} look alike (gain "
                      f"{res.gain:.2f}); the duration does: a standard cycle of {hours:g} h "
                      f"gives an expected LR of {longer:.4g} ({r.a}: {lam[r.a]:.4g}, {r.b}: "
                      f"{lam[r.b]:.4g})"]
    if res.verify is not None:
        v = res.verify
        lines += ["", f"verify: {v['runs']} simulated runs from each model on each profile, "
                      "both models fitted by ML (how often the right one wins)"]
        for label in ("designed", "reference"):
            for truth in (r.a, r.b):
                x = v[label][truth]
                if x["mean_lr"] is None:
                    lines.append(f"  {label:<10} data from {truth}: every fit failed")
                    continue
                lines.append(f"  {label:<10} data from {truth:<12} right wins "
                             f"{100 * x['right_wins_lr']:.0f} % by LR, "
                             f"{100 * x['right_wins_bic']:.0f} % by BIC; mean LR "
                             f"{x['mean_lr']:.3g}" + (f" ({x['failed']} fits failed)"
                                                       if x["failed"] else ""))
    lines += ["", f"files: {out}/program.csv (the chamber program), profile.csv, "
                  "simulate.yaml, design.json, design.png"]
    return "\n".join(lines)
