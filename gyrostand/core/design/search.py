"""Design of the next chamber run: the temperature set-point program that makes the
parameters in doubt best determined, within the chamber's limits.

A program is ``legs`` legs from a start temperature T₀: leg j ramps at rate r_j to T_j
and soaks there s_j,

    T_j ∈ [T_min, T_max],   0 < r_j ≤ r_max,   s_j ≥ s_min,   Σ_j (|T_j − T_{j−1}|/r_j + s_j) = D.

The gyro's case follows the set-point through the chamber-to-case lag τ (first order,
dT_c/dt = (T_s − T_c)/τ from T_c(0) = T_s(0); τ = 0: the case is at the set-point),
exact on the Δt grid for a set-point linear between grid points (first-order hold):
with s the step's slope and φ = e^{−Δt/τ},

    T_c[k] = T_s[k] − sτ + φ (T_c[k−1] − T_s[k−1] + sτ),

and the model sees T_c. The information a program gives is the expected Fisher
information I(θ) of the exact likelihood on T_c (:func:`~gyrostand.core.design.fisher.information`:
the part the program changes is exact, a Kalman pass over the derivatives of the mean
response; the noise's part does not depend on the program and is a Monte Carlo average
over ``n_mc_report`` records computed once and shared by every program evaluated, so the
objective is a smooth, deterministic function of the program). Goals, minimized over the
program:

    d-optimal     ln det (I⁻¹)_SS               (the parameters in doubt S, jointly;
                                                 the other parameters stay free: D_s)
    std:NAME      √(I⁻¹)_NAME,NAME              (one parameter)
    worst         max_{i∈S} √(I⁻¹)_ii / |θ_i|   (the worst-determined in S, relative)

The search: the program is a point z ∈ ℝ^{3·legs} (targets and rates through logistic
maps into their boxes, soak shares through a softmax), Powell's method from the best few
of the standard cycle, zigzags between the range's ends and seeded random programs (the
starts run side by side on threads: the Kalman kernels release the GIL); a program whose
ramps do not fit in D with s_min soaks is infeasible (penalized by its excess).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ...errors import ModelError
from ..model import Model
from ..profiles import TemperatureProfile
from .fisher import information, mean_free, noise_information

__all__ = ["ChamberLimits", "Program", "DesignResult", "case_temperature",
           "standard_cycle", "zigzag", "predicted_std", "design", "search", "search_budget",
           "GOALS"]

GOALS = ("d-optimal", "worst", "std:NAME")
#: the standard chamber cycle's ramp rate, °C/s (0.5 °C/min)
STANDARD_RATE = 0.5 / 60.0


@dataclass(frozen=True)
class ChamberLimits:
    """What the chamber can do. Temperatures °C, ``max_rate`` °C/s, times s."""

    t_min: float
    t_max: float
    max_rate: float
    min_soak: float
    duration: float
    legs: int = 6
    lag: float = 0.0
    start: float | None = None  # default: the middle of the range
    dt: float = 1.0

    def __post_init__(self) -> None:
        if not self.t_max > self.t_min:
            raise ModelError(f"chamber limits: t_max {self.t_max} must exceed t_min {self.t_min}")
        if not self.max_rate > 0:
            raise ModelError("chamber limits: the maximum ramp rate must be > 0")
        if self.min_soak < 0 or self.lag < 0:
            raise ModelError("chamber limits: min_soak and lag must be >= 0")
        if self.legs < 1:
            raise ModelError("chamber limits: at least one leg")
        if self.duration < self.legs * self.min_soak + self.dt:
            raise ModelError(f"chamber limits: {self.duration:g} s cannot hold {self.legs} "
                             f"soaks of {self.min_soak:g} s")
        if self.start is not None and not self.t_min <= self.start <= self.t_max:
            raise ModelError(f"chamber limits: start {self.start} outside [{self.t_min}, "
                             f"{self.t_max}]")

    @property
    def t0(self) -> float:
        return 0.5 * (self.t_min + self.t_max) if self.start is None else float(self.start)

    @property
    def grid(self) -> np.ndarray:
        return np.arange(0.0, self.duration + 0.5 * self.dt, self.dt)


@dataclass(frozen=True)
class Program:
    """A set-point program: legs (target °C, rate °C/s, soak s) from ``start``."""

    start: float
    legs: tuple[tuple[float, float, float], ...]
    #: s by which the ramps overrun the duration with minimum soaks (0: feasible)
    excess: float = 0.0

    def setpoint(self, duration: float) -> TemperatureProfile:
        """The piecewise-linear set-point, held after the last leg, cut at ``duration``."""
        pts = [(0.0, self.start)]
        t, T = 0.0, self.start
        for target, rate, soak in self.legs:
            ramp = abs(target - T) / rate
            if ramp > 0:
                t += ramp
                pts.append((t, target))
            T = target
            if soak > 0:
                t += soak
                pts.append((t, T))
        prof = TemperatureProfile.from_breakpoints(
            [p for i, p in enumerate(pts) if i == 0 or p[0] > pts[i - 1][0]])
        keep = [(a, b) for a, b in zip(prof.times, prof.temps, strict=True) if a < duration]
        return TemperatureProfile.from_breakpoints(keep + [(duration, float(prof(duration)))])

    def rows(self) -> list[tuple[float, float]]:
        """The chamber program as (time s, set-point °C) breakpoints."""
        prof = self.setpoint(math.inf if not self.legs else self._end())
        return list(zip(prof.times, prof.temps, strict=True))

    def _end(self) -> float:
        t, T = 0.0, self.start
        for target, rate, soak in self.legs:
            t += abs(target - T) / rate + soak
            T = target
        return t


def case_temperature(setpoint: TemperatureProfile, limits: ChamberLimits) -> np.ndarray:
    """The case temperature on ``limits.grid``: the set-point through the lag τ."""
    t = limits.grid
    ts = setpoint(t)
    if limits.lag <= 0:
        return ts
    tau = limits.lag
    phi = math.exp(-limits.dt / tau)
    slope_tau = np.diff(ts) / limits.dt * tau  # s·τ of each step's linear piece
    out = np.empty_like(ts)
    out[0] = ts[0]
    for k in range(1, ts.size):
        p = ts[k] - slope_tau[k - 1]
        out[k] = p + phi * (out[k - 1] - ts[k - 1] + slope_tau[k - 1])
    return out


def standard_cycle(limits: ChamberLimits, rate: float = STANDARD_RATE) -> Program:
    """The reference: from T₀ soak, ramp up to T_max, soak, ramp down to T_min, soak, back
    to T₀, soak, at ``rate`` (0.5 °C/min; faster, up to the chamber's, where the ramps
    would not fit), the soaks equal and filling the duration."""
    T0, lo, hi = limits.t0, limits.t_min, limits.t_max
    targets = [T0, hi, lo, T0]
    swing = abs(hi - T0) + abs(hi - lo) + abs(T0 - lo)
    r = min(limits.max_rate, max(rate, swing / max(limits.duration - 4 * limits.min_soak, 1.0)))
    soak = max((limits.duration - swing / r) / 4.0, limits.min_soak)
    return Program(T0, tuple((T, r, soak) for T in targets))


def zigzag(limits: ChamberLimits, amplitude: float = 1.0, rate: float = 1.0) -> Program:
    """Legs alternating between the top and bottom of the range (``amplitude`` of it,
    about the middle) at ``rate`` × the chamber's maximum rate, equal soaks: a start of
    the search rich in rate reversals (what rate and heating/cooling effects need)."""
    mid, half = 0.5 * (limits.t_min + limits.t_max), 0.5 * amplitude * (limits.t_max - limits.t_min)
    r = rate * limits.max_rate
    targets = [mid + half if j % 2 == 0 else mid - half for j in range(limits.legs)]
    prev = [limits.t0] + targets[:-1]
    ramp = sum(abs(a - b) / r for a, b in zip(targets, prev, strict=True))
    soak = max((limits.duration - ramp) / limits.legs, limits.min_soak)
    return Program(limits.t0, tuple((T, r, soak) for T in targets))


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def _logit(p: float) -> float:
    p = min(max(p, 1e-6), 1 - 1e-6)
    return math.log(p / (1 - p))


def program_of(z: np.ndarray, limits: ChamberLimits) -> Program:
    """The program of a search point ``z`` (see the module docstring)."""
    L = limits.legs
    z = np.asarray(z, dtype=float)
    targets = limits.t_min + (limits.t_max - limits.t_min) * _sigmoid(z[:L])
    rates = limits.max_rate * (0.05 + 0.95 * _sigmoid(z[L:2 * L]))
    w = np.exp(z[2 * L:] - np.max(z[2 * L:]))
    w /= w.sum()
    prev = np.concatenate([[limits.t0], targets[:-1]])
    ramp = float(np.sum(np.abs(targets - prev) / rates))
    free = limits.duration - ramp - L * limits.min_soak
    soaks = limits.min_soak + max(free, 0.0) * w
    return Program(limits.t0, tuple((float(T), float(r), float(s))
                                    for T, r, s in zip(targets, rates, soaks, strict=True)),
                   excess=max(-free, 0.0))


def point_of(program: Program, limits: ChamberLimits) -> np.ndarray:
    """A search point near ``program`` (its legs padded/cut to ``limits.legs``)."""
    legs = list(program.legs)[:limits.legs]
    while len(legs) < limits.legs:
        legs.append((legs[-1][0] if legs else limits.t0, limits.max_rate, limits.min_soak))
    span = limits.t_max - limits.t_min
    zt = [_logit((T - limits.t_min) / span) for T, _, _ in legs]
    zr = [_logit((min(r / limits.max_rate, 1.0) - 0.05) / 0.95) for _, r, _ in legs]
    extra = [max(s - limits.min_soak, 1.0) for _, _, s in legs]
    zs = list(np.log(np.asarray(extra) / max(extra)))
    return np.array(zt + zr + zs)


def predicted_std(model: Model, params: Mapping[str, float], case: np.ndarray,
                  limits: ChamberLimits, *, free: Sequence[str] | None = None,
                  n_mc: int = 40, seed: int = 12345) -> dict[str, float]:
    """√CRLB of each free parameter for a record on the case temperature ``case``."""
    return _information(model, params, case, limits, free, None, n_mc, seed)[0]


def _information(model: Model, params: Mapping[str, float], case: np.ndarray,
                 limits: ChamberLimits, free: Sequence[str] | None,
                 noise: np.ndarray | None, n_mc: int, seed: int
                 ) -> tuple[dict[str, float], np.ndarray, tuple[str, ...]]:
    """(√CRLB per free parameter, the information I, its parameter names); ``noise``: the
    noise's part of I, shared by every program on the grid (else computed here)."""
    info, names = information(model, params, limits.grid, case, dt=limits.dt, free=free,
                              noise=noise, n_mc=n_mc, seed=seed)
    C = _inverse(info)
    std = {n: float(math.sqrt(C[i, i])) if C[i, i] > 0 else math.inf
           for i, n in enumerate(names)}
    return std, info, names


def _inverse(info: np.ndarray) -> np.ndarray:
    try:
        return np.linalg.inv(info)
    except np.linalg.LinAlgError:
        return np.full_like(info, np.inf)


def goal_function(goal: str, model: Model, params: Mapping[str, float],
                  free: Sequence[str] | None = None, doubt: Sequence[str] | None = None
                  ) -> Callable[[np.ndarray, tuple[str, ...]], float]:
    """``f(I, names)`` to minimize for ``goal`` (one of :data:`GOALS`); ``doubt``: the
    parameters the goal is about (default: every free one; all stay free)."""
    names_all = tuple(free) if free is not None else model.free_names(params)
    if doubt is not None:
        bad = [n for n in doubt if n not in names_all]
        if bad:
            raise ModelError(f"design: {', '.join(bad)} not free parameter(s) of the model "
                             f"({', '.join(names_all)})")
    about = tuple(doubt) if doubt else names_all
    if goal == "d-optimal":  # of the parameters in doubt: D_s-optimal, the others nuisance
        def f(info, names):
            C = _inverse(info)
            idx = [names.index(n) for n in about]
            sign, logdet = np.linalg.slogdet(C[np.ix_(idx, idx)])
            return logdet if sign > 0 and np.all(np.isfinite(C)) else math.inf
        return f
    if goal == "worst":
        scale = {n: abs(params[n]) for n in about if abs(params[n]) > 0}
        if not scale:
            raise ModelError("design goal 'worst': every parameter is 0")

        def f(info, names):
            C = _inverse(info)
            rel = [math.sqrt(max(C[i, i], 0.0)) / scale[n] for i, n in enumerate(names)
                   if n in scale]
            return math.log(max(rel)) if all(np.isfinite(rel)) else math.inf
        return f
    if goal.startswith("std:"):
        target = goal[4:]
        if target not in names_all:
            raise ModelError(f"design goal {goal!r}: {target!r} is not a free parameter of "
                             f"the model ({', '.join(names_all)})")

        def f(info, names):
            C = _inverse(info)
            v = C[names.index(target), names.index(target)]
            return 0.5 * math.log(v) if v > 0 and np.isfinite(v) else math.inf
        return f
    raise ModelError(f"design goal {goal!r}: use d-optimal, worst or std:PARAM")


def search_budget(limits: ChamberLimits, *, starts: int = 3, maxfev: int = 120) -> int:
    """About how many programs :func:`search` evaluates (the progress bar's total; Powell
    stops a start early when it converges, and may overrun its ``maxfev`` by a line search)."""
    return 5 + starts + (max(starts, 1) + 1) * maxfev


def search(objective: Callable[[np.ndarray], float], limits: ChamberLimits,
           reference: Program, *, starts: int = 3, maxfev: int = 120, seed: int = 1,
           progress: Callable[[int], None] | None = None, workers: int = 2
           ) -> tuple[Program, int]:
    """The program whose case temperature minimizes ``objective(case)`` (see the module
    docstring's search), and how many programs it evaluated. Every goal's search: the
    information goals of :func:`design` and the separation of :mod:`.separation`.

    The Powell searches from the best starts run on ``workers`` threads (``objective``
    must be safe to call from several threads: the Kalman kernels release the GIL); each
    start is deterministic, and the best is refined from the best start's optimum, so
    the result does not depend on ``workers``."""
    from concurrent.futures import ThreadPoolExecutor

    from scipy.optimize import minimize

    count = [0]
    lock = threading.Lock()

    def f(z: np.ndarray) -> float:
        prog = program_of(z, limits)
        with lock:
            count[0] += 1
            if progress is not None:
                progress(1)
        if prog.excess > 0:  # ramps too slow for the duration: push back, smoothly
            return 1e3 + prog.excess / limits.duration * 1e3
        val = objective(case_temperature(prog.setpoint(limits.duration), limits))
        return val if np.isfinite(val) else 1e3

    rng = np.random.default_rng(seed)
    dim = 3 * limits.legs
    # starts: the reference, zigzags (full and half range, full and half rate), random
    # programs; the search runs from the ``starts`` best of them
    cands = [point_of(reference, limits)] + [
        point_of(zigzag(limits, a, r), limits) for a in (1.0, 0.6) for r in (1.0, 0.5)]
    cands += [rng.normal(0.0, 1.5, dim) for _ in range(starts)]
    scored = sorted(((f(x), i) for i, x in enumerate(cands)))
    best_v, best_x = scored[0][0], cands[scored[0][1]]

    def powell(i: int) -> tuple[float, np.ndarray]:
        res = minimize(f, cands[i], method="Powell",
                       options={"maxfev": maxfev, "xtol": 1e-2, "ftol": 1e-4})
        return float(res.fun), res.x

    firsts = [i for _, i in scored[:max(starts, 1)]]
    if workers > 1 and len(firsts) > 1:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            done = list(pool.map(powell, firsts))
    else:
        done = [powell(i) for i in firsts]
    for val, x in done:  # in the starts' order: the same result on any number of workers
        if val < best_v:
            best_x, best_v = x, val
    res = minimize(f, best_x, method="Powell",
                   options={"maxfev": maxfev, "xtol": 1e-3, "ftol": 1e-5})
    if res.fun < best_v:
        best_x, best_v = res.x, float(res.fun)
    return program_of(best_x, limits), count[0]


@dataclass
class DesignResult:
    """The designed program, the reference, and what each is predicted to give."""

    goal: str
    program: Program
    reference: Program
    predicted: dict[str, float]
    reference_predicted: dict[str, float]
    objective: float
    reference_objective: float
    evaluations: int
    params: dict[str, float] = field(default_factory=dict)
    doubt: tuple[str, ...] = ()

    def worst(self, which: str = "designed", among: Sequence[str] | None = None
              ) -> tuple[str, float]:
        """(name, relative std) of the worst-determined parameter (nonzero truth) of
        ``among`` (default: the design's parameters in doubt)."""
        std = self.predicted if which == "designed" else self.reference_predicted
        names = among or self.doubt or tuple(std)
        rel = {n: std[n] / abs(self.params[n]) for n in names if self.params.get(n)}
        name = max(rel, key=rel.__getitem__)
        return name, rel[name]


def design(model: Model, params: Mapping[str, float], limits: ChamberLimits, *,
           goal: str = "d-optimal", free: Sequence[str] | None = None,
           doubt: Sequence[str] | None = None, reference: Program | None = None,
           starts: int = 3, maxfev: int = 120, n_mc_report: int = 40, seed: int = 1,
           progress: Callable[[int], None] | None = None, workers: int = 2) -> DesignResult:
    """Search the program that minimizes ``goal`` (see the module docstring).

    ``starts``: random starts besides the reference; ``maxfev``: evaluations per start
    (the best start is refined with as many again); ``progress(n)`` after each evaluation;
    ``workers``: threads for the starts. The noise's part of the information is averaged
    over ``n_mc_report`` records once, and shared by the search and the report; a
    designed program the report does not find better than the reference is replaced by
    the reference (the result then says so: ``program is reference``).
    """
    model.check_params({**model.defaults, **params})
    f_goal = goal_function(goal, model, params, free, doubt)
    ref = reference or standard_cycle(limits)
    noise = noise_information(model, params, limits.grid.size, dt=limits.dt, free=free,
                              n_mc=n_mc_report, seed=seed + 1)[0]

    # noise levels the mean does not depend on: their ∂μ/∂θ is 0 on every program
    still = mean_free(model, params, limits.grid, case_temperature(
        ref.setpoint(limits.duration), limits), dt=limits.dt, free=free)

    def objective(case: np.ndarray) -> float:
        info, names = information(model, params, limits.grid, case, dt=limits.dt,
                                  free=free, noise=noise, still=still)
        return f_goal(info, names)

    prog, count = search(objective, limits, ref, starts=starts, maxfev=maxfev, seed=seed,
                         progress=progress, workers=workers)

    def report(p: Program) -> tuple[dict[str, float], float]:
        case = case_temperature(p.setpoint(limits.duration), limits)
        std, info, names = _information(model, params, case, limits, free, noise,
                                        n_mc_report, seed + 1)
        return std, float(f_goal(info, names))

    std, val = report(prog)
    ref_std, ref_val = report(ref)
    if not val < ref_val:  # never propose a program no better than the reference
        prog, std, val = ref, ref_std, ref_val
    return DesignResult(goal, prog, ref, std, ref_std, val, ref_val, count,
                        params={n: float(params[n]) for n in std},
                        doubt=tuple(doubt) if doubt else tuple(std))
