"""Several switch-ons within one chamber budget: what separates two time-only rivals.

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

from ...errors import GyrostandError, ModelError
from ..data import Samples
from ..model import Model, context
from .divergence import (
    VERIFY_FIT,
    design_samples,
    divergence_runs,
    log_bounds,
    mean_response,
    nelder_mead,
    refitted_params,
    tally_wins,
    whittle_grids,
    whittle_loglik,
)
from .search import ChamberLimits, case_temperature, standard_cycle
from .separation import Rivals, expected_lr

log = logging.getLogger(__name__)

__all__ = ["SwitchOnResult", "separate_switch_ons", "switch_on_records", "PowerCycle",
           "PowerCycleResult", "power_cycle", "separate_power_cycle", "expected_lr_protocol",
           "simulate_protocol", "verify_protocol", "protocol_splits", "run_record"]

MAX_SWITCH_ONS, MIN_RUN = 4, 3600.0


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
        X = fit.regressors(q, context(s, fit))
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

    if "bias.b" not in fit.param_names or "bias.b" not in truth.param_names:
        raise ModelError("a power-cycle protocol needs the bias term in both models")
    offsets = pc.starts
    recs = []
    for (t, temp), d in zip(pc.runs, offsets, strict=True):
        s = design_samples(t, np.zeros_like(t), temp, dt)
        recs.append(s.replace(drift=protocol_mean(truth, truth_params, s, d)))
    grids = whittle_grids(truth, truth_params, recs, dt)
    names = refitted_params(fit, fit_params, recs[0], refit_noise)
    bounds = log_bounds(fit, names, max(float(t[-1] - t[0]) for t, _ in pc.runs), dt)

    def point(z: np.ndarray) -> dict[str, float]:
        q = dict(fit_params)
        for k, v in zip(names, z, strict=True):
            lo, hi = bounds[k]
            q[k] = math.exp(min(max(float(v), lo), hi))
        return q

    def total(z: np.ndarray) -> float:
        q = point(z)
        return _protocol_distance(fit, [q] * len(recs), recs, offsets, pc.spread) + sum(
            whittle_loglik(S0, fit, q, w, dt, n) for w, S0, n in grids)

    start = np.array([math.log(fit_params[k]) for k in names])
    best = total(start)
    if not names:
        return max(best, 0.0)
    fun, _ = nelder_mead(total, start, best, refit_noise)
    return float(max(min(fun, best), 0.0))


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
    from ..simulation import simulate

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
    from ..ml.joint import joint_ml

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
                lt = joint_ml(ss, mt, start=pt, **pc.fit_options(mt), **VERIFY_FIT).loglik
                lo = joint_ml(ss, mo, start=po, **pc.fit_options(mo), **VERIFY_FIT).loglik
            except GyrostandError as exc:
                log.warning("verify: a fit failed: %s", exc)
                failed += 1
            else:
                lrs.append(2.0 * (lt - lo))
            if progress is not None:
                progress(1)
        out[truth] = {**tally_wins(other, lrs, failed, penalty), "bic_threshold": penalty}
    return out
