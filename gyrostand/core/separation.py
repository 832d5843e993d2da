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

Time-only rivals (a trend c·(t − t₀) and a warm-up A·e^{−(t−t₀)/τ}: functions of the time
since switch-on alone) look alike on every temperature program. What tells them apart is a
power cycle (:class:`PowerCycle`, :func:`separate_power_cycle`): the powered-on budget split
into k switch-ons, δ_r apart on one clock (off periods: chamber soak, gyro unpowered), with

    y_r(t) = μ + u_r + c·(t − t_on,1) [trend]  or  μ + u_r + A·e^{−(t − t_on,r)/τ} [warm-up]
             + the rest of the model (its Markov drift from its stationary law at each
             switch-on),   u_r ~ N(0, σ_b²) independent,

the trend keeping its rate across the off periods, the warm-up restarting with the same A
and τ, σ_b the known turn-on-to-turn-on spread of the bias (the runs' repeatability). Each
run's covariance is V_r = Σ_r + σ_b² 11', the runs independent given the parameters; Λ is
the same 2 KL with the whitening of V_r (:func:`_protocol_distance`: Kalman whitening of
Σ_r, then the whitened ones direction shrunk by Woodbury) and every parameter shared, and
:func:`verify_protocol` fits both by :func:`~.multirun.joint_ml_fit` with the same model
(``bias_spread``, ``absolute_time``, ``shared=["warmup"]``). A trend's level climbs
c·(L + off) from one switch-on to the next, a warm-up's starts again at μ + A: the larger
that step is beside σ_b, the better they separate; as σ_b → ∞ every run's own bias
absorbs it again (the free-bias split of :func:`separate_switch_ons`).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import GyrostandError, ModelError
from .data import Samples
from .design import ChamberLimits, Program, case_temperature, search, standard_cycle
from .model import Model, context

log = logging.getLogger(__name__)

__all__ = ["Rivals", "SeparationResult", "SwitchOnResult", "rivals", "expected_lr",
           "separate", "separate_switch_ons", "switch_on_records", "time_only", "verify",
           "run_limits", "design_command", "PowerCycle", "PowerCycleResult", "power_cycle",
           "separate_power_cycle", "expected_lr_protocol", "simulate_protocol",
           "verify_protocol", "protocol_splits", "run_record"]

#: verify's ML fits: only ln L is used (no standard errors); the best start (the model's
#: own parameters among them) refined
_VERIFY_FIT = {"n_local": 1, "std_errors": False}
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
    from .ml import ml
    from .simulate import simulate

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


def _samples(t: np.ndarray, y: np.ndarray, temp: np.ndarray, dt: float) -> Samples:
    return Samples(np.asarray(t, dtype=float), np.asarray(y, dtype=float),
                   np.asarray(temp, dtype=float), float(dt), source="design --separate")


def mean_response(model: Model, params: Mapping[str, float], s: Samples) -> np.ndarray:
    """μ = X θ: the model's deterministic response on the record ``s``."""
    X = model.regressors(params, context(s))
    theta = np.array([params[n] for n in model.names_of_kind("linear")])
    return X @ theta if theta.size else np.zeros(len(s))


def _distance(fit: Model, params: Mapping[str, float], s: Samples) -> float:
    """min_β ‖W (y − X β)‖² with the model's whitening W at ``params``."""
    return _joint_distance(fit, [params], [s])


def _joint_distance(fit: Model, params: Sequence[Mapping[str, float]],
                    records: Sequence[Samples]) -> float:
    """The same over several runs (run k at ``params[k]``): one least squares over the
    stacked whitened runs, a shared linear coefficient one column, a per-run one
    (:func:`~.multirun.per_run_names`: the bias, a warm-up's amplitude) a column per run."""
    from .multirun import per_run_names

    lin = fit.names_of_kind("linear")
    per = set(per_run_names(fit))
    cols = [(j, k) for j, n in enumerate(lin)
            for k in (range(len(records)) if n in per and len(records) > 1 else [None])]
    ys, blocks = [], []
    for k, (q, s) in enumerate(zip(params, records, strict=True)):
        X = fit.regressors(q, context(s))
        E, f = fit.filter_columns(q, s, X)
        ok = np.isfinite(E[:, 0]) & (f > 0)
        W = E[ok] / np.sqrt(f[ok])[:, None]
        ys.append(W[:, 0])
        block = np.zeros((W.shape[0], len(cols)))
        for c, (j, owner) in enumerate(cols):
            if owner is None or owner == k:
                block[:, c] = W[:, 1 + j]
        blocks.append(block)
    y = np.concatenate(ys)
    if not cols:
        return float(y @ y)
    A = np.concatenate(blocks)
    beta, *_ = np.linalg.lstsq(A, y, rcond=None)
    r = y - A @ beta
    return float(r @ r)


def mean_parameters(fit: Model, params: Mapping[str, float], s: Samples) -> list[str]:
    """The nonlinear parameters (``rate``, ``time``) the model's mean response depends on
    (markov.beta through an input term, a time constant): what a refit moves to mimic."""
    ctx = context(s)
    X0 = fit.regressors(params, ctx)
    out = []
    for n in fit.param_names:
        if fit.kind(n) in ("rate", "time"):
            q = dict(params)
            q[n] *= 1.01
            if not np.allclose(fit.regressors(q, context(s)), X0, rtol=0, atol=0):
                out.append(n)
    return out


def _whittle(S0: np.ndarray, fit: Model, params: Mapping[str, float], w: np.ndarray,
             dt: float, n: int) -> float:
    """N · mean_j [ρ_j − 1 − ln ρ_j], ρ = S_truth/S_fit: 2 KL of the noises (Whittle)."""
    rho = S0 / _spectrum(fit, params, dt, w)
    return float(n * np.mean(rho - 1.0 - np.log(rho)))


def divergence(truth: Model, truth_params: Mapping[str, float], fit: Model,
               fit_params: Mapping[str, float], t: np.ndarray, temp: np.ndarray, dt: float,
               *, refit_noise: bool = True, found: dict[str, float] | None = None) -> float:
    """Λ(truth→fit) on the record (``t``, ``temp``): min over ``fit``'s linear
    coefficients (least squares), its mean parameters (:func:`mean_parameters`) and, with
    ``refit_noise``, its noise levels (``std``), of the whitened squared distance plus the
    noises' Whittle divergence (module docstring). ``found``: filled with the re-fitted
    nonlinear parameters (a warm start for the next, similar record)."""
    return divergence_runs(truth, truth_params, fit, fit_params, [(t, temp)], dt,
                           refit_noise=refit_noise, found=found)


def divergence_runs(truth: Model, truth_params: Mapping[str, float], fit: Model,
                    fit_params: Mapping[str, float],
                    records: Sequence[tuple[np.ndarray, np.ndarray]], dt: float, *,
                    refit_noise: bool = True, found: dict[str, float] | None = None
                    ) -> float:
    """Λ(truth→fit) summed over several runs (switch-ons) of one gyro, each record
    (``t``, ``temp``) its own run: the truth runs each from its own switch-on with the
    same parameters; ``fit`` is refitted jointly as :mod:`~.multirun` fits several runs
    (its shared parameters once, its per-run ones — bias, a warm-up's A and τ — once per
    run). One record: :func:`divergence`."""
    from scipy.optimize import minimize

    from .multirun import per_run_names

    recs = []
    for t, temp in records:
        s = _samples(t, np.zeros_like(t), temp, dt)
        recs.append(s.replace(drift=mean_response(truth, truth_params, s)))
    K = len(recs)
    grids = []
    for s in recs:
        n = len(s)
        w = 2.0 * np.pi * np.arange(1, n // 2 + 1) / n
        grids.append((w, _spectrum(truth, truth_params, dt, w), n))
    names = mean_parameters(fit, fit_params, recs[0])
    if refit_noise:  # the noise levels, and the rates of processes no input goes through
        names += [k for k in fit.param_names if fit.kind(k) in ("std", "rate")
                  and k not in names and fit_params[k] > 0]
    per = set(per_run_names(fit)) if K > 1 else set()
    # the searched point: a per-run parameter once per run (owner k), a shared one once
    slots = [(k, owner) for k in names for owner in (range(K) if k in per else [None])]
    duration = max(float(t[-1] - t[0]) for t, _ in records)
    bounds = {k: ((math.log(2.0 * dt), math.log(20.0 * max(duration, dt)))
                  if fit.kind(k) == "time" else
                  (math.log(1e-3 / max(duration, dt)), math.log(1.0 / dt))
                  if fit.kind(k) == "rate" else (-math.inf, math.inf)) for k in names}

    def point(z: np.ndarray) -> list[dict[str, float]]:
        qs = [dict(fit_params) for _ in range(K)]
        for (k, owner), v in zip(slots, z, strict=True):
            lo, hi = bounds[k]
            x = math.exp(min(max(float(v), lo), hi))
            for r in (range(K) if owner is None else [owner]):
                qs[r][k] = x
        return qs

    def total(z: np.ndarray) -> float:
        qs = point(z)
        return _joint_distance(fit, qs, recs) + sum(
            _whittle(S0, fit, q, w, dt, n) for q, (w, S0, n) in zip(qs, grids, strict=True))

    start = np.array([math.log(fit_params[k]) for k, _ in slots])
    best = total(start)
    if not slots:
        return max(best, 0.0)
    # the search's Λ (noise held) to 1 %, the report's to 0.1 %
    tol = 1e-3 if refit_noise else 1e-2
    res = minimize(total, start, method="Nelder-Mead",
                   options={"xatol": tol, "fatol": tol * max(best, 1e-3),
                            "maxfev": (200 if refit_noise else 25) * len(slots)})
    if found is not None and res.fun < best:
        # the shared values (a per-run one: its first run's) warm-start the next record
        found.update({k: v for k, v in point(res.x)[0].items() if k in names})
    return float(max(min(res.fun, best), 0.0))


def _spectrum(model: Model, params: Mapping[str, float], dt: float, w: np.ndarray
              ) -> np.ndarray:
    ss = model.state_space(params, dt)
    z = np.exp(-1j * w)
    S = np.full(w.shape, ss.r)
    for phi, q in zip(ss.phi, ss.q, strict=True):
        S = S + q / np.abs(1.0 - phi * z) ** 2
    return S


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
                         progress=progress)
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
           seed: int = 1, progress: Callable[[int], None] | None = None
           ) -> dict[str, Any]:
    """Simulate ``n`` runs from each rival on each record (label → t, case temperature; or
    label → a list of them: ``n`` sets of several switch-ons, each run from its own
    initial state, fitted jointly by :func:`~.multirun.joint_ml`), fit both by ML (each
    search started at its own parameters) and count how often the right model wins: by
    likelihood (LR > 0) and by BIC (LR > Δp ln N, a per-run parameter counted once per
    run); the realized mean LR = 2 (ln L_right − ln L_wrong)."""
    from .ml import ml
    from .multirun import joint_ml, per_run_names
    from .simulate import simulate

    out: dict[str, Any] = {"runs": n}
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
            lrs: list[float] = []
            failed = 0
            for _ in range(n):
                ss = [simulate(mt, pt, t=t, temp=temp, dt=float(np.median(np.diff(t))),
                               seed=rng) for t, temp in runs]
                try:
                    if len(ss) == 1:
                        lt = ml(ss[0], mt, start=pt, **_VERIFY_FIT).loglik
                        lo = ml(ss[0], mo, start=po, **_VERIFY_FIT).loglik
                    else:
                        lt = joint_ml(ss, mt, start=pt, **_VERIFY_FIT).loglik
                        lo = joint_ml(ss, mo, start=po, **_VERIFY_FIT).loglik
                except GyrostandError as exc:
                    log.warning("verify: a fit failed: %s", exc)
                    failed += 1
                else:
                    assert lt is not None and lo is not None
                    lrs.append(2.0 * (lt - lo))
                if progress is not None:
                    progress(1)
            arr = np.asarray(lrs)
            doc[truth] = {"fitted_by": other, "failed": failed,
                          "right_wins_lr": float(np.mean(arr > 0)) if arr.size else None,
                          "right_wins_bic": float(np.mean(arr > penalty)) if arr.size else None,
                          "mean_lr": float(np.mean(arr)) if arr.size else None}
        out[label] = doc
    return out


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
    rate = float(np.max(np.abs(context(samples).temp_rate))) * 60.0
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
MAX_SWITCH_ONS, MIN_RUN = 4, 3600.0


def _term_params(model: Model, term: str) -> list[str]:
    return [n for n in model.param_names if n.startswith(term + ".")]


def time_only(r: Rivals) -> bool:
    """Both rivals' own terms add a deterministic mean that is a function of the time since
    switch-on alone (trend, warmup): no temperature program changes how alike they look."""
    t = np.arange(0.0, 600.0)
    flat = context(_samples(t, t * 0, np.full_like(t, 20.0), 1.0))
    ramp = context(_samples(t, t * 0, 20.0 + 0.05 * t, 1.0))
    for model, term, params in ((r.model_a, r.a, r.params_a), (r.model_b, r.b, r.params_b)):
        names = _term_params(model, term)
        if not names:
            return False
        tm = model.term_of(names[0])
        p = {**model.defaults, **params}
        x1, x2 = tm.regressors(p, flat), tm.regressors(p, ramp)
        if not x1 or any(not np.array_equal(x1[k], x2[k]) for k in x1):
            return False
    return True


def switch_on_limits(limits: ChamberLimits, k: int) -> ChamberLimits:
    """One run's limits when the budget is split into ``k`` switch-ons: the duration / k,
    as many legs and soaks as fit."""
    run = limits.duration / k
    soak = min(limits.min_soak, run / 5.0)
    return dataclasses.replace(limits, duration=run, min_soak=soak,
                               legs=max(1, min(limits.legs, int((run - limits.dt) // max(soak, 1.0)))))


def switch_on_records(limits: ChamberLimits, k: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The records of ``k`` switch-ons: each run the standard cycle of its share."""
    run = switch_on_limits(limits, k)
    case = case_temperature(standard_cycle(run).setpoint(run.duration), run)
    return [(run.grid, case)] * k


@dataclass
class SwitchOnResult:
    """Λ of the budget split into k switch-ons (k = 1: one standard cycle), each
    direction; ``best`` the k with the largest sum; ``gain`` its sum over k = 1's."""

    expected: dict[int, dict[str, float]]
    best: int
    run_hours: dict[int, float]
    verify: dict[str, Any] | None = None

    @property
    def gain(self) -> float:
        one = sum(self.expected[1].values())
        return sum(self.expected[self.best].values()) / one if one > 0 else math.inf


def separate_switch_ons(r: Rivals, limits: ChamberLimits, *, max_runs: int = MAX_SWITCH_ONS,
                        min_run: float = MIN_RUN,
                        progress: Callable[[int], None] | None = None) -> SwitchOnResult:
    """Λ (each direction, the wrong model refitted jointly over the runs: shared trend,
    per-run bias and warm-up) of the budget split into k = 1..``max_runs`` switch-ons of
    at least ``min_run`` s each: what separates two time-only rivals if anything does (a
    warm-up restarts at every switch-on, a trend does not)."""
    ks = [k for k in range(1, max_runs + 1) if k == 1 or limits.duration / k >= min_run]
    out: dict[int, dict[str, float]] = {}
    for k in ks:
        recs = switch_on_records(limits, k)
        lam = {}
        for truth, fit in ((r.a, r.b), (r.b, r.a)):
            mt, pt = r.side(truth)
            mf, pf = r.side(fit)
            lam[truth] = divergence_runs(mt, pt, mf, pf, recs, limits.dt)
        out[k] = lam
        log.info("switch-ons %d: expected LR %s", k, lam)
        if progress is not None:
            progress(1)
    best = max(out, key=lambda k: sum(out[k].values()))
    return SwitchOnResult(out, best, {k: limits.duration / k / 3600.0 for k in out})


# -- time-only rivals: a power-cycle protocol (random-effect turn-on bias) -------------

#: the off periods a power-cycle design tries, as shares of the longest one allowed
OFF_SHARES = (0.25, 0.5, 1.0)
#: the default longest off period (s): a day's soak
MAX_OFF = 24 * 3600.0


@dataclass(frozen=True)
class PowerCycle:
    """A power-cycle protocol: ``k`` switch-ons of the gyro in the chamber, run r powered
    on for its share of the budget with its own standard cycle, the runs separated by off
    periods of ``off`` s (the gyro unpowered, the chamber soaking at the next run's start
    temperature). ``spread``: σ_b, the turn-on-to-turn-on spread of the bias.

    The model of the set (:func:`~.multirun.joint_ml_fit`'s protocol options): a turn-on
    bias b_r = μ + u_r, u_r ~ N(0, σ_b²); a trend c·(t − t_on,1) on the clock of the first
    switch-on (it keeps its rate while the gyro is off); a warm-up A·exp(−(t − t_on,r)/τ)
    that restarts at every switch-on with the same A and τ; the Markov drift restarts
    from its stationary law at each switch-on."""

    runs: tuple[tuple[np.ndarray, np.ndarray], ...]
    off: float
    spread: float

    @property
    def k(self) -> int:
        return len(self.runs)

    @property
    def hours(self) -> tuple[float, ...]:
        """Each run's powered-on hours."""
        return tuple(round(float(t[-1] - t[0]) / 3600.0, 6) for t, _ in self.runs)

    @property
    def key(self) -> tuple[tuple[float, ...], float]:
        """(each run's hours, the off period's hours)."""
        return self.hours, round(self.off / 3600.0, 6)

    @property
    def starts(self) -> tuple[float, ...]:
        """Each switch-on's time from the first, s."""
        out, t = [], 0.0
        for tr, _ in self.runs:
            out.append(t)
            t += float(tr[-1] - tr[0]) + self.off
        return tuple(out)

    @property
    def chamber_hours(self) -> float:
        """Powered-on hours plus the off periods: the chamber time the protocol takes."""
        return sum(self.hours) + (self.k - 1) * self.off / 3600.0

    def fit_options(self, model: Model) -> dict[str, Any]:
        """:func:`~.multirun.joint_ml_fit`'s options for a set run under this protocol."""
        return {"bias_spread": self.spread, "absolute_time": True,
                "shared": [t for t in model.names if t == "warmup"]}


def run_limits_of(limits: ChamberLimits, duration: float) -> ChamberLimits:
    """One switch-on's limits: ``duration`` s, as many legs and soaks as fit."""
    soak = min(limits.min_soak, duration / 5.0)
    return dataclasses.replace(
        limits, duration=duration, min_soak=soak,
        legs=max(1, min(limits.legs, int((duration - limits.dt) // max(soak, 1.0)))))


def run_record(limits: ChamberLimits, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """One switch-on's record: the standard cycle of ``duration`` s (cut at it)."""
    run = run_limits_of(limits, duration)
    return run.grid, case_temperature(standard_cycle(run).setpoint(run.duration), run)


def power_cycle(limits: ChamberLimits, split: int | Sequence[float], off: float,
                spread: float) -> PowerCycle:
    """The protocol of ``split`` switch-ons (a number: equal shares of
    ``limits.duration`` powered-on seconds; or each run's hours), ``off`` s apart."""
    hours = ([limits.duration / split / 3600.0] * split if isinstance(split, int)
             else [float(h) for h in split])
    return PowerCycle(tuple(run_record(limits, h * 3600.0) for h in hours), float(off),
                      float(spread))


def protocol_splits(limits: ChamberLimits, max_runs: int = MAX_SWITCH_ONS,
                    min_run: float = MIN_RUN) -> list[tuple[float, ...]]:
    """The splits of the powered-on budget a power-cycle design tries (hours per run):
    k = 2..``max_runs`` equal runs of at least ``min_run`` s, and a long first run
    followed by k − 1 = 1, 2 runs of ``min_run`` (measured: the long run carries the
    within-run shape, the short ones the level at each switch-on)."""
    D = limits.duration
    out = [tuple([round(D / k / 3600.0, 6)] * k) for k in range(2, max_runs + 1)
           if D / k >= min_run]
    for short in (1, 2):
        first = D - short * min_run
        if first > min_run * (1 + 1e-9) and short + 1 <= max_runs:
            split = tuple([round(first / 3600.0, 6)] + [round(min_run / 3600.0, 6)] * short)
            if split not in out:
                out.append(split)
    return out


def _protocol_distance(fit: Model, params: Sequence[Mapping[str, float]],
                       records: Sequence[Samples], offsets: Sequence[float], spread: float
                       ) -> float:
    """min_β Σ_r ‖V_r^{-1/2}(y_r − X_r β)‖², V_r = Σ_r + σ_b² 11' (each run's covariance
    with the random turn-on bias), every linear coefficient shared (the bias its mean μ),
    a trend's column counted from the first switch-on (+ δ_r). The Kalman whitening W_r
    of Σ_r, then the whitened ones g = W_r 1 shrunk: Z ← Z − κ g g'Z/g'g with
    κ = 1 − 1/√(1 + σ_b² g'g), so that Z'Z = Z'W'(I − g g'/(σ_b⁻² + g'g))WZ."""
    lin = fit.names_of_kind("linear")
    ib = lin.index("bias.b")
    it = lin.index("trend.c") if "trend.c" in lin else None
    blocks = []
    for q, s, d in zip(params, records, offsets, strict=True):
        X = fit.regressors(q, context(s))
        if it is not None:
            X = X.copy()
            X[:, it] += d
        E, f = fit.filter_columns(q, s, X)
        ok = np.isfinite(E[:, 0]) & (f > 0)
        Z = E[ok] / np.sqrt(f[ok])[:, None]
        g = Z[:, 1 + ib].copy()
        gg = float(g @ g)
        if spread > 0 and gg > 0:
            kappa = 1.0 - 1.0 / math.sqrt(1.0 + spread * spread * gg)
            Z = Z - kappa * np.outer(g, g @ Z) / gg
        blocks.append(Z)
    Z = np.concatenate(blocks)
    y, A = Z[:, 0], Z[:, 1:]
    if A.shape[1] == 0:
        return float(y @ y)
    norm = np.linalg.norm(A, axis=0)  # equilibrated: the trend's column is large
    A = A / np.where(norm > 0, norm, 1.0)
    beta, *_ = np.linalg.lstsq(A, y, rcond=None)
    r = y - A @ beta
    return float(r @ r)


def protocol_mean(model: Model, params: Mapping[str, float], s: Samples, offset: float
                  ) -> np.ndarray:
    """A run's mean response under the protocol: :func:`mean_response`, plus the trend's
    level at its switch-on c·δ_r (δ_r its switch-on's time from the first)."""
    return mean_response(model, params, s) + offset * float(params.get("trend.c", 0.0))


def divergence_protocol(truth: Model, truth_params: Mapping[str, float], fit: Model,
                        fit_params: Mapping[str, float], pc: PowerCycle, dt: float, *,
                        refit_noise: bool = True) -> float:
    """Λ(truth→fit) of a set run under the power-cycle protocol ``pc``: the wrong model
    refitted jointly with the protocol's model (:class:`PowerCycle`; all its parameters
    shared, the bias a random effect of spread σ_b in both), min over its linear
    coefficients, mean parameters and (``refit_noise``) noise levels of the whitened
    distance (:func:`_protocol_distance`) plus each run's Whittle noise divergence. The
    random bias is in truth and fit alike, so it adds nothing to the noise term."""
    from scipy.optimize import minimize

    if "bias.b" not in fit.param_names or "bias.b" not in truth.param_names:
        raise ModelError("a power-cycle protocol needs the bias term in both models")
    offsets = pc.starts
    recs = []
    for (t, temp), d in zip(pc.runs, offsets, strict=True):
        s = _samples(t, np.zeros_like(t), temp, dt)
        recs.append(s.replace(drift=protocol_mean(truth, truth_params, s, d)))
    grids = []
    for s in recs:
        n = len(s)
        w = 2.0 * np.pi * np.arange(1, n // 2 + 1) / n
        grids.append((w, _spectrum(truth, truth_params, dt, w), n))
    names = mean_parameters(fit, fit_params, recs[0])
    if refit_noise:
        names += [k for k in fit.param_names if fit.kind(k) in ("std", "rate")
                  and k not in names and fit_params[k] > 0]
    duration = max(float(t[-1] - t[0]) for t, _ in pc.runs)
    bounds = {k: ((math.log(2.0 * dt), math.log(20.0 * max(duration, dt)))
                  if fit.kind(k) == "time" else
                  (math.log(1e-3 / max(duration, dt)), math.log(1.0 / dt))
                  if fit.kind(k) == "rate" else (-math.inf, math.inf)) for k in names}

    def point(z: np.ndarray) -> dict[str, float]:
        q = dict(fit_params)
        for k, v in zip(names, z, strict=True):
            lo, hi = bounds[k]
            q[k] = math.exp(min(max(float(v), lo), hi))
        return q

    def total(z: np.ndarray) -> float:
        q = point(z)
        return _protocol_distance(fit, [q] * len(recs), recs, offsets, pc.spread) + sum(
            _whittle(S0, fit, q, w, dt, n) for w, S0, n in grids)

    start = np.array([math.log(fit_params[k]) for k in names])
    best = total(start)
    if not names:
        return max(best, 0.0)
    tol = 1e-3 if refit_noise else 1e-2
    res = minimize(total, start, method="Nelder-Mead",
                   options={"xatol": tol, "fatol": tol * max(best, 1e-3),
                            "maxfev": (200 if refit_noise else 25) * len(names)})
    return float(max(min(res.fun, best), 0.0))


def expected_lr_protocol(r: Rivals, pc: PowerCycle, dt: float) -> dict[str, float]:
    """Λ each direction under the protocol ``pc`` (:func:`divergence_protocol`)."""
    out = {}
    for truth, fit in ((r.a, r.b), (r.b, r.a)):
        mt, pt = r.side(truth)
        mf, pf = r.side(fit)
        out[truth] = divergence_protocol(mt, pt, mf, pf, pc, dt)
    return out


@dataclass
class PowerCycleResult:
    """Λ (each direction) of the power-cycle protocols tried, keyed by
    :attr:`PowerCycle.key` (each run's hours, off hours); the chosen one; the reference
    (one standard cycle, one switch-on) Λ; Λ of the chosen protocol at other spreads σ_b."""

    expected: dict[tuple[tuple[float, ...], float], dict[str, float]]
    best: PowerCycle
    reference: dict[str, float]
    spread: float
    by_spread: dict[float, dict[str, float]] = field(default_factory=dict)
    verify: dict[str, Any] | None = None

    @property
    def best_expected(self) -> dict[str, float]:
        return self.expected[self.best.key]

    @property
    def gain(self) -> float:
        one = sum(self.reference.values())
        return sum(self.best_expected.values()) / one if one > 0 else math.inf

    def gain_at(self, spread: float) -> float:
        one = sum(self.reference.values())
        return sum(self.by_spread[spread].values()) / one if one > 0 else math.inf


#: the spreads σ_b (× the given one's unit) the result also shows the best protocol at
SPREADS = (0.03, 0.1, 0.3)


def separate_power_cycle(r: Rivals, limits: ChamberLimits, spread: float, *,
                         max_off: float = MAX_OFF, max_runs: int = MAX_SWITCH_ONS,
                         min_run: float = MIN_RUN, reference: dict[str, float] | None = None,
                         spreads: Sequence[float] = SPREADS,
                         progress: Callable[[int], None] | None = None) -> PowerCycleResult:
    """The power-cycle protocol (the splits of :func:`protocol_splits` of the powered-on
    budget ``limits.duration``; off periods of ``OFF_SHARES`` × ``max_off``) that best
    separates the rivals with the turn-on bias a random effect of spread ``spread`` (σ_b):
    the largest Λ of the weaker direction, then the largest sum (both are reported);
    ``reference``: Λ of one standard cycle (else computed)."""
    if not spread >= 0:
        raise ModelError(f"the turn-on bias spread must be >= 0, got {spread}")
    splits = protocol_splits(limits, max_runs, min_run)
    if not splits:
        raise ModelError(f"a power-cycle protocol needs two runs of at least "
                         f"{min_run / 3600:g} h: {limits.duration / 3600:g} h is too short")
    if reference is None:
        reference = expected_lr(r, limits.grid, case_temperature(
            standard_cycle(limits).setpoint(limits.duration), limits), limits.dt)
    offs = sorted({round(share * max_off / 3600.0, 6) for share in OFF_SHARES})
    out: dict[tuple[tuple[float, ...], float], dict[str, float]] = {}
    protocols = {}
    for split in splits:
        for off_h in offs:
            pc = power_cycle(limits, split, off_h * 3600.0, spread)
            out[pc.key] = expected_lr_protocol(r, pc, limits.dt)
            protocols[pc.key] = pc
            log.info("power cycle: runs %s h, off %g h: expected LR %s", split, off_h,
                     out[pc.key])
            if progress is not None:
                progress(1)
    # a design is as good as its weaker direction: the sum grows without bound with the
    # off period in the trend's direction alone (the level climbs while the gyro is off),
    # while the warm-up's direction grows slowly; the larger smaller-Λ wins, then the sum
    key = max(out, key=lambda kk: (round(min(out[kk].values()), 3), sum(out[kk].values())))
    best = protocols[key]
    res = PowerCycleResult(out, best, dict(reference), float(spread))
    for sb in spreads:
        res.by_spread[float(sb)] = (out[key] if sb == spread else
                                    expected_lr_protocol(r, dataclasses.replace(best, spread=sb),
                                                         limits.dt))
        if progress is not None:
            progress(1)
    return res


def simulate_protocol(model: Model, params: Mapping[str, float], pc: PowerCycle,
                      rng: np.random.Generator) -> list[Samples]:
    """One simulated set under the protocol: each run simulated from its own switch-on
    (its Markov state stationary, the same warm-up), its turn-on bias μ + u_r with
    u_r ~ N(0, σ_b²), the trend's level at its switch-on added, its times on the clock of
    the first switch-on."""
    from .simulate import simulate

    out = []
    c = float(params.get("trend.c", 0.0)) if "trend.c" in model.param_names else 0.0
    for (t, temp), d in zip(pc.runs, pc.starts, strict=True):
        s = simulate(model, params, t=t, temp=temp, dt=float(np.median(np.diff(t))), seed=rng)
        u = float(rng.normal(0.0, pc.spread)) if pc.spread > 0 else 0.0
        out.append(s.replace(t=np.asarray(s.t, dtype=float) + d, drift=s.drift + u + c * d))
    return out


def verify_protocol(r: Rivals, pc: PowerCycle, n: int, *, seed: int = 1,
                    progress: Callable[[int], None] | None = None) -> dict[str, Any]:
    """``n`` sets simulated from each rival under the protocol (:func:`simulate_protocol`),
    both fitted by the joint ML with the protocol's model (:meth:`PowerCycle.fit_options`,
    each search started at its own parameters): how often the right model wins by LR
    (> 0) and by BIC (LR > Δp ln N), and the realized mean LR."""
    from .multirun import joint_ml

    n_obs = sum(len(t) for t, _ in pc.runs)
    out: dict[str, Any] = {"runs": n, "switch_ons": pc.k, "run_hours": list(pc.hours),
                           "off_hours": pc.off / 3600.0, "spread": pc.spread}
    for j, truth in enumerate((r.a, r.b)):
        other = r.b if truth == r.a else r.a
        mt, pt = r.side(truth)
        mo, po = r.side(other)
        penalty = (len(mt.param_names) - len(mo.param_names)) * math.log(n_obs)
        rng = np.random.default_rng([seed, 1517, j])
        lrs: list[float] = []
        failed = 0
        for _ in range(n):
            ss = simulate_protocol(mt, pt, pc, rng)
            try:
                lt = joint_ml(ss, mt, start=pt, **pc.fit_options(mt), **_VERIFY_FIT).loglik
                lo = joint_ml(ss, mo, start=po, **pc.fit_options(mo), **_VERIFY_FIT).loglik
            except GyrostandError as exc:
                log.warning("verify: a fit failed: %s", exc)
                failed += 1
            else:
                lrs.append(2.0 * (lt - lo))
            if progress is not None:
                progress(1)
        arr = np.asarray(lrs)
        out[truth] = {"fitted_by": other, "failed": failed,
                      "right_wins_lr": float(np.mean(arr > 0)) if arr.size else None,
                      "right_wins_bic": float(np.mean(arr > penalty)) if arr.size else None,
                      "mean_lr": float(np.mean(arr)) if arr.size else None,
                      "bic_threshold": penalty}
    return out
