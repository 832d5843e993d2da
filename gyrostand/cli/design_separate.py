"""``gyrostand design ... --separate A B``: the chamber program that best tells the
look-alike terms A and B apart (:mod:`gyrostand.core.design.separation`), its files (those of
``design``), the expected likelihood ratio on it beside the reference's, and ``--verify``."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from ..core.design.realised import expected_gain, gain_words, realised_lr_gain
from .design_program import limits_of, program_document, program_lines, write_files


def run_separate(args: argparse.Namespace, given: dict[str, float]) -> int:
    import numpy as np

    from .. import progress
    from ..core.design.search import case_temperature, search_budget, standard_cycle
    from ..core.design.separation import (
        Rivals,
        rival_models,
        rivals,
        separate,
        time_only,
        verify,
    )
    from ..core.design.switch_ons import separate_switch_ons, switch_on_records
    from ..core.model import Model
    from ..errors import ModelError

    a, b = args.separate
    given = dict(given)
    spread = _spread(args, given)
    reference_record = None
    if args.run is not None:
        from ..core.ml.fit import ml
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
    with progress.stage("design", f"search: {a} vs {b}", unit="evaluations",
                        total=search_budget(limits, starts=1, maxfev=args.evaluations)
                        ) as bar:
        # one start (the best of the standard cycle, zigzags, a random program): 86
        # programs, 83 s CPU for 6 h at 40 evaluations
        res = separate(riv, limits, reference_record=reference_record, starts=1,
                       maxfev=args.evaluations, seed=args.seed, progress=bar.update)
    if time_only(riv):  # no program helps: does splitting the budget into switch-ons?
        with progress.stage("design", f"switch-ons: {a} vs {b} over split runs",
                            unit="splits") as bar:
            res.switch_ons = separate_switch_ons(riv, limits, progress=bar.update)
        if spread is not None:
            from ..core.design.switch_ons import SPREADS, separate_power_cycle

            with progress.stage("design", f"power cycles: {a} vs {b}, sigma_b {spread:g}",
                                total=None, unit="protocols") as bar:
                res.power_cycle = separate_power_cycle(
                    riv, limits, spread, max_off=args.off_hours * 3600.0,
                    reference=res.reference_expected,
                    spreads=sorted({*SPREADS, spread}), progress=bar.update)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    case = case_temperature(res.program.setpoint(limits.duration), limits)
    ref_case = case_temperature(res.reference.setpoint(limits.duration), limits)
    total, ref_total = sum(res.expected.values()), sum(res.reference_expected.values())
    write_files(out, res.program, f"separate {a} {b}", limits, case, ref_case,
                reference_record, res.reference_label,
                f"{a} vs {b}: expected LR {total:.3g} designed vs {ref_total:.3g} "
                f"({res.reference_label})")
    pcr = res.power_cycle
    if pcr is not None:
        write_power_cycle(out, pcr, limits)
    if args.verify > 0:
        records: dict[str, Any] = {"designed": (limits.grid, case),
                                   "reference": reference_record or (limits.grid, ref_case)}
        if res.switch_ons is not None and res.switch_ons.best > 1:
            records["switch-ons"] = switch_on_records(limits, res.switch_ons.best)
        with progress.stage("design", "verify", total=2 * len(records) * args.verify,
                            unit="runs") as bar:
            res.verify = verify(riv, records, args.verify, seed=args.seed,
                                progress=bar.update)
        if pcr is not None:
            from ..core.design.switch_ons import verify_protocol

            with progress.stage("design", "verify the power cycle", total=2 * args.verify,
                                unit="sets") as bar:
                pcr.verify = verify_protocol(riv, pcr.best, args.verify, seed=args.seed,
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


def _gain(num: float, den: float) -> float | None:
    """An expected-LR ratio, None over a reference below 1 (:func:`expected_gain`)."""
    g = expected_gain(num, den)
    return None if g is None else _finite(g)


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
        # an expected-LR ratio only over a reference that can carry one (#24 item 7)
        "gain": _gain(sum(res.expected.values()), sum(res.reference_expected.values())),
        "realised_gain": (None if res.verify is None
                          else realised_lr_gain(res.verify, (r.a, r.b))),
        "evaluations": res.evaluations,
        "longer_run": None if res.longer is None else {"hours": res.longer[0],
                                                       "expected_lr": _lr(res.longer[1])},
        "verify": res.verify,
        "switch_ons": None if res.switch_ons is None else {
            "time_only": True,
            "splits": [{"runs": k, "run_hours": res.switch_ons.run_hours[k],
                        "expected_lr": _lr(lam)} for k, lam in res.switch_ons.expected.items()],
            "best": res.switch_ons.best,
            "gain": _gain(sum(res.switch_ons.expected[res.switch_ons.best].values()),
                          sum(res.switch_ons.expected[1].values())),
            "target_gain": TARGET_GAIN,
        },
        "power_cycle": (None if res.power_cycle is None
                        else power_cycle_document(res.power_cycle)),
    }


def headline(res) -> str:
    """What the design will realise: the verify's gain with its interval when simulated;
    else the expected LRs side by side (their ratio only over a reference >= 1)."""
    total, ref = sum(res.expected.values()), sum(res.reference_expected.values())
    label = res.reference_label
    if res.verify is not None:
        g = realised_lr_gain(res.verify, (res.rivals.a, res.rivals.b))
        if g is not None:
            lo, hi = g["interval"]
            return (f"gain: {g['ratio']:.2f}x realised by --verify {res.verify['runs']} "
                    f"(95 % bootstrap interval {lo:.2f}-{hi:.2f}; mean LR, both directions, "
                    f"designed over {label}); expected LR {total:.3g} vs {ref:.3g}")
    return (f"{gain_words(total, ref)}, designed vs {label}: expected, not realised "
            "(--verify N simulates the runs)")


def _said(res) -> str:
    return gain_words(sum(res.expected.values()), sum(res.reference_expected.values()))


def render(res, limits, out: Path) -> str:
    r = res.rivals
    lines = program_lines(f"separate {r.a} from {r.b}", res, limits)
    ref = res.reference_label
    lines += ["", "expected likelihood ratio 2 ln(L_right/L_wrong), the wrong model refitted:",
              f"  {'data from':<30}{'designed':>12}{ref:>20}{'ratio':>8}"]
    rows = [(f"{r.a} (fitted by {r.b})", res.expected[r.a], res.reference_expected[r.a]),
            (f"{r.b} (fitted by {r.a})", res.expected[r.b], res.reference_expected[r.b]),
            ("both (sum)", sum(res.expected.values()), sum(res.reference_expected.values()))]
    for label, d, f in rows:  # a ratio over an expected LR below 1 is no gain: "-"
        g = expected_gain(d, f)
        lines.append(f"  {label:<30}{d:>12.4g}{f:>20.4g}"
                     + (f"{g:>8.2f}" if g is not None else f"{'-':>8}"))
    lines += ["", headline(res)]
    if res.longer is not None:
        hours, lam = res.longer
        longer = sum(lam.values())
        lines += ["", f"the profile hardly changes how {r.a} and {r.b} look alike (gain "
                      f"{_said(res)}); the duration does: a standard cycle of {hours:g} h "
                      f"gives an expected LR of {longer:.4g} ({r.a}: {lam[r.a]:.4g}, {r.b}: "
                      f"{lam[r.b]:.4g})"]
    if res.switch_ons is not None:
        lines += switch_on_lines(res)
        if res.power_cycle is not None:
            lines += power_cycle_lines(res)
        else:
            lines.append(f"   a power-cycle protocol separates them through the level at each "
                         f"switch-on: give the turn-on bias spread (--param "
                         f"{SPREAD_PARAM}=SIGMA_B, the repeatability of `gyrostand identify "
                         f"RUN RUN ...`, or --spread-from its JSON) to design it")
    if res.verify is not None:
        v = res.verify
        lines += ["", f"verify: {v['runs']} simulated runs from each model on each profile, "
                      "both models fitted by ML (how often the right one wins)"]
        for label in [k for k in ("designed", "reference", "switch-ons") if k in v]:
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


#: the gain over the standard cycle #15 asks of a separating design
TARGET_GAIN = 4.0


def switch_on_lines(res) -> list[str]:
    """The switch-on table of time-only rivals and what it means."""
    r, so = res.rivals, res.switch_ons
    one = sum(so.expected[1].values())
    tot, ref = sum(res.expected.values()), sum(res.reference_expected.values())
    lines = ["", f"{r.a} and {r.b} are time-only effects: both add a function of the time "
                 f"since switch-on alone, so a temperature program moves their expected LR "
                 f"only through the refit of the rest of the model (designed vs "
                 f"standard cycle: {gain_words(tot, ref)}).",
             f"A switch-on restarts a warm-up, not a trend: the budget split into k runs "
             f"(one standard cycle each; the wrong model refitted jointly over them, "
             f"shared {r.a if r.a != 'warmup' else r.b}, per-run bias and warm-up):",
             f"  {'runs':>4} {'hours each':>10} {r.a:>12} {r.b:>12} {'sum':>10} "
             f"{'vs one run':>10}"]
    for k, lam in so.expected.items():
        tot = sum(lam.values())
        lines.append(f"  {k:>4} {so.run_hours[k]:>10.3g} {lam[r.a]:>12.4g} {lam[r.b]:>12.4g} "
                     f"{tot:>10.4g} {tot / one if one > 0 else math.inf:>10.2f}")
    if so.best > 1 and so.gain >= TARGET_GAIN:
        lines.append(f"-> {so.best} switch-ons of {so.run_hours[so.best]:.3g} h separate them "
                     f"{so.gain:.2f}x better than one run (switch the gyro off between "
                     f"runs long enough for it to cool to the chamber)")
    else:
        num = max(sum(res.expected.values()),
                  sum(so.expected[so.best].values()) if so.best > 1 else 0.0)
        g = expected_gain(num, ref)
        reach = (f"{g:.2f}" if g is not None else
                 f"not a ratio to quote (expected LR {num:.3g} vs {ref:.3g})")
        lines.append(f"-> the reachable gain over the standard cycle is {reach}, short of "
                     f"{TARGET_GAIN:g}x: each run's own turn-on bias absorbs the level at a "
                     f"switch-on, so a restart shows only through the warm-up's curvature "
                     f"within a run, and shorter runs have less of it. What separates them "
                     f"is duration (the warm-up settles, the trend does not)"
                     + ("." if res.longer is None else
                        f": {res.longer[0]:g} h give an expected LR of "
                        f"{sum(res.longer[1].values()):.4g}."))
    return lines


#: the name of the turn-on bias spread σ_b among ``--param`` (not a model parameter: the
#: power-cycle protocol's random-effect spread of ``bias.b``)
SPREAD_PARAM = "bias.spread"


def _spread(args: argparse.Namespace, given: dict[str, float]) -> float | None:
    """σ_b from ``--param bias.spread=…`` (removed from ``given``), else from
    ``--spread-from`` (the JSON of ``identify RUN RUN … --format json``: its
    repeatability's spread), else None."""
    from ..errors import ModelError

    if SPREAD_PARAM in given:
        value = given.pop(SPREAD_PARAM)
        if not value > 0:
            raise ModelError(f"--param {SPREAD_PARAM}={value:g}: the turn-on bias spread "
                             "must be > 0")
        return float(value)
    source = getattr(args, "spread_from", None)
    if source is None:
        return None
    try:
        doc = json.loads(Path(source).read_text(encoding="utf-8"))
        value = float(doc["repeatability"]["spread"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ModelError(f"--spread-from {source}: no repeatability spread in it (the JSON "
                         f"of `gyrostand identify RUN RUN ... --format json`): {exc}") from None
    if not value > 0:
        raise ModelError(f"--spread-from {source}: the repeatability spread is {value:g}; "
                         f"give --param {SPREAD_PARAM}=VALUE (e.g. its interval's upper end)")
    return value


def write_power_cycle(out: Path, pcr, limits) -> None:
    """power_cycle.csv (time / set-point / power of the whole protocol, off periods held
    at the next run's start temperature) and simulate_power_cycle.yaml (one ``simulate:``
    document per switch-on, its program)."""
    from ..core.design.search import standard_cycle
    from ..core.design.switch_ons import run_limits_of

    pc = pcr.best
    docs = []
    with open(out / "power_cycle.csv", "w", encoding="utf-8", newline="") as fh:
        fh.write("time_s,setpoint_degC,power\n")
        for r, (start, h) in enumerate(zip(pc.starts, pc.hours, strict=True)):
            run = run_limits_of(limits, h * 3600.0)
            prog = standard_cycle(run)
            cut = prog.setpoint(run.duration)  # a short run's cycle is cut at its duration
            rows = list(zip(cut.times, cut.temps, strict=True))
            for t, T in rows:
                fh.write(f"{start + t:.1f},{T:.3f},1\n")
            end = start + run.duration
            if rows[-1][0] < run.duration:
                fh.write(f"{end:.1f},{rows[-1][1]:.3f},1\n")
            fh.write(f"{end:.1f},{rows[-1][1]:.3f},0\n")
            if r < pc.k - 1:
                nxt = standard_cycle(run_limits_of(limits, pc.hours[r + 1] * 3600.0)).start
                fh.write(f"{end + pc.off:.1f},{nxt:.3f},0\n")
            lines = [f"# switch-on {r + 1} of {pc.k}: {h:g} h powered on"
                     + (f", then the gyro off for {pc.off / 3600:g} h" if r < pc.k - 1 else ""),
                     "simulate:", f"  duration: {run.duration:g}", "  temperature:"]
            lines += [f"    - [{round(t, 1):g}, {round(T, 4):g}]" for t, T in rows]
            docs.append("\n".join(lines))
    head = ("# gyrostand design --separate: the power-cycle protocol, one simulate: document "
            "per switch-on\n")
    (out / "simulate_power_cycle.yaml").write_text(head + "\n---\n".join(docs) + "\n",
                                                   encoding="utf-8")


def power_cycle_document(pcr) -> dict[str, Any]:
    pc = pcr.best
    return {
        "assumptions": {
            "bias_spread": pcr.spread,
            "turn_on_bias": "random effect: b_r = mu + u_r, u_r ~ N(0, bias_spread^2)",
            "trend": "keeps its rate in absolute time across the off periods",
            "warmup": "restarts at every switch-on with the same A and tau",
            "off_periods": "chamber soak with the gyro unpowered",
        },
        "tried": [{"run_hours": list(hours), "off_hours": off, "expected_lr": _lr(lam)}
                  for (hours, off), lam in pcr.expected.items()],
        "protocol": {"runs": pc.k, "run_hours": list(pc.hours), "off_hours": pc.off / 3600.0,
                     "chamber_hours": pc.chamber_hours,
                     "switch_on_hours": [s / 3600.0 for s in pc.starts]},
        "expected_lr": _lr(pcr.best_expected),
        "reference_expected_lr": _lr(pcr.reference),
        "gain": _gain(sum(pcr.best_expected.values()), sum(pcr.reference.values())),
        "by_spread": [{"bias_spread": sb, "expected_lr": _lr(lam),
                       "gain": _gain(sum(lam.values()), sum(pcr.reference.values()))}
                      for sb, lam in pcr.by_spread.items()],
        "target_gain": TARGET_GAIN,
        "verify": pcr.verify,
    }


def power_cycle_lines(res) -> list[str]:
    """The power-cycle protocol: its assumptions in words, the protocols tried, the
    chosen one and its gain over the standard cycle, the gain at other spreads."""
    r, pcr = res.rivals, res.power_cycle
    pc = pcr.best
    ref = sum(pcr.reference.values())
    lines = ["", f"power-cycle protocol: what separates {r.a} and {r.b} is the level at each "
                 "switch-on. Assumed:",
             f"  - the turn-on bias varies from switch-on to switch-on with spread sigma_b = "
             f"{pcr.spread:g} (a random effect around one mean; the runs' repeatability);",
             "  - an ageing/settling trend keeps its rate in absolute time while the gyro "
             "is off;",
             "  - a warm-up restarts at every switch-on, with the same amplitude and time "
             "constant (the same gyro, the same self-heating);",
             "  - the off periods are chamber soak with the gyro unpowered; the powered-on "
             f"hours stay {sum(pc.hours):g} h.",
             f"  {'runs, h each':>16} {'off h':>6} {r.a:>12} {r.b:>12} {'sum':>10} "
             f"{'gain':>8}"]
    for (hours, off), lam in pcr.expected.items():
        tot = sum(lam.values())
        mark = "  <- chosen" if (hours, off) == pc.key else ""
        g = expected_gain(tot, ref)  # over a standard cycle's expected LR below 1: "-"
        lines.append(f"  {' + '.join(f'{h:g}' for h in hours):>16} {off:>6.3g} "
                     f"{lam[r.a]:>12.4g} "
                     f"{lam[r.b]:>12.4g} {tot:>10.4g} "
                     + (f"{g:>8.1f}" if g is not None else f"{'-':>8}") + mark)
    best = pcr.best_expected
    lines.append(f"-> {pc.k} switch-ons of {' + '.join(f'{h:g}' for h in pc.hours)} h, "
                 f"{pc.off / 3600:g} h off between "
                 f"them ({pc.chamber_hours:g} h in the chamber): expected LR "
                 f"{sum(best.values()):.4g} ({r.a} {best[r.a]:.3g}, {r.b} {best[r.b]:.3g}) vs "
                 f"{ref:.3g} for one standard cycle"
                 + ("" if expected_gain(sum(best.values()), ref) is None
                    else f": gain {pcr.gain:.1f}x") + " (the choice: the "
                 "largest expected LR of the weaker direction)")
    lines.append("   the same protocol at other spreads (expected LR): " + ", ".join(
        f"sigma_b {sb:g}: {sum(lam.values()):.3g} ({r.a} {lam[r.a]:.3g}, {r.b} "
        f"{lam[r.b]:.3g})" for sb, lam in pcr.by_spread.items()))
    if pcr.verify is not None:
        v = pcr.verify
        lines.append(f"   verify: {v['runs']} simulated sets from each model under the "
                     "protocol, both fitted by its joint ML:")
        for truth in (r.a, r.b):
            x = v[truth]
            if x["mean_lr"] is None:
                lines.append(f"     data from {truth}: every fit failed")
                continue
            lines.append(f"     data from {truth:<8} right wins {100 * x['right_wins_lr']:.0f} "
                         f"% by LR, {100 * x['right_wins_bic']:.0f} % by BIC; mean LR "
                         f"{x['mean_lr']:.3g}" + (f" ({x['failed']} fits failed)"
                                                   if x["failed"] else ""))
    lines.append("   files: power_cycle.csv (time, set-point, power), "
                 "simulate_power_cycle.yaml (each switch-on's program)")
    return lines
