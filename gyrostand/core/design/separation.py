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
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import GyrostandError, ModelError
from ..data import Samples
from ..model import Model, context
from .search import ChamberLimits, Program, case_temperature, search, standard_cycle

if TYPE_CHECKING:
    from .switch_ons import PowerCycleResult, SwitchOnResult

log = logging.getLogger(__name__)

__all__ = ["Rivals", "SeparationResult", "rivals", "expected_lr", "separate", "time_only",
           "verify", "run_limits", "design_command"]

#: verify's ML fits: only ln L is used (no standard errors); the best start (the model's
#: own parameters among them) refined
VERIFY_FIT = {"n_local": 1, "std_errors": False}
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


def design_samples(t: np.ndarray, y: np.ndarray, temp: np.ndarray, dt: float) -> Samples:
    return Samples(np.asarray(t, dtype=float), np.asarray(y, dtype=float),
                   np.asarray(temp, dtype=float), float(dt), source="design --separate")


def mean_response(model: Model, params: Mapping[str, float], s: Samples) -> np.ndarray:
    """μ = X θ: the model's deterministic response on the record ``s``."""
    X = model.regressors(params, context(s, model))
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
    from ..ml.joint_problem import per_run_names

    lin = fit.names_of_kind("linear")
    per = set(per_run_names(fit))
    cols = [(j, k) for j, n in enumerate(lin)
            for k in (range(len(records)) if n in per and len(records) > 1 else [None])]
    ys, blocks = [], []
    for k, (q, s) in enumerate(zip(params, records, strict=True)):
        X = fit.regressors(q, context(s, fit))
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
    ctx = context(s, fit)
    X0 = fit.regressors(params, ctx)
    out = []
    for n in fit.param_names:
        if fit.kind(n) in ("rate", "time"):
            q = dict(params)
            q[n] *= 1.01
            if not np.allclose(fit.regressors(q, ctx), X0, rtol=0, atol=0):
                out.append(n)
    return out


def whittle_loglik(S0: np.ndarray, fit: Model, params: Mapping[str, float], w: np.ndarray,
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

    from ..ml.joint_problem import per_run_names

    recs = []
    for t, temp in records:
        s = design_samples(t, np.zeros_like(t), temp, dt)
        recs.append(s.replace(drift=mean_response(truth, truth_params, s)))
    K = len(recs)
    grids = whittle_grids(truth, truth_params, recs, dt)
    names = refitted_params(fit, fit_params, recs[0], refit_noise)
    per = set(per_run_names(fit)) if K > 1 else set()
    # the searched point: a per-run parameter once per run (owner k), a shared one once
    slots = [(k, owner) for k in names for owner in (range(K) if k in per else [None])]
    bounds = log_bounds(fit, names, max(float(t[-1] - t[0]) for t, _ in records), dt)

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
            whittle_loglik(S0, fit, q, w, dt, n) for q, (w, S0, n) in zip(qs, grids, strict=True))

    start = np.array([math.log(fit_params[k]) for k, _ in slots])
    best = total(start)
    if not slots:
        return max(best, 0.0)
    fun, x = nelder_mead(total, start, best, refit_noise)
    if found is not None and fun < best:
        # the shared values (a per-run one: its first run's) warm-start the next record
        found.update({k: v for k, v in point(x)[0].items() if k in names})
    return float(max(min(fun, best), 0.0))


def whittle_grids(truth: Model, truth_params: Mapping[str, float], recs: Sequence[Samples],
                   dt: float) -> list[tuple[np.ndarray, np.ndarray, int]]:
    """Each record's Fourier frequencies ω_j = 2πj/N, the truth's noise spectrum at them,
    and N (the Whittle term of :func:`whittle_loglik`)."""
    grids = []
    for s in recs:
        n = len(s)
        w = 2.0 * np.pi * np.arange(1, n // 2 + 1) / n
        grids.append((w, _spectrum(truth, truth_params, dt, w), n))
    return grids


def refitted_params(fit: Model, fit_params: Mapping[str, float], s: Samples, refit_noise: bool
              ) -> list[str]:
    """The wrong model's parameters searched in Λ's minimization: those its mean depends on
    (:func:`mean_parameters`) and, with ``refit_noise``, the noise levels and the rates of
    processes no input goes through."""
    names = mean_parameters(fit, fit_params, s)
    if refit_noise:
        names += [k for k in fit.param_names if fit.kind(k) in ("std", "rate")
                  and k not in names and fit_params[k] > 0]
    return names


def log_bounds(fit: Model, names: Sequence[str], duration: float, dt: float
                ) -> dict[str, tuple[float, float]]:
    """The searched parameters' bounds in log: a time constant 2Δt .. 20 × the record, a
    rate 1e-3 / the record .. 1/Δt, a noise level unbounded."""
    return {k: ((math.log(2.0 * dt), math.log(20.0 * max(duration, dt)))
                if fit.kind(k) == "time" else
                (math.log(1e-3 / max(duration, dt)), math.log(1.0 / dt))
                if fit.kind(k) == "rate" else (-math.inf, math.inf)) for k in names}


def nelder_mead(total: Callable[[np.ndarray], float], start: np.ndarray, best: float,
                 refit_noise: bool) -> tuple[float, np.ndarray]:
    """Nelder–Mead of Λ's ``total`` from ``start`` (where it is ``best``): (min, argmin).
    The search's Λ (noise held) to 1 %, the report's to 0.1 %."""
    from scipy.optimize import minimize

    tol = 1e-3 if refit_noise else 1e-2
    res = minimize(total, start, method="Nelder-Mead",
                   options={"xatol": tol, "fatol": tol * max(best, 1e-3),
                            "maxfev": (200 if refit_noise else 25) * len(start)})
    return float(res.fun), res.x


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
    from ..ml.fit import ml
    from ..ml.joint import joint_ml
    from ..ml.joint_problem import per_run_names
    from ..simulation import simulate

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
                        lt = ml(ss[0], mt, start=pt, **VERIFY_FIT).loglik
                        lo = ml(ss[0], mo, start=po, **VERIFY_FIT).loglik
                    else:
                        lt = joint_ml(ss, mt, start=pt, **VERIFY_FIT).loglik
                        lo = joint_ml(ss, mo, start=po, **VERIFY_FIT).loglik
                except GyrostandError as exc:
                    log.warning("verify: a fit failed: %s", exc)
                    failed += 1
                else:
                    assert lt is not None and lo is not None
                    lrs.append(2.0 * (lt - lo))
                if progress is not None:
                    progress(1)
            doc[truth] = tally_wins(other, lrs, failed, penalty)
        out[label] = doc
    return out


def tally_wins(other: str, lrs: Sequence[float], failed: int, penalty: float) -> dict[str, Any]:
    """A verify's tally of one direction: how often the right model wins, by LR (> 0) and
    by BIC (> ``penalty``), and the mean LR of the sets whose fits did not fail."""
    arr = np.asarray(lrs)
    return {"fitted_by": other, "failed": failed,
            "right_wins_lr": float(np.mean(arr > 0)) if arr.size else None,
            "right_wins_bic": float(np.mean(arr > penalty)) if arr.size else None,
            "mean_lr": float(np.mean(arr)) if arr.size else None}


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
