"""Design the chamber run that tells two look-alike effects apart (``design --separate``).

Two rival models share a base M₀: A = M₀ + a, B = M₀ + b (e.g. a = trend, b = warmup), at
parameters θ_A, θ_B (each fitted to the same run, or one given and the other its pseudo-true
look-alike: the ML fit of it to a record simulated from the first on the reference). On a
case-temperature record, the expected log-likelihood ratio of the right model over the
wrong one, each direction,

    Λ(A→B) = min_{θ'} E_A[2 ln L_A(θ_A) − 2 ln L_B(θ')] = 2 KL(p_A ‖ p_B(θ*))

(the wrong model re-fitted: its pseudo-true θ*), is computed on the expected data, with no
simulation: the Gaussian 2 KL between the truth and the re-fitted wrong model,

    Λ(A→B) ≈ min_{ν, s} { ‖ W_B (μ_A − X_B β̂) ‖²  +  N · mean_j [ρ_j − 1 − ln ρ_j] }

The first term: μ_A the mean response of A (its regressors times its coefficients), W_B the
Kalman whitening of B (the innovations divided by √f of
:meth:`~gyrostand.core.model.Model.filter_columns`), β̂ B's linear coefficients by least
squares on the whitened columns: the whitened squared distance from A's mean to its best
projection on B. The second: the Whittle approximation of 2 KL between the two stationary
noises, ρ_j = S_A(ω_j)/S_B(ω_j) at the Fourier frequencies ω_j = 2πj/N (0 when the random
parts are alike; temp_lag vs markov2 and random_walk differ). Minimized (Nelder–Mead in
logs) over ν, B's nonlinear parameters its mean depends on (markov.beta through the
temperature input, time constants: :func:`mean_parameters` — a lag in series with the drift's
own 1/β is mostly mimicked by a longer 1/β) and s, B's noise levels and noise-only rates.

The search maximizes the symmetrized Λ = Λ(A→B) + Λ(B→A) with the chamber search of
:func:`~.design.search`, on a cheaper Λ with B's noise held at θ_B (its ranking of programs,
not its value); the designed and the reference programs are then reported with the full
minimization, and :func:`verify` fits both models by ML to simulated runs to confirm it.

Time-only rivals (a trend and a warm-up: functions of the time since switch-on alone) look
alike on every temperature program; :mod:`~.switch_ons` designs what tells them apart (a
power cycle with a random-effect turn-on bias).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import GyrostandError, ModelError
from ..data import Samples
from ..model import Model, context
from .divergence import VERIFY_FIT, design_samples, divergence, tally_wins
from .search import ChamberLimits, Program, case_temperature, search, standard_cycle

if TYPE_CHECKING:
    from .switch_ons import PowerCycleResult, SwitchOnResult

log = logging.getLogger(__name__)

__all__ = ["Rivals", "SeparationResult", "rivals", "expected_lr", "separate", "time_only",
           "verify", "run_limits", "design_command"]

#: a designed/reference gain below which the result also shows a longer run's Λ, and
#: how many times longer
WEAK_GAIN, LONGER = 2.0, 2.0


@dataclass(frozen=True)
class Rivals:
    """The two look-alike models and their parameters."""

    a: str
    b: str
    model_a: Model
    model_b: Model
    params_a: dict[str, float]
    params_b: dict[str, float]

    def side(self, which: str) -> tuple[Model, dict[str, float]]:
        return (self.model_a, self.params_a) if which == self.a else (self.model_b,
                                                                      self.params_b)


def rival_models(model: Model, a: str, b: str) -> tuple[Model, Model]:
    """(M₀ + a, M₀ + b) with M₀ ``model`` without a and b."""
    if a == b:
        raise ModelError(f"design --separate: two different terms, not {a!r} twice")
    base = model.remove(*[n for n in (a, b) if n in model.names])
    try:
        return base.add(a), base.add(b)
    except ModelError as exc:
        raise ModelError(f"design --separate {a} {b}: {exc}") from None


def rivals(model: Model, a: str, b: str, given: Mapping[str, float], t: np.ndarray,
           temp: np.ndarray, dt: float, *, seed: int = 1) -> Rivals:
    """The rivals of ``a`` and ``b`` on ``model``'s base. ``given``: parameter values; a
    model whose parameters are not all given gets its pseudo-true look-alike of the other
    (its ML fit to a record simulated from the other on ``t``, ``temp``)."""
    from ..ml.fit import ml
    from ..simulation import simulate

    ma, mb = rival_models(model, a, b)
    pa = {n: float(given[n]) for n in ma.param_names if n in given}
    pb = {n: float(given[n]) for n in mb.param_names if n in given}
    full_a, full_b = len(pa) == len(ma.param_names), len(pb) == len(mb.param_names)
    if not full_a and not full_b:
        missing = [n for n in ma.param_names if n not in pa]
        raise ModelError(f"design --separate {a} {b}: give every parameter of one model "
                         f"(missing {', '.join(missing)} of {ma})")
    if not full_b:
        s = simulate(ma, pa, t=t, temp=temp, dt=dt, seed=seed)
        pb = {**ml(s, mb, start={**pa, **pb}).values, **pb}
    elif not full_a:
        s = simulate(mb, pb, t=t, temp=temp, dt=dt, seed=seed)
        pa = {**ml(s, ma, start={**pb, **pa}).values, **pa}
    return Rivals(a, b, ma, mb, pa, pb)


def expected_lr(r: Rivals, t: np.ndarray, temp: np.ndarray, dt: float,
                refit_noise: bool = True, warm: dict[str, dict[str, float]] | None = None
                ) -> dict[str, float]:
    """Λ each direction on the record (``t``, case ``temp``): ``{a: Λ(A→B), b: Λ(B→A)}``
    (the right model's expected LR when it generated the data); ``refit_noise=False``:
    the wrong model's noise levels held (the search's cheaper Λ); ``warm``: per direction,
    the last re-fit's parameters, where each re-fit starts and what it leaves."""
    out = {}
    for truth, fit in ((r.a, r.b), (r.b, r.a)):
        mt, pt = r.side(truth)
        mf, pf = r.side(fit)
        last = warm.setdefault(truth, {}) if warm is not None else None
        out[truth] = divergence(mt, pt, mf, {**pf, **(last or {})}, t, temp, dt,
                                refit_noise=refit_noise, found=last)
    return out


@dataclass
class SeparationResult:
    """The designed program, the reference and the expected LR on each."""

    rivals: Rivals
    program: Program
    reference: Program
    expected: dict[str, float]
    reference_expected: dict[str, float]
    evaluations: int
    reference_label: str = "standard cycle"
    verify: dict[str, Any] | None = field(default=None)
    #: when the profile hardly separates them (time-only effects: trend, warmup):
    #: (hours, Λ each direction) of a standard cycle :data:`LONGER` × as long
    longer: tuple[float, dict[str, float]] | None = None
    #: time-only rivals: the budget split into switch-ons (:func:`separate_switch_ons`)
    switch_ons: SwitchOnResult | None = None
    #: time-only rivals with a turn-on bias spread: the power-cycle protocol
    #: (:func:`separate_power_cycle`)
    power_cycle: PowerCycleResult | None = None

    @property
    def gain(self) -> float:
        """Symmetrized Λ on the designed program over that on the reference."""
        ref = sum(self.reference_expected.values())
        return sum(self.expected.values()) / ref if ref > 0 else math.inf


def separate(r: Rivals, limits: ChamberLimits, *, reference: Program | None = None,
             reference_record: tuple[np.ndarray, np.ndarray] | None = None,
             starts: int = 1, maxfev: int = 40, seed: int = 1,
             progress: Callable[[int], None] | None = None) -> SeparationResult:
    """The program within ``limits`` that maximizes the symmetrized Λ (module docstring);
    the reference is ``reference_record`` (a run's own t, temperature) if given, else
    ``reference`` or the standard cycle. A designed program no better than the reference
    program is replaced by it."""
    ref = reference or standard_cycle(limits)
    grid = limits.grid

    warm: dict[str, dict[str, float]] = {}  # consecutive programs are alike: warm starts

    def objective(case: np.ndarray) -> float:
        lam = sum(expected_lr(r, grid, case, limits.dt, refit_noise=False,
                              warm=warm).values())
        return -math.log(lam) if lam > 0 else math.inf

    prog, count = search(objective, limits, ref, starts=starts, maxfev=maxfev, seed=seed,
                         progress=progress, workers=1)  # one thread: ``warm`` is shared
    lam = expected_lr(r, grid, case_temperature(prog.setpoint(limits.duration), limits),
                      limits.dt)
    ref_prog = expected_lr(r, grid, case_temperature(ref.setpoint(limits.duration), limits),
                           limits.dt)
    if sum(lam.values()) <= sum(ref_prog.values()):
        prog, lam = ref, ref_prog
    label, ref_lam = "standard cycle", ref_prog
    if reference_record is not None:
        t, temp = reference_record
        ref_lam = expected_lr(r, t, temp, float(np.median(np.diff(t))))
        label = "this run's record"
    out = SeparationResult(r, prog, ref, lam, ref_lam, count, label)
    if out.gain < WEAK_GAIN:
        long = dataclasses.replace(limits, duration=LONGER * limits.duration)
        case = case_temperature(standard_cycle(long).setpoint(long.duration), long)
        lam_long = expected_lr(r, long.grid, case, long.dt)
        if sum(lam_long.values()) >= WEAK_GAIN * sum(ref_lam.values()):
            out.longer = (long.duration / 3600.0, lam_long)
    return out


def verify(r: Rivals, records: Mapping[str, Any], n: int, *,
           seed: int = 1, progress: Callable[[int], None] | None = None,
           workers: int = 2) -> dict[str, Any]:
    """Simulate ``n`` runs from each rival on each record (label → t, case temperature; or
    label → a list of them: ``n`` sets of several switch-ons, each run from its own
    initial state, fitted jointly by :func:`~.multirun.joint_ml`), fit both by ML (each
    search started at its own parameters) and count how often the right model wins: by
    likelihood (LR > 0) and by BIC (LR > Δp ln N, a per-run parameter counted once per
    run); the realized mean LR = 2 (ln L_right − ln L_wrong).

    The runs are simulated here in order; their fits run in ``workers`` processes (an ML
    fit is mostly Python between compiled Kalman passes: processes, not threads, use two
    CPUs), each the same computation wherever it runs."""
    import multiprocessing
    from concurrent.futures import Executor, ProcessPoolExecutor

    from ..ml.joint_problem import per_run_names
    from ..simulation import simulate

    out: dict[str, Any] = {"runs": n}
    pool: Executor | None = (
        ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
        if workers > 1 else None)
    try:
        for k, (label, rec) in enumerate(records.items()):
            runs = list(rec) if isinstance(rec, list) else [rec]
            n_obs = sum(len(t) for t, _ in runs)
            doc: dict[str, Any] = {}
            for j, truth in enumerate((r.a, r.b)):
                other = r.b if truth == r.a else r.a
                mt, pt = r.side(truth)
                mo, po = r.side(other)
                per_t, per_o = set(per_run_names(mt)), set(per_run_names(mo))
                n_t = sum(len(runs) if x in per_t else 1 for x in mt.param_names)
                n_o = sum(len(runs) if x in per_o else 1 for x in mo.param_names)
                penalty = (n_t - n_o) * math.log(n_obs)
                rng = np.random.default_rng([seed, 1515, k, j])
                sets = [[simulate(mt, pt, t=t, temp=temp, dt=float(np.median(np.diff(t))),
                                  seed=rng) for t, temp in runs] for _ in range(n)]
                jobs = [(ss, mt, pt, mo, po) for ss in sets]
                done = pool.map(pair_lr, jobs) if pool is not None else map(pair_lr, jobs)
                lrs: list[float] = []
                failed = 0
                for lr in done:
                    if isinstance(lr, str):
                        log.warning("verify: a fit failed: %s", lr)
                        failed += 1
                    else:
                        lrs.append(lr)
                    if progress is not None:
                        progress(1)
                doc[truth] = tally_wins(other, lrs, failed, penalty)
            out[label] = doc
    finally:
        if pool is not None:
            pool.shutdown()
    return out


def pair_lr(job: tuple[Any, ...]) -> float | str:
    """2 (ln L_right − ln L_wrong) of one simulated set ``ss`` (a list of runs) fitted by
    the right model ``mt`` (started at ``pt``) and the wrong ``mo`` (at ``po``); the
    error's text when a fit fails. :func:`verify`'s unit of work (a worker process's)."""
    from ..ml.fit import ml
    from ..ml.joint import joint_ml

    ss, mt, pt, mo, po = job
    try:
        if len(ss) == 1:
            lt = ml(ss[0], mt, start=pt, **VERIFY_FIT).loglik
            lo = ml(ss[0], mo, start=po, **VERIFY_FIT).loglik
        else:
            lt = joint_ml(ss, mt, start=pt, **VERIFY_FIT).loglik
            lo = joint_ml(ss, mo, start=po, **VERIFY_FIT).loglik
    except GyrostandError as exc:
        return str(exc)
    assert lt is not None and lo is not None
    return 2.0 * (lt - lo)


#: design's defaults the command leaves out (cli/design.py: --legs, --min-soak)
_LEGS, _MIN_SOAK_MIN = 6, 10.0


def run_limits(samples: Samples) -> dict[str, float]:
    """The chamber limits a run shows: its temperature range (°C, to the whole degree
    outside it), its fastest ramp (°C/min, robust rate, to 0.1 up), its duration (h) and a
    minimum soak (min) that lets a short run hold design's legs."""
    temp = np.asarray(samples.temp, dtype=float)
    lo, hi = math.floor(float(np.min(temp))), math.ceil(float(np.max(temp)))
    if hi <= lo:
        lo, hi = lo - 1, hi + 1
    rate = float(np.max(np.abs(context(samples, None).temp_rate))) * 60.0
    hours = float(samples.t[-1] - samples.t[0]) / 3600.0
    soak = min(_MIN_SOAK_MIN, math.floor(hours * 60.0 / (2 * _LEGS) * 10) / 10)
    return {"t_min": float(lo), "t_max": float(hi),
            "max_rate": max(math.ceil(rate * 10.0) / 10.0, 0.1),
            "hours": math.floor(hours * 100.0) / 100.0, "min_soak": soak}


def design_command(source: str, a: str, b: str, samples: Samples, model: Model, *,
                   gyro: str | None = None) -> str:
    """The ``gyrostand design --separate a b`` command for this run (``source``: its
    folder or CSV) within the limits it shows (:func:`run_limits`), on its current
    ``model``; what ``diagnose`` prints when it finds look-alikes."""
    import shlex

    lim = run_limits(samples)
    words = ["gyrostand", "design", shlex.quote(str(source)), "--separate", a, b,
             "--model", str(model)]
    if gyro is not None:
        words += ["--gyro", shlex.quote(gyro)]
    words += ["--t-min", f"{lim['t_min']:g}", "--t-max", f"{lim['t_max']:g}",
              "--max-rate", f"{lim['max_rate']:g}", "--hours", f"{lim['hours']:g}"]
    if lim["min_soak"] < _MIN_SOAK_MIN:
        words += ["--min-soak", f"{lim['min_soak']:g}"]
    return " ".join(words)


# -- time-only rivals: switch-ons ------------------------------------------------------

#: how many switch-ons a split design tries at most, and the shortest run it makes (s)
def _term_params(model: Model, term: str) -> list[str]:
    return [n for n in model.param_names if n.startswith(term + ".")]


def time_only(r: Rivals) -> bool:
    """Both rivals' own terms add a deterministic mean that is a function of the time since
    switch-on alone (trend, warmup): no temperature program changes how alike they look."""
    t = np.arange(0.0, 600.0)
    flat_s = design_samples(t, t * 0, np.full_like(t, 20.0), 1.0)
    ramp_s = design_samples(t, t * 0, 20.0 + 0.05 * t, 1.0)
    for model, term, params in ((r.model_a, r.a, r.params_a), (r.model_b, r.b, r.params_b)):
        flat, ramp = context(flat_s, model), context(ramp_s, model)
        names = _term_params(model, term)
        if not names:
            return False
        tm = model.term_of(names[0])
        p = {**model.defaults, **params}
        x1, x2 = tm.regressors(p, flat), tm.regressors(p, ramp)
        if not x1 or any(not np.array_equal(x1[k], x2[k]) for k in x1):
            return False
    return True
