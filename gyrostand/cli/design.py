"""``gyrostand design [RUN|CSV] --model TERMS --param NAME=VALUE ... [limits] [--goal G |
--separate A B] [--out DIR] [--verify N]``: the chamber program that best determines the
parameters in doubt, within the chamber's limits, with its predicted std beside the
reference profile's (the run's own record, or a standard cycle of the same duration); with
``--separate A B`` the program that best tells the look-alike terms A and B apart (the
expected likelihood ratio between the model with A and the model with B)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from ..plugins import available_terms
from .common import number, whole
from .design_program import limits_of, program_document, program_lines, write_files


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "design", help="design the next chamber run: the temperature program that best "
                       "determines the parameters in doubt",
        description=__doc__)
    p.add_argument("run", nargs="?", default=None,
                   help="a run folder or CSV: its current model fitted by ML gives the "
                        "parameters, and its own record is the reference (optional)")
    p.add_argument("--gyro", default=None, help="which gyro of a multi-gyro run")
    p.add_argument("--model", default=None,
                   help=f"comma-separated terms of: {', '.join(available_terms())} (default: the "
                        "run's current model)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="a parameter's current value (e.g. temp_rate.k=5); every parameter "
                        "of --model without a run; overrides the run's fit; with --separate, "
                        "bias.spread=SIGMA_B: the turn-on-to-turn-on spread of the bias")
    p.add_argument("--t-min", type=float, default=0.0, help="chamber minimum, °C (0)")
    p.add_argument("--t-max", type=float, default=50.0, help="chamber maximum, °C (50)")
    p.add_argument("--max-rate", type=number(positive=True), default=1.0,
                   help="maximum ramp rate, °C/min (1)")
    p.add_argument("--min-soak", type=number(nonnegative=True), default=10.0,
                   help="minimum soak at each leg's target, min (10)")
    p.add_argument("--hours", type=number(positive=True), default=None,
                   help="run duration, h (default: the run's, else 6)")
    p.add_argument("--legs", type=int, default=6, help="ramp+soak legs (6)")
    p.add_argument("--lag", type=number(nonnegative=True), default=0.0,
                   help="chamber-to-case time constant, min (0: the case follows the "
                        "set-point)")
    p.add_argument("--start", type=float, default=None,
                   help="start temperature, °C (default: mid-range)")
    p.add_argument("--goal", default="d-optimal",
                   help="d-optimal (default), worst (the worst-determined, relative), or "
                        "std:PARAM")
    p.add_argument("--separate", nargs=2, default=None, metavar=("A", "B"),
                   help="design the run that tells the look-alike terms A and B apart "
                        "(e.g. temp_lag markov2): the model with A vs the model with B")
    p.add_argument("--off-hours", type=number(positive=True), default=24.0,
                   help="--separate of time-only effects (trend warmup) with a turn-on bias "
                        "spread (--param bias.spread=SIGMA_B): the longest off period between "
                        "switch-ons of the power-cycle protocol, h (24; chamber soak with the "
                        "gyro unpowered, not counted in --hours)")
    p.add_argument("--spread-from", default=None, metavar="JSON",
                   help="the turn-on bias spread from `gyrostand identify RUN RUN ... --format "
                        "json` (its repeatability), instead of --param bias.spread=")
    p.add_argument("--doubt", default=None,
                   help="the parameters in doubt, comma-separated (default: every one)")
    p.add_argument("--evaluations", type=whole(1), default=120,
                   help="likelihood-information evaluations per search start (120)")
    p.add_argument("--verify", type=int, default=0, metavar="N",
                   help="simulate N runs of the designed and of the reference profile, fit "
                        "them by ML, print realized std beside predicted (--separate: N runs "
                        "from each model, both fitted, how often the right one wins)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", default="design", metavar="DIR",
                   help="folder for program.csv, profile.csv, simulate.yaml, design.json, "
                        "design.png (default ./design)")
    p.add_argument("--json", action="store_true", help="print design.json")
    p.set_defaults(func=run)


#: processes fitting --verify's runs (an ML fit is mostly Python between compiled
#: Kalman passes: two processes use two CPUs, two threads do not)
VERIFY_WORKERS = 2


def _params(args: argparse.Namespace) -> dict[str, float]:
    from ..errors import ModelError

    out: dict[str, float] = {}
    for item in args.param:
        name, sep, value = item.partition("=")
        try:
            if not sep:
                raise ValueError
            out[name.strip()] = float(value)
        except ValueError:
            raise ModelError(f"--param {item!r}: expected NAME=VALUE, e.g. "
                             "temp_rate.k=5") from None
    return out


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from .. import progress
    from ..core.design.search import case_temperature, design, search_budget
    from ..core.model import Model
    from ..errors import ModelError

    given = _params(args)
    if args.separate is not None:
        from .design_separate import run_separate

        return run_separate(args, given)
    reference_record = None
    drift_unit = "y"  # the drift's unit: the run's (its DBC's), else the model's y
    if args.run is not None:
        from ..core.ml.fit import ml
        from ..workbench import open_subject

        subject = open_subject(args.run, gyro=args.gyro, model=args.model)
        model = subject.model
        drift_unit = subject.unit
        with progress.stage("design", "fit of the run"):
            fit = ml(subject.samples, model)
        params = {**fit.values, **given}
        reference_record = (subject.samples.t - subject.samples.t[0], subject.samples.temp)
        hours = args.hours or float(reference_record[0][-1]) / 3600.0
    else:
        if args.model is None:
            raise ModelError("design: give a run (its model and fit) or --model with --param")
        model = Model.parse(args.model)
        params = {"white.sigma": 0.0, **given}
        hours = args.hours or 6.0
    model.check_params({**model.defaults, **params})
    limits = limits_of(args, hours)
    doubt = [n.strip() for n in args.doubt.split(",")] if args.doubt else None
    total = search_budget(limits, maxfev=args.evaluations)
    with progress.stage("design", "search", total=total, unit="evaluations") as bar:
        res = design(model, params, limits, goal=args.goal, doubt=doubt,
                     maxfev=args.evaluations, seed=args.seed, progress=bar.update)
    ref_label = "standard cycle"
    if reference_record is not None:
        from ..core.design.fisher import information

        t, temp = reference_record
        info, names = information(model, params, t, temp, dt=float(np.median(np.diff(t))),
                                  n_mc=40, seed=args.seed + 1)
        cov = np.linalg.inv(info)
        res.reference_predicted = {n: float(np.sqrt(cov[i, i])) for i, n in enumerate(names)}
        ref_label = "this run's record"
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    case = case_temperature(res.program.setpoint(limits.duration), limits)
    ref_case = case_temperature(res.reference.setpoint(limits.duration), limits)
    name, rel = res.worst()
    rname, rrel = res.worst("reference")
    write_files(out, res.program, res.goal, limits, case, ref_case, reference_record,
                 ref_label, f"{res.goal}: worst relative std {rel:.3g} ({name}) vs {rrel:.3g} "
                            f"({rname})")
    verify = None
    if args.verify > 0:
        verify = _verify(model, params, limits, case,
                         reference_record or (limits.grid, ref_case), args.verify, args.seed,
                         res.doubt)
    held = held_in_prediction(model, res)
    doc = _document(res, limits, model, ref_label, verify, held, drift_unit)
    (out / "design.json").write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
    if args.json:
        json.dump(doc, sys.stdout, indent=2, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(render(res, limits, ref_label, verify, out, held))
    return 0


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


def _document(res, limits, model, ref_label: str, verify, held: dict[str, float],
              drift_unit: str = "y") -> dict[str, Any]:
    from ..core.summary import unit_text

    name, rel = res.worst()
    rname, rrel = res.worst("reference")
    return {
        "goal": res.goal, "model": list(model.names), "params": res.params,
        "doubt": list(res.doubt),
        **program_document(res.program, limits),
        "predicted_std": {n: _finite(v) for n, v in res.predicted.items()},
        # the parameters the predicted stds take as known (verify's fits estimate them)
        "predicted_given": held,
        "reference": ref_label,
        "reference_std": {n: _finite(v) for n, v in res.reference_predicted.items()},
        "worst": {"designed": [name, _finite(rel)], "reference": [rname, _finite(rrel)]},
        "evaluations": res.evaluations,
        "verify": verify,
        # the units of the stds above (each parameter's, the drift's in place of y), and
        # of the program's times and temperatures
        "units": {"parameters": {n: unit_text(model.unit(n), drift_unit) for n in res.params},
                  "drift": drift_unit, "time": "s", "temperature": "degC"},
    }


def _verify(model, params, limits, case, reference, n: int, seed: int,
            doubt: tuple[str, ...]) -> dict[str, Any]:
    """Realized std of ML over ``n`` simulated runs on each profile: every run simulated
    here, the 2n fits queued at once on the worker processes (the reference's fits start
    while the designed program's last ones finish: no core waits between the profiles),
    collected in the runs' order."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    import numpy as np

    from .. import progress
    from ..core.design.realised import realised_std_gain
    from ..core.simulation import simulate

    out: dict[str, Any] = {"runs": n}
    est: dict[str, dict[str, list[float]]] = {}
    profiles = (("designed", (limits.grid, case)), ("reference", reference))
    pool = ProcessPoolExecutor(max_workers=VERIFY_WORKERS,
                               mp_context=multiprocessing.get_context("spawn"))
    with pool:
        queued = {}
        for label, (t, temp) in profiles:
            rng = np.random.default_rng([seed, 952, 0 if label == "designed" else 1])
            runs = [simulate(model, params, t=t, temp=temp, dt=limits.dt, seed=rng)
                    for _ in range(n)]
            queued[label] = [pool.submit(fit_values, r, model) for r in runs]
        for label, _ in profiles:
            with progress.stage("design", f"verify {label}", total=n, unit="fits") as bar:
                fits = []
                for fut in queued[label]:
                    fits.append(fut.result())
                    bar.update(1)
            out[label], est[label] = _verify_summary(model, fits)
    # the headline (#24 item 7): the worst relative std in doubt, realised, with its interval
    out["realised_gain"] = realised_std_gain(est["designed"], est["reference"], doubt, params)
    return out


def _verify_summary(model, fits: list[dict[str, float] | None]
                    ) -> tuple[dict[str, Any], dict[str, list[float]]]:
    """One profile of :func:`_verify`: its document and the estimates (name -> one value
    per successful fit)."""
    import numpy as np

    from ..core.validate import robust_std

    est: dict[str, list[float]] = {k: [] for k in model.param_names}
    for r in fits:
        if r is not None:
            for k in est:
                est[k].append(r[k])
    return {"failed": sum(r is None for r in fits),
            "realized_std": {k: float(np.std(v, ddof=1)) if len(v) > 2 else None
                             for k, v in est.items()},
            # the spread of the bulk (1.4826 x the median absolute deviation): beside the
            # std it shows a heavy tail, e.g. a fit that traded temp_rate.k against its lag
            "realized_robust_std": {k: robust_std(v) if len(v) > 2 else None
                                    for k, v in est.items()},
            "mean": {k: float(np.mean(v)) if v else None for k, v in est.items()}}, est


def held_in_prediction(model: Any, res: Any) -> dict[str, float]:
    """The model's parameters the predicted stds hold at a value (a shape parameter at its
    plain value: the Fisher information is of the others, given it), name -> value.
    A fit of the run (and verify's) estimates them too."""
    values = {**model.defaults, **res.params}
    return {n: float(values[n]) for n in model.param_names
            if n not in res.predicted and n in values}


def fit_values(samples: Any, model: Any) -> dict[str, float] | None:
    """The ML estimates of one verify run (None: the fit failed); no standard errors
    (the same estimates, a sixth less work). Runs in a worker process."""
    from ..core.ml.fit import ml

    try:
        r = ml(samples, model, std_errors=False)
    except Exception:  # noqa: BLE001 - a failed fit is counted, as before
        return None
    return {k: r.value(k) for k in model.param_names}


def headline(verify, rel: float, rrel: float, ref_label: str) -> str:
    """The gain the design will realise: its verify's, with the interval, when simulated;
    else the predicted one, said to be predicted (#24 item 7)."""
    predicted = f"{rrel / rel:.2f}x predicted" if rel > 0 else "predicted: -"
    g = None if verify is None else verify.get("realised_gain")
    if g is None:
        return (f"gain (worst relative std, {ref_label} over designed): {predicted} "
                "(--verify N simulates the runs and realises it)")
    lo, hi = g["interval"]
    return (f"gain (worst relative std, {ref_label} over designed): {g['ratio']:.2f}x "
            f"realised by --verify {verify['runs']} (95 % bootstrap interval {lo:.2f}-"
            f"{hi:.2f}); {predicted}")


def render(res, limits, ref_label: str, verify, out: Path,
           held: dict[str, float] | None = None) -> str:
    lines = program_lines(res.goal, res, limits)
    lines += ["", f"{'parameter':<16}{'value':>12}{'std designed':>16}{'std ' + ref_label:>26}"
                  f"{'ratio':>8}"]
    for n, v in res.predicted.items():
        ref = res.reference_predicted.get(n, math.nan)
        mark = " *" if n in res.doubt and len(res.doubt) < len(res.predicted) else ""
        lines.append(f"{n + mark:<16}{res.params[n]:>12.4g}{v:>16.4g}{ref:>26.4g}"
                     f"{ref / v if v > 0 else math.nan:>8.2f}")
    name, rel = res.worst()
    rname, rrel = res.worst("reference")
    lines.append(f"worst-determined (relative std): designed {name} {rel:.3g}, "
                 f"{ref_label} {rname} {rrel:.3g}")
    lines.append(headline(verify, rel, rrel, ref_label))
    if verify is not None:
        lines += ["", f"verify: {verify['runs']} simulated runs each, fitted by ML "
                      "(realized std / predicted; robust std of the bulk / predicted)"]
        for n in res.predicted:
            d = verify["designed"]["realized_std"].get(n)
            r = verify["reference"]["realized_std"].get(n)
            dr = verify["designed"].get("realized_robust_std", {}).get(n)
            rr = verify["reference"].get("realized_robust_std", {}).get(n)
            pd, pr = res.predicted[n], res.reference_predicted.get(n, math.nan)
            lines.append(f"  {n:<16} designed {d:.4g} ({d / pd:.2f}; {dr / pd:.2f})   "
                         f"reference {r:.4g} ({r / pr:.2f}; {rr / pr:.2f})"
                         if None not in (d, r, dr, rr)
                         else f"  {n:<16} too few successful fits")
        if held:
            given = ", ".join(f"{n} = {v:g}" for n, v in held.items())
            it = "them" if len(held) > 1 else "it"
            lines.append(f"  predicted with {given} known; verify's fits estimate {it}, as "
                         "a fit of the run will: a realized std well above the robust one "
                         f"is a tail of runs where a coefficient traded against {it}")
    lines += ["", f"files: {out}/program.csv (the chamber program), profile.csv, "
                  "simulate.yaml, design.json, design.png"]
    return "\n".join(lines)
