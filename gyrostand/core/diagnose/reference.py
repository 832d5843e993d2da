"""A reference the misfit cannot move: the current model beside a saturated one.

The fitted random part of a model absorbs what its deterministic part misses (a Markov σ
that grows, a β that shrinks), so every check judged against that random part — the
model-error floor, whiteness, a candidate's LR — certifies the wrong model. The
*reference* is the classical lack-of-fit test's "pure error": the current model with a
deliberately rich deterministic part added (:func:`reference_basis`), fitted by exact ML
with the same noise model:

* **temperature** — Legendre polynomials P₂…P_K of the scaled temperature, entering the
  drift's dynamics as the temperature does (``temp``: through the Markov state), K sized
  by the range the profile covers (one degree per :data:`DEGC_PER_DEGREE`, at most
  :data:`MAX_T_DEGREE`), and a piecewise-linear response at the output with a knot every
  :data:`DEGC_PER_KNOT` (a step, a kink); P₀ (an offset) when the model has no ``bias``;
* **temperature rate** — dT/dt and its first-order lag by :data:`RATE_LAG_FRACTION` of the
  record, each linear and as a switch ``tanh(rate / w)`` (a rate effect, a hysteresis, a
  lagged temperature: all are functions of these), and dT/dt through the drift's dynamics;
* **time since switch-on** — t and exp(−t/τ) for τ at :data:`WARMUP_FRACTIONS` of the
  record (a trend, a warm-up).

Its fit gives what the data allow whatever the vocabulary holds: the random part (the
floor's, :func:`~.prederror.model_error`'s ``noise``), the lack-of-fit likelihood ratio
``LR = 2 (ln L_ref − ln L)`` on ``df`` = the rank the basis adds (χ²(df): the basis enters
linearly and its coefficients are interior), and each group's *partial effect* with bands
— the static effect of a soak at T, of a steady ramp at rate r, and of the time since
switch-on — which shows the shape that is missing (:class:`Partial`).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..chisq import chi2_sf
from ..data import Samples
from ..ml.fit import ml
from ..model import Model, context
from ..results import FitResult
from ..terms.base import HYSTERESIS_RATE, Context, Param, Term
from .partials import Partial, partial_effects, rank

#: °C of temperature range per Legendre degree of the temperature basis (above P₁)
DEGC_PER_DEGREE = 8.0
#: °C of temperature range per interval of the output's piecewise-linear response to T
DEGC_PER_KNOT = 5.0
#: most interior knots of it
MAX_KNOTS = 5
#: highest Legendre degree of the temperature basis
MAX_T_DEGREE = 5
#: the lagged rate's time constant, as a fraction of the record (at most MAX_RATE_LAG_S)
RATE_LAG_FRACTION = 0.05
MAX_RATE_LAG_S = 900.0
#: warm-up time constants of the time basis, as fractions of the record
WARMUP_FRACTIONS = (0.03, 0.15)
#: a profile whose temperature spans less than this (°C) has no temperature basis
MIN_T_SPAN = 1.0
#: a profile whose fastest rate is below this (°C/s: 0.05 °C/min) has no rate basis
MIN_RATE = 0.05 / 60.0
#: level of the lack-of-fit test in the verdict. 0.001 while its calibration is open: at
#: 0.01 a hidden hysteresis, added with its shape fitted (τ at its bound), still showed a
#: lack of fit (p 0.002 refitted, 0.005 at the fit's random part with the tangents) on
#: one of ten seeds, where a step above 40 °C outside the vocabulary gave p 0.0045
LACK_OF_FIT_ALPHA = 0.001
#: level at which the diagnosis reports the lack of fit and its shape (not a verdict)
REPORT_ALPHA = 0.01
#: the reference's LR over its χ²(df) mean on clean runs (its random part refitted
#: trades low frequencies against the basis): 1.13, 1.05, 1.03 on 30, 30, 24 clean 2-,
#: 4-, 6-h chamber cycles; the test refers LR / this to χ²(df)
FREE_LR_SCALE = 1.15
#: step (in ln of the value) of the model's tangent along a held shape parameter
TANGENT_STEP = 1e-3
#: a random-part parameter more than this many of its stds from the reference's was
#: moved by the misfit (:meth:`Reference.traded`)
TRADE_STD = 3.0
#: the reference term's name in its model (not a vocabulary term: never a candidate)
NAME = "reference"


@dataclass(frozen=True)
class Column:
    """One column of the basis: its parameter's short name, group, and how it is built."""

    name: str
    group: str
    doc: str
    through_drift: bool  # enters dε/dt (filtered by the Markov state) rather than the output


class ReferenceBasis(Term):
    """The saturated deterministic part, built for one record by :func:`reference_basis`
    (a subclass per record: its columns depend on the profile). Not registered: it is
    never a candidate, a summary bit or a term of a user's model."""

    name = NAME
    role = "output"
    math = "+ Σ θ_j B_j(T, dT/dt, t): a saturated deterministic part"
    no_signature = "the reference's basis: judged as a whole by the lack-of-fit test"
    columns: tuple[Column, ...] = ()
    t_mid: float = 0.0
    t_half: float = 1.0
    rate_lag: float = 0.0
    width: float = HYSTERESIS_RATE
    taus: tuple[float, ...] = ()
    rate_scale: float = 1.0
    knots: tuple[float, ...] = ()
    tangents: dict[str, np.ndarray] = {}

    def x(self, T: np.ndarray) -> np.ndarray:
        return (np.asarray(T, dtype=float) - self.t_mid) / self.t_half

    def raw(self, ctx: Context) -> dict[str, np.ndarray]:
        """Every column before the drift's dynamics, keyed by short name: computed once a
        record (kept with ``ctx``'s data, read-only; the fit asks at each of its ~40
        evaluations, 2.7 ms each on a 6-h run: Legendre polynomials, tanh, exp)."""
        kept = ctx._cache.setdefault("reference_raw", {})
        out = kept.get(type(self))
        if out is None:
            out = kept[type(self)] = self._raw(ctx)
            for v in out.values():
                v.flags.writeable = False
        return out

    def _raw(self, ctx: Context) -> dict[str, np.ndarray]:
        t = ctx.t - ctx.t[0]
        out: dict[str, np.ndarray] = {}
        x = self.x(ctx.temp)
        rates = {"r0": ctx.temp_rate, "rL": ctx.lagged_rate(self.rate_lag)}
        for c in self.columns:
            if c.group == "tangent":
                continue
            if c.name.startswith("K"):
                out[c.name] = np.maximum(ctx.temp - self.knots[int(c.name[1:])], 0.0) / self.t_half
            elif c.group == "temperature":
                deg = int(c.name[1:])
                out[c.name] = np.polynomial.legendre.legval(x, [0] * deg + [1])
            elif c.name in ("r0", "rL"):
                out[c.name] = rates[c.name] / self.rate_scale
            elif c.name in ("s0", "sL"):
                out[c.name] = np.tanh(rates["r" + c.name[1]] / self.width)
            elif c.name == "rin":
                out[c.name] = rates["r0"] / self.rate_scale
            elif c.name == "trend":
                out[c.name] = t / max(t[-1], 1.0)
            else:  # e<k>: a warm-up
                out[c.name] = np.exp(-t / self.taus[int(c.name[1:])])
        return out

    def regressors(self, p, ctx: Context) -> dict[str, np.ndarray]:
        raw = self.raw(ctx)
        beta = p.get("markov.beta")
        out = {self.key(n): v for n, v in self.tangents.items()}
        for c in self.columns:
            if c.group == "tangent":
                continue
            u = raw[c.name]
            out[self.key(c.name)] = (ctx.through_markov(u, beta) if c.through_drift
                                     and beta is not None else u)
        return out


def whole_basis(model: Model) -> bool:
    """Whether ``model``'s reference holds every group of its basis: a random walk in the
    model is the record's slow course in time, and the time group is left out beside it
    (:func:`reference_basis`), so a slow deterministic misfit the walk absorbed shows in
    no lack of fit there."""
    return "random_walk" not in model.names


def second_start(ref: Reference | None) -> dict[str, float] | None:
    """The reference's random part as a second start of the candidate refits, where it
    differs from the fit's (a lack of fit at the reporting level, :data:`REPORT_ALPHA`);
    None where there is none — then the candidates are score-tested at the fit
    (:mod:`.screen`, :func:`~.candidates.guarded`)."""
    if ref is None or ref.fit is None or not ref.p_value < REPORT_ALPHA:
        return None
    return {n: float(ref.fit.values[n]) for n in ref.noise_names}


def misfit_floor(ref: Reference | None, current: FitResult) -> Reference | None:
    """``ref`` with its own random part as the floor's, where a significant candidate shows
    the misfit the lack-of-fit test alone did not (its 17-25 df dilute one effect) and
    that misfit moved the ``current`` fit's random part (:func:`moved`: beyond ±3 of its
    std from the reference's); None where the floor stays as it is.

    The current fit's random part stands in for the floor's only while nothing shows a
    misfit (the reference's is biased low on clean runs: σ 9 %). Measured on 4-h runs of a
    hidden trend (1e-5 deg/h/s) with a lack of fit of p 0.001-0.03: markov.sigma 0.056-0.060
    against the reference's 0.045-0.051, so the floor rose with the error (0.051-0.056
    against 0.036-0.039 where the test saw the misfit) and the headline said "unexplained 0"
    beside a significant trend."""
    if ref is None or ref.fit is None or ref.traded:
        return None
    traded = moved(current.model, current, ref.fit.values)
    if not traded:
        return None
    return replace(ref, noise_model=ref.model, noise=dict(ref.fit.values), traded=traded)


def reference_basis(samples: Samples, model: Model) -> type[ReferenceBasis]:
    """The basis for this record and model, sized by the record's length and the
    profile's coverage: a :class:`ReferenceBasis` subclass."""
    ctx = context(samples, None)
    T = np.asarray(samples.temp, dtype=float)
    ok = np.isfinite(T)
    lo, hi = (float(np.min(T[ok])), float(np.max(T[ok]))) if ok.any() else (0.0, 0.0)
    duration = float(samples.t[-1] - samples.t[0]) if len(samples) else 0.0
    drift = "markov" in model.names
    cols: list[Column] = []
    if not {"bias"} & set(model.names):
        cols.append(Column("P0", "temperature", "an offset", False))
    span = hi - lo
    knots: tuple[float, ...] = ()
    if span >= MIN_T_SPAN:
        top = min(MAX_T_DEGREE, 1 + max(1, int(span // DEGC_PER_DEGREE)))
        cols += [Column(f"P{d}", "temperature", f"Legendre P{d} of the scaled T", drift)
                 for d in range(2, top + 1)]
        n_int = int(min(MAX_KNOTS + 1, max(2, span // DEGC_PER_KNOT)))
        knots = tuple(lo + span * (i + 1) / n_int for i in range(n_int - 1))
        cols += [Column(f"K{i}", "temperature", f"(T − {k:.1f} °C)₊ at the output", False)
                 for i, k in enumerate(knots)]
    rate = np.abs(ctx.temp_rate) if len(samples) > 1 else np.zeros(1)
    fastest = float(np.max(rate)) if rate.size else 0.0
    lag = min(MAX_RATE_LAG_S, RATE_LAG_FRACTION * duration)
    if fastest >= MIN_RATE:
        cols += [Column("r0", "rate", "dT/dt", False),
                 Column("s0", "rate", "tanh(dT/dt / w)", False)]
        if lag >= 10 * samples.dt:
            cols += [Column("rL", "rate", f"dT/dt lagged by {lag:.0f} s", False),
                     Column("sL", "rate", f"tanh of dT/dt lagged by {lag:.0f} s", False)]
        if drift:
            cols.append(Column("rin", "rate", "dT/dt into dε/dt", True))
    taus = tuple(f * duration for f in WARMUP_FRACTIONS if f * duration >= 10 * samples.dt)
    # a random walk in the model is the record's slow course in time: smooth functions of t
    # beside it take its realised path (measured: a hidden walk, once fitted, left 'time'
    # Wald 102 and a floor of 0.041 against an open-loop error of 0.13: NOT ADEQUATE)
    if not whole_basis(model):
        taus = ()
    elif duration > 0:
        cols.append(Column("trend", "time", "t / record", False))
        cols += [Column(f"e{i}", "time", f"exp(−t / {tau:.0f} s)", False)
                 for i, tau in enumerate(taus)]
    attrs = {
        "params": tuple(Param(c.name, "linear", "y", c.doc) for c in cols),
        "columns": tuple(cols),
        "t_mid": 0.5 * (lo + hi), "t_half": max(0.5 * span, 1e-9),
        "rate_lag": lag if lag >= 10 * samples.dt else 0.0,
        "width": max(HYSTERESIS_RATE, 0.05 * fastest),
        "taus": taus, "rate_scale": max(fastest, 1e-12),
        "knots": knots,
    }
    return type("ReferenceBasis_", (ReferenceBasis,), attrs)


@dataclass(frozen=True)
class Reference:
    """The saturated reference beside a fit (:func:`reference_fit`).

    ``lr``/``df``/``p_value``: the lack-of-fit test; ``partial``: each group's partial
    effect; ``fit``: the reference's exact ML fit with its own random part; ``noise``: the
    random part the floors are drawn from (the reference's where ``traded`` names what the
    misfit moved, else the current fit's)."""

    model: Model
    basis: type[ReferenceBasis]
    lr: float
    df: int
    p_value: float
    alpha: float
    partial: tuple[Partial, ...]
    noise_model: Model
    noise: dict[str, float]
    fit: FitResult | None = None
    traded: tuple[str, ...] = ()
    lr_fixed: float = 0.0
    noise_names: tuple[str, ...] = ()
    seconds: float = 0.0

    @property
    def significant(self) -> bool:
        """Whether the lack of fit is significant at the reference's level ``alpha``."""
        return self.df > 0 and self.p_value < self.alpha

    @property
    def reported(self) -> bool:
        """Whether the lack of fit is significant at :data:`REPORT_ALPHA` (its shape shown)."""
        return self.df > 0 and self.p_value < REPORT_ALPHA

    def missing(self) -> list[Partial]:
        """The groups whose partial effect is significant, largest first."""
        sig = [q for q in self.partial if q.significant]
        return sorted(sig, key=lambda q: -q.wald / max(q.df, 1))

    def to_dict(self) -> dict[str, Any]:
        return {"lr": self.lr, "lr_at_fit_noise": self.lr_fixed,
                "scale": FREE_LR_SCALE, "df": self.df, "p_value": self.p_value, "alpha": self.alpha,
                "significant": self.significant,
                "loglik": self.fit.loglik if self.fit is not None else None,
                "noise": dict(self.noise), "traded": list(self.traded),
                "columns": [c.name for c in self.basis.columns],
                "partial": [q.to_dict() for q in self.partial], "seconds": self.seconds}


def _tangent(model: Model, p, samples: Samples, name: str, ctx: Context | None = None,
             theta: np.ndarray | None = None) -> np.ndarray:
    """The model's own freedom near its fit: d(Xθ)/d ln η along the shape η ``name``."""
    ctx = ctx if ctx is not None else context(samples, model)
    if theta is None:
        theta = np.array([p[n] for n in model.names_of_kind("linear")])
    hi, lo = dict(p), dict(p)
    hi[name], lo[name] = p[name] * np.exp(TANGENT_STEP), p[name] * np.exp(-TANGENT_STEP)
    d = (model.regressors(hi, ctx) - model.regressors(lo, ctx)) @ theta
    return d / (2 * TANGENT_STEP)


def _whitened(model: Model, p, samples: Samples, tangents: Mapping[str, np.ndarray]
              ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The regressors and the drift through the model's Kalman filter at ``p``, scaled by
    1/√f (observed rows), and the regressors' names: the GLS design. With a column per
    held shape parameter (``tangent:<name>``, ``tangents``' :func:`_tangent`): the
    derivative of the model's deterministic part along it."""
    X = model.regressors(p, context(samples, model))
    names = list(model.names_of_kind("linear"))
    if tangents:
        X = np.column_stack([X, *tangents.values()])
        names += [f"tangent:{n}" for n in tangents]
    E, f = model.filter_columns(p, samples, X)
    ok = np.isfinite(E[:, 0]) & (f > 0)
    w = 1.0 / np.sqrt(f[ok])
    return E[ok, 1:] * w[:, None], E[ok, 0] * w, names


def _noise_names(model: Model) -> list[str]:
    return [n for n in model.param_names if model.term_of(n).role in ("process", "noise")]


def moved(model: Model, base: FitResult, values: Mapping[str, float],
          towards: Mapping[str, float] | None = None, k: float = TRADE_STD
          ) -> tuple[str, ...]:
    """The random-part parameters of ``model`` whose value in ``values`` lies beyond ±``k``
    of their std in ``base``, unless closer than ``base``'s to ``towards`` (the reference's:
    a move towards it undoes a misfit's inflation)."""
    t = towards or {}
    return tuple(n for n in _noise_names(model) if n in values
                 and 0 < base.parameters[n].std * k < abs(values[n] - base.parameters[n].value)
                 and not (n in t and abs(values[n] - t[n]) < abs(base.parameters[n].value - t[n])))


def reference_fit(samples: Samples, model: Model, current: FitResult,
                  alpha: float = LACK_OF_FIT_ALPHA) -> Reference:
    """The saturated reference of ``model`` on ``samples`` beside the ``current`` fit.

    The reference is fitted by exact ML with its random part free (the model's shapes
    held, started at the current fit and the basis's GLS estimate). The lack-of-fit LR
    is 2 (ln L_ref − ln L), at least the GLS one at the current fit's random part with the
    model's tangents along its held shapes; LR / :data:`FREE_LR_SCALE` is referred to
    χ²(df), df the rank the basis adds. (At the current fit's random part alone the test
    is exact given the noise, but a misfit inflates that noise and hides itself: a step
    of 0.4 deg/h above 40 °C gave p 0.02 there, σ 0.078 against the reference's 0.056.)
    When the lack of fit is significant and the misfit moved the current fit's random
    part (``traded``: parameters beyond ±:data:`TRADE_STD` of their std from the
    reference's), the reference's random part is the floor's; otherwise the current fit's
    is (the reference's, with its extra columns, is biased low: σ 9 % on clean 4-h runs)
    until a significant candidate shows the misfit (:func:`misfit_floor`, the diagnosis)."""
    t0 = time.perf_counter()
    basis = reference_basis(samples, model)
    term = basis()
    ref_model = Model(model.terms + (term,))
    p = dict(current.values)
    p.update({term.key(c.name): 0.0 for c in basis.columns})
    noise_names = _noise_names(model)
    # the shapes of the model's deterministic terms (a lag, a width, a warm-up's τ) are
    # held at the current fit, with the model's tangent along each beside its columns:
    # the test is of what the model cannot do near its fit (a shape at a search bound or
    # a little off its optimum would otherwise count as lack of fit: hidden hysteresis,
    # its τ at the bound, LR averaged 15.2 on 12 df without the tangents)
    shapes = [n for n, q in model.params if q.kind != "linear" and n not in noise_names]
    # each held shape's tangent, once (the basis does not move with the model's shapes)
    tangents = {n: _tangent(model, current.values, samples, n) for n in shapes}
    W, wy, names = _whitened(ref_model, p, samples, tangents)
    own = [i for i, n in enumerate(names) if not n.startswith(NAME + ".")]
    rss_cur = float(np.sum((wy - W[:, own] @ np.linalg.lstsq(W[:, own], wy,
                                                              rcond=1e-12)[0]) ** 2))
    theta, *_ = np.linalg.lstsq(W, wy, rcond=1e-12)
    rss_ref = float(np.sum((wy - W @ theta) ** 2))
    lr_fixed = max(rss_cur - rss_ref, 0.0)
    df = rank(W) - rank(W[:, own])
    p.update({n: float(v) for n, v in zip(names, theta, strict=True)
              if n.startswith(NAME + ".")})
    basis0, ref_model0 = basis, ref_model
    # the reference by exact ML, its random part free, the model's shapes held (free, with
    # the basis beside them, a hidden hysteresis added gave LR 29.4 on 12 df) and their
    # tangents as fixed columns; started at the current fit and the GLS basis
    tan = {f"T_{n.replace('.', '_')}": v for n, v in tangents.items()}
    if tan:
        cols = basis.columns + tuple(Column(k, "tangent", "the model's tangent", False)
                                     for k in tan)
        basis = type("ReferenceBasis_", (basis,), {
            "columns": cols, "tangents": tan,
            "params": basis.params + tuple(Param(k, "linear", "y", "tangent") for k in tan)})
        ref_model = Model(model.terms + (basis(),))
    start = {k: v for k, v in p.items() if not k.startswith("tangent:")}
    start.update({basis().key(k): 0.0 for k in tan})
    # from that start alone (no start grid: the current fit is a whole search's optimum;
    # measured on 16 hidden-effect and clean 4-h runs and the 6-h run of
    # benchmarks/diagnose_speed.py, the same optimum as with the grid, 0.06-0.13 s less)
    fit = ml(samples, ref_model, start=start,
             fixed={n: float(current.values[n]) for n in shapes}, n_local=1,
             std_errors=False, grid=False)
    assert fit.loglik is not None and current.loglik is not None
    lr = max(2.0 * (fit.loglik - current.loglik), lr_fixed)
    pv = chi2_sf(lr / FREE_LR_SCALE, df) if df > 0 else 1.0
    traded: tuple[str, ...] = ()
    noise_model, noise = model, {n: float(current.values[n]) for n in noise_names}
    if df > 0 and pv < alpha:
        traded = moved(model, current, fit.values)
    if traded:
        noise_model, noise = ref_model, dict(fit.values)
    # the partial effects by GLS at the random part the floors use: the reference's when
    # the misfit moved the fit's (at the fit's, inflated by the misfit, a cubic in T with
    # a lack of fit LR 96 on 17 df showed no group: the temperature's Wald 4.7 on 7 df;
    # at the reference's 435 on 9), its Wald then referred as the LR is (/ FREE_LR_SCALE:
    # the basis trades with the random part's low frequencies)
    # (not traded: the first GLS's design and estimate, already in W and p)
    at = p
    if traded:
        at = {**p, **{n: float(fit.values[n]) for n in noise_names}}
        W, wy, names = _whitened(ref_model0, at, samples, tangents)
        theta, *_ = np.linalg.lstsq(W, wy, rcond=1e-12)
        at.update({n: float(v) for n, v in zip(names, theta, strict=True)
                   if n.startswith(NAME + ".")})
    partial = partial_effects(basis0(), at, W, wy, names, samples,
                              FREE_LR_SCALE if traded else 1.0)
    return Reference(model=ref_model, basis=basis, lr=lr, df=df, p_value=pv, alpha=alpha,
                     partial=partial, noise_model=noise_model, noise=noise, fit=fit,
                     lr_fixed=lr_fixed, noise_names=tuple(noise_names),
                     traded=traded, seconds=time.perf_counter() - t0)
