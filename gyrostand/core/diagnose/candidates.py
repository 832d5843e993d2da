"""Which effect is missing: refit with every candidate term, rank by likelihood ratio.

For a model M fitted by ML and every vocabulary term c not in M (whose requirements M
meets), M + c is fitted and compared with M (forward selection with likelihood-ratio
tests, as CTSM-R does for grey-box models):

    LR = 2 (ln L₁ − ln L₀) ~ χ²(df)      df = parameters c adds
    ΔAIC = −LR + 2 df,   ΔBIC = −LR + df ln n

Where the null value sits on the boundary of the parameter space (a noise intensity → 0)
the reference distribution is the 50:50 mixture ½χ²(0) + ½χ²(df) (Self & Liang 1987): the
p-value is halved. Where a parameter is not identified under the null (a time constant or
a second correlation time when the effect's amplitude is 0: Davies 1987) the supremum of
the LR over it exceeds χ²(df). A deterministic candidate with one coefficient and a shape
(``temp_rate.tau``, ``hysteresis.tau``/``w``, ``warmup.tau``: not identified when the
coefficient is 0) is tested calibrated: its LR, the supremum over the shape, is referred to
the supremum of a χ²(df) process over the shape's search range, df = its coefficients
(:func:`~.chisq.sup_chi2_sf`: the Euler characteristic tail, in one dimension Davies'
bound; the range's curvatures from the geometry of the efficient score process at the
current fit, :func:`shape_curvatures`). Counting the shapes in χ²(df) instead was off both ways: on
clean 2-h cycles hysteresis's LR averaged 3.5 against χ²(3)'s 3, while temp_rate's LR was
referred to χ²(2) where its tail is that of χ²(1) stretched by a lag range of length
~1.3–1.5. temp_rate's test fires at about twice its level on clean runs (its LR at a
fixed lag over-dispersed as β moves with it; holding β cost power on short runs:
benchmarks/results/false_alarm.txt). A deterministic candidate beside a random term of the
model that looks like it (a trend beside a random walk) is referred to its law simulated
under the current fit (:mod:`.simulated`). A joint diagnosis of several runs (a tuple of
:class:`Samples`) takes the same test, its geometry on the joint model, for a shape the
runs share; a per-run shape (a warm-up's τ, one process per run) keeps χ² with the shapes
counted. Other candidates with a parameter not identified under the null
(``temp_lag``'s τ, ``markov2``'s β₂) get one more degree of freedom and no halving: we
measured false alarms of ``temp_lag`` at 2 of 4 seeds with χ²(1)/2 when ``temp_rate`` is in
the model. ``Candidate.test`` names the reference distribution used; the df shown is the df used.
Candidates are ranked by ΔBIC, best first (BIC's ln n per parameter prefers the simpler of two
effects that fit alike — a trend over a warm-up with a very long time constant — where AIC would
not). A shape parameter with a plain shape (``Param.default``: no lag, the standard width) that the
data do not determine (at a search bound, or |estimate| < 2 std) is not counted in ΔAIC/ΔBIC: the
fit is then the term's plain shape, whose one coefficient is what it adds (as in Laplace's
approximation behind BIC, ln n per parameter is the price of a parameter the data pin down; one
they leave free costs ~nothing). ``Candidate.n_params`` is the count used. The verdict is
:mod:`.verdict`'s; the order of a deterministic and a random candidate that explain the
same failure, :mod:`.competitors`'.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

from ...errors import GyrostandError, IdentificationError
from ..chisq import chi2_sf, sup_chi2_sf
from ..data import Samples
from ..ml.cov import FLAT_WARNING
from ..ml.fit import ml
from ..ml.joint_problem import base_name
from ..ml.search import bound_warning
from ..model import Model
from ..results import FitResult
from ..terms.builtin import POSITIVE_KINDS, TERMS, separation, term_class
from ..threads import one_blas_thread, pool_width
from .reference import Reference, moved, second_start, whole_basis
from .results import (
    TEST_CHI2,
    TEST_CHI2_EXTRA,
    TEST_GUARD,
    TEST_MIXTURE,
    TEST_SIM,
    TEST_SUP,
    Candidate,
)
from .screen import Score, score_testable, score_tests, screenable, screened_candidate, to_refit
from .shapes import as_runs, shape_curvatures, shape_params
from .simulated import looks_random, simulated_p

log = logging.getLogger(__name__)
_DONE_LOCK = threading.Lock()

#: fewest observed samples a diagnosis judges (Ljung–Box lags, candidate refits)
MIN_DIAGNOSE_SAMPLES = 30
#: most threads the candidate refits run on (at most one per CPU this process may use)
MAX_THREADS = 4
#: ln L rise that shows the current fit was not at its maximum
REFIT_GAIN = 0.05
#: the test's null hypothesis and the look-alikes are facts of each term
#: (:attr:`~gyrostand.core.terms.base.Term.null`, ``look_alikes``): see :func:`extra_df`,
#: :func:`halved` and :func:`look_alikes`
FALLBACK_ADVICE = ("a profile with ramps of several rates in both directions, steps and "
                   "long soaks, repeated")


def candidate_terms(model: Model) -> list[str]:
    """Known terms (built-in and plugins) not in ``model`` that can be added to it."""
    have = set(model.names)
    return [t for t in TERMS if t not in have and all(r in have for r in TERMS[t].requires)]


def extra_df(term: str) -> int:
    """One more degree of freedom for a term with a parameter not identified under the
    null (Davies 1987): measured false alarms of ``temp_lag`` at 2 of 4 seeds without."""
    return 1 if term_class(term).null == "nuisance" else 0


def _determined(r: FitResult, name: str) -> bool:
    """Whether the data determine a shape parameter of the fit ``r``: inside its search
    range and known to better than half its value."""
    return name not in r.info.get("at_bound", ()) and abs(r.value(name)) >= 2.0 * r.std(name)


def halved(term: str) -> bool:
    """The null on the boundary of the parameter space: ½χ²(0) + ½χ²(df)."""
    return term_class(term).null == "boundary"


def refit(samples: Samples, model: Model, base: FitResult | None,
          also: Mapping[str, float] | None = None) -> FitResult:
    """ML fit of ``model`` from ``base`` where it shares parameters, and from ``base`` with
    ``also``'s values (the reference's random part: a fit whose random part absorbed a misfit
    is not the only start); no start grid, one local search, two where the term adds two
    shapes (a hysteresis refit's second basin won by up to 32 in ln L); runs fitted jointly.
    Where the noise levels the term adds end at 0 (the fit is ``base``'s), the Hessian is
    their own curvatures, the others' covariance ``base``'s (``ml``'s ``known``)."""
    start = base.values if base is not None else None
    if isinstance(samples, tuple):
        from ..ml.joint import joint_ml
        return joint_ml(samples, model, start=start,  # type: ignore[return-value]
                        n_local=2 if base is not None else None, hessian_passes=1)
    if start is None:
        return ml(samples, model, hessian_passes=1)
    shapes = sum(q.kind in POSITIVE_KINDS and n not in start for n, q in model.params)
    r = ml(samples, model, start=[start, {**start, **also}] if also else start,
           n_local=2 if shapes >= 2 else 1, hessian_passes=1, grid=False, known=base)
    new_levels = [n for n, q in model.params if q.kind == "std" and n not in start]
    if not shapes and new_levels:
        # a noise level alone (a random walk): from the current optimum its level, scanned
        # at the current β, can stop at 0 where the Markov process absorbed the walk (a 4-h
        # walk run, seed 511: LR 0; the walk's optimum, β 0.0106, q 0.0021, the truth
        # 0.01, 0.002: LR 6.46). So its profile likelihood at two levels too — the level
        # held, every other parameter refitted — and where the better beats the refit, a
        # free fit from there. Measured on 80 4-h runs (a walk, a lag + a walk with and
        # without temp_lag in the model, clean, warm-up + T²) against a search from ML's
        # whole start grid: the same optimum on 78 (511's walk among them), a higher one
        # on 2 (506 LR 3.86 and 507 LR 3.24 where the grid found 0), at 0.62 of its CPU
        best = r
        level = _level_scale(model, start)
        for n in new_levels:
            for ratio in PROFILE_LEVELS:
                try:
                    g = ml(samples, model, fixed={n: ratio * level}, start=start,
                           n_local=1, grid=False, std_errors=False)
                except IdentificationError:
                    continue
                assert g.loglik is not None and best.loglik is not None
                if g.loglik > best.loglik + GRID_GAIN:
                    best = g
        if best is not r:
            g = ml(samples, model, start=best.values, hessian_passes=1, grid=False,
                   known=base)
            assert g.loglik is not None and r.loglik is not None
            if g.loglik > r.loglik + GRID_GAIN:
                return g
    return r


#: a new noise level's profile points (:func:`refit`), as ratios to the current model's
#: reference noise level (the Markov process's σ): e^-6 and e^-3.5, where 4-h walk runs'
#: walks lie (q/σ 0.03-0.05 at q 1e-3-2e-3)
PROFILE_LEVELS = (float(np.exp(-6.0)), float(np.exp(-3.5)))
#: ln L a random walk's refit from its profile must gain over the refit from the current
#: optimum to replace it (above the searches' own tolerance)
GRID_GAIN = 1e-6


def _level_scale(model: Model, start: Mapping[str, float]) -> float:
    """The current model's reference noise level (the Markov process's σ, else its
    largest), which a new noise level's profile points are ratios of."""
    if start.get("markov.sigma", 0.0) > 0:
        return float(start["markov.sigma"])
    levels = [v for k, v in start.items() if k in model.param_names and model.kind(k) == "std"]
    return max([v for v in levels if v > 0], default=1.0)


def calibrated(samples: Samples | tuple[Samples, ...], model: Model, term: str) -> bool:
    """Whether ``term``'s candidate test is the calibrated supremum over its shape
    (:func:`shape_params`); on several runs only if the shape is the gyro's (shared by the
    runs: a per-run shape, a warm-up's τ, makes one process per run) or there is one
    run."""
    bigger = model.add(term)
    shapes = shape_params(bigger, term)
    if not shapes:
        return False
    return len(as_runs(samples)) == 1 or not any(
        getattr(bigger.term_of(n), "per_run", False) for n in shapes)


def _physical_at_bound(model: Model, r: FitResult, name: str) -> bool:
    """A shape parameter at a search bound where its shape is still physical (a thermal
    lag of a few Δt: none measurable; :class:`~gyrostand.core.terms.base.Param`'s
    ``physical_bounds``)."""
    q = dict(model.params)[base_name(name)]  # a run's own copy (name@k): its term's
    return any(bound_warning(name, side) in w for side in q.physical_bounds for w in r.warnings)


def identification(model: Model, r: FitResult, new: list[str]) -> tuple[bool, tuple[str, ...]]:
    """Whether the effect a candidate adds is identified, and which of its time constants
    or rates sit at a search bound (then the optimum is not an interior one; a shape
    parameter at a bound where its shape is still physical does not count)."""
    ok = True
    for k in new:
        e = r.parameters[k]
        if model.kind(base_name(k)) == "linear" and not abs(e.value) >= 2.0 * e.std:
            ok = False
    if not any(model.kind(base_name(k)) == "linear" for k in new):
        # an effect without a linear amplitude (a lag): its own parameter must be
        # determined to better than half its value
        for k in new:
            if model.kind(base_name(k)) == "time" and not abs(r.parameters[k].value) >= 2.0 * r.parameters[k].std:
                ok = False
    for w in r.warnings:
        if w.startswith(FLAT_WARNING) and any(k in w for k in new):
            ok = False
    bound = tuple(k for k in r.info.get("at_bound", ()) if k in new and
                  model.kind(base_name(k)) in POSITIVE_KINDS
                  and not _physical_at_bound(model, r, k))
    return ok, bound


def _refits(samples: Samples, model: Model, base: FitResult, terms: list[str],
            also: Mapping[str, float] | None = None,
            on_done: Callable[[str], None] | None = None,
            lkcs: Mapping[str, tuple[float, ...]] | None = None
            ) -> list[tuple[FitResult | None, GyrostandError | None, float,
                            tuple[float, ...]]]:
    """:func:`refit` of ``model + c`` for every candidate ``c``: (fit or None, the error
    that stopped it, seconds it took, the curvatures of its shape's range — ``()`` for a
    candidate without a calibrated shape, :func:`shape_curvatures`), in the order of
    ``terms``.

    The refits are independent: they run on a thread per CPU (at most
    :data:`MAX_THREADS`; the compiled filter releases the GIL), each the same computation
    whichever thread runs it, BLAS held to one thread (tiny matrices: see
    :func:`~gyrostand.core.ml.fit.ml`). ``lkcs``: curvatures already measured (by the
    score screen, :mod:`.screen`), by term."""
    def one(term: str) -> tuple[FitResult | None, GyrostandError | None, float,
                                tuple[float, ...]]:
        t0 = time.perf_counter()
        shaped = calibrated(samples, model, term)
        try:
            r = refit(samples, model.add(term), base, also)
        except GyrostandError as exc:
            return None, exc, time.perf_counter() - t0, ()
        seconds = time.perf_counter() - t0
        lkc: tuple[float, ...] = ()
        if lkcs is not None and term in lkcs:
            lkc = lkcs[term]
        elif shaped:
            lkc = shape_curvatures(samples, model, base, term)
        if on_done is not None:
            with _DONE_LOCK:
                on_done(term)
        return r, None, seconds, lkc

    # in a worker thread (a Dask task: one run per core already) one refit after another
    workers = min(len(terms), pool_width(MAX_THREADS))
    if workers <= 1:
        return [one(t) for t in terms]
    # the costliest first (more nonlinear parameters to search: a longer fit), so that the
    # threads finish together
    def searched(term: str) -> int:
        big = model.add(term)
        return sum(k not in model.param_names and big.kind(k) in ("rate", "time", "std")
                   for k in big.param_names)

    order = sorted(range(len(terms)), key=lambda i: -searched(terms[i]))
    with one_blas_thread(), \
            ThreadPoolExecutor(max_workers=workers, thread_name_prefix="refit") as pool:
        futures = {i: pool.submit(one, terms[i]) for i in order}
        return [futures[i].result() for i in range(len(terms))]


def rank_candidates(samples: Samples, model: Model, base: FitResult,
                    terms: list[str] | None = None,
                    also: Mapping[str, float] | None = None,
                    alpha: float = 0.05,
                    on_done: Callable[[str], None] | None = None,
                    screen: bool = True) -> list[Candidate]:
    """Refit ``model + c`` for each candidate ``c`` (started also from ``also``, see
    :func:`refit`); in :func:`ordered`'s order at ``alpha`` (Bonferroni over the
    candidates, as the verdict). ``on_done(term)``: called as each refit ends (a progress
    count; from the refits' threads, one call at a time). ``screen``: score-test the
    candidates first and refit only those the test cannot rule out (:mod:`.screen`);
    ``False`` refits them all."""
    n = base.n_observed
    out = []
    todo = list(terms if terms is not None else candidate_terms(model))
    # score-tested (and screened) only where the reference shows no lack of fit (``also``
    # None): see :mod:`.screen` for the misses measured otherwise
    scores = score_tests(samples, model, base, [t for t in todo if score_testable(
        samples, model, t)]) if not also else {}
    can_screen = {t: sc for t, sc in scores.items() if screenable(samples, model, t)}
    keep = to_refit(can_screen) if screen else set(can_screen)
    fitted = [t for t in todo if t not in can_screen or t in keep]
    for term in todo:
        if term not in fitted:
            out.append(screened_candidate(scores[term], base))
            if on_done is not None:
                on_done(term)
    # the curvatures of a shaped term's own LR (a modifier's chord has its own: not its LR's)
    lkcs = {t: sc.shape_lkc for t, sc in scores.items() if calibrated(samples, model, t)}
    for term, (r, exc, seconds, lkc) in zip(fitted, _refits(samples, model, base, fitted,
                                                            also, on_done, lkcs), strict=True):
        bigger = model.add(term)
        if r is None:
            log.warning("candidate %s could not be fitted: %s", term, exc)
            continue
        assert base.loglik is not None and r.loglik is not None
        lr = max(2.0 * (r.loglik - base.loglik), 0.0)
        added = len(r.parameters) - len(base.parameters)
        new = [k for k in r.parameters if k not in base.parameters]
        shapes = shape_params(bigger, term) if lkc else ()
        df, p, test = term_test(samples, model, base, r, term, lkc,
                                scores.get(term) if whole_basis(model) else None)
        # the parameters the fit uses: a shape parameter with a plain shape (its default:
        # no lag, the standard width) that the data do not determine (at a bound, or
        # flat) leaves the term that plain shape, and is not counted in ΔAIC/ΔBIC
        plain = [k for k in shapes if dict(bigger.params)[k].default is not None]
        used = added - sum(1 for k in plain if not _determined(r, k))
        stochastic = TERMS[term].n_states > 0
        ident, bound = identification(bigger, r, new) if not stochastic else (True, ())
        if stochastic:
            bound = tuple(k for k in r.info.get("at_bound", ()) if k in new and
                          bigger.kind(base_name(k)) == "rate")
        note = ""
        if bound:
            note = f"{', '.join(bound)} at a search bound: not ranked"
        elif not ident:
            note = "its effect is not identified (|estimate| < 2 std): not ranked"
        out.append(Candidate(
            term=term, lr_stat=lr, df=df, p_value=p, delta_aic=-lr + 2 * used,
            delta_bic=-lr + used * float(np.log(n)), rms_after=r.residual_rms,
            loglik_after=float(r.loglik), effect={k: r.parameters[k] for k in new},
            seconds=seconds, result=r, identified=ident, at_bound=bound,
            stochastic=stochastic, note=note, test=test, shape_lkc=lkc, n_params=used,
            traded=moved(model, base, r.values, also) if not stochastic else (),
            score_stat=scores[term].stat if term in scores else None,
            score_p=scores[term].p_value if term in scores else None,
        ))
    return ordered(out, alpha / max(len(out), 1))


def ordered(cands: list[Candidate], alpha_each: float) -> list[Candidate]:
    """The table's order, the criterion ``diagnose`` states: the significant candidates
    (ranked, p < ``alpha_each``) by ΔBIC, best first; then the other ranked ones, then the
    unranked ones, each by p. An insignificant candidate is never above a significant one
    (a 0-LR random walk on top of a table after a fit read as the best candidate)."""
    def key(c: Candidate) -> tuple[int, float, float]:
        if c.ranked and c.p_value < alpha_each:
            return 0, c.delta_bic, c.p_value
        return (1 if c.ranked else 2), c.p_value, c.delta_bic
    return sorted(cands, key=key)


def term_test(samples: Samples | tuple[Samples, ...], model: Model, base: FitResult,
              r: FitResult, term: str, lkc: tuple[float, ...] | None = None,
              score: Score | None = None) -> tuple[int, float, str]:
    """The test of ``model + term`` (its fit ``r``) against ``model`` (its fit ``base``):
    (df, p, the reference distribution's name), the one test a candidate gets in
    ``diagnose`` and a one-term step in ``fit`` and the ledger (one number, one meaning).
    ``lkc``: the curvatures of the term's shape range (:func:`shape_curvatures`) when
    already measured; computed here when the term's test is calibrated. ``score``: the
    term's score test at ``base`` (:func:`~.screen.score_tests`, taken where the model
    shows no lack of fit), which guards the LR's p (:func:`guarded`)."""
    return guarded(*_lr_test(samples, model, base, r, term, lkc), score)


def step_score(samples: Samples | tuple[Samples, ...], model: Model, base: FitResult,
               term: str, ref: Reference | None) -> Score | None:
    """The score test that guards ``term``'s LR against ``model`` (its fit ``base``, its
    saturated reference ``ref``) as ``diagnose`` takes it: one run, a score-testable term,
    a reference with its whole basis and no lack of fit at the report's level; else
    None."""
    if isinstance(samples, tuple) or not score_testable(samples, model, term) or \
            not whole_basis(model) or second_start(ref) is not None:
        return None
    return score_tests(samples, model, base, [term])[term]


def guarded(df: int, p: float, test: str, score: Score | None) -> tuple[int, float, str]:
    """The LR's test ``(df, p, test)`` guarded by the term's score test: p the larger of
    the two, :data:`~.results.TEST_GUARD` where the score's decides.

    Where the model fits (no lack of fit against its saturated reference), the LR of a
    term whose refit readjusts the random part overshoots its own law. Measured on 100
    clean 6-h runs from frames (seeds 1000-1099 of benchmarks/false_alarm.py): temp_rate's
    refit LR exceeded its score statistic by a median 0.2 and by 2.1 at the 95th
    percentile, with markov.beta moved by 0.85-1.26×, and its p < 0.05 on 10 runs and
    p < 0.05/8 on 4 (the score test's: 5 and 2); on a 4-h run that holds T² (advice
    seed 503) temp_rate's LR 11.7 (p 0.0023, significant) had a score of 4.3 (p 0.11),
    temp_lag's LR 10.4 (p 0.0056) a chord score of 3.8 (p 0.17): a chance pattern of the
    random part, added as an effect. The score test (the efficient score in the metric
    where the current parameters readjust, calibrated as the LR) is the size-correct
    one, and it sees a real effect where the model fits otherwise (4-h runs that hide
    one, no lack of fit: hysteresis's score 23.4, p 6e-5; trend's 20.4, p 6e-6). Under
    a lack of fit no score is taken (the current fit's random part has absorbed the
    misfit: :mod:`.screen`) and the LR's p stands; so too beside a random walk, whose
    reference has no time group (:func:`~.reference.whole_basis`) to show the slow misfit
    the walk absorbed (warm-up + T², advice seed 511: with the walk in, T²'s LR 8.4, p
    0.004, had a score p of 0.012 there — the true T², which the sequence adds before the
    warm-up and then drops the walk as redundant)."""
    if score is None or not score.p_value > p:
        return df, p, test
    return df, float(score.p_value), TEST_GUARD


def _lr_test(samples: Samples | tuple[Samples, ...], model: Model, base: FitResult,
             r: FitResult, term: str, lkc: tuple[float, ...] | None
             ) -> tuple[int, float, str]:
    assert base.loglik is not None and r.loglik is not None
    if lkc is None:
        lkc = (shape_curvatures(samples, model, base, term)  # type: ignore[arg-type]
               if calibrated(samples, model, term) else ())
    # parameters the candidate adds (a per-run one once per run in a joint fit)
    added = len(r.parameters) - len(base.parameters)
    lr = max(2.0 * (r.loglik - base.loglik), 0.0)
    shapes = shape_params(model.add(term), term) if lkc else ()
    if shapes:
        # the supremum of a χ² process over the shape (not identified under the null)
        df = added - len(shapes)
        return df, sup_chi2_sf(lr, df, lkc), TEST_SUP
    df = added + extra_df(term)
    p = chi2_sf(lr, df)
    sim = None if isinstance(samples, tuple) or not looks_random(model, term) else \
        simulated_p(samples, model, base, term, lr)  # beside a random look-alike
    if sim is not None:
        return df, sim, TEST_SIM
    if halved(term):
        return df, 0.5 * p, TEST_MIXTURE
    return df, p, TEST_CHI2_EXTRA if extra_df(term) else TEST_CHI2


def look_alikes(cands: list[Candidate], alpha_each: float) -> list[dict[str, Any]]:
    """Candidates that explain the data about as well as the best significant one (ΔAIC
    within max(4, 10 %)): the significant ones, and those significant and identified but
    not ranked because a shape parameter sits at a search bound (their fit is as good;
    only its shape is not pinned down), with that note."""
    sig = [c for c in cands if c.ranked and c.p_value < alpha_each]
    if not sig:
        return []
    best = min(sig, key=lambda c: c.delta_aic)
    near = [c for c in cands if c.p_value < alpha_each and c is not best and
            (c.ranked or (c.identified and c.at_bound and not c.stochastic))]
    out = []
    for c in near:
        if c.delta_aic - best.delta_aic < max(4.0, 0.1 * abs(best.delta_aic)):
            out.append({
                "terms": [best.term, c.term],
                "delta_aic": [best.delta_aic, c.delta_aic],
                "lr_stat": [best.lr_stat, c.lr_stat],
                "advice": separation(best.term, c.term) or FALLBACK_ADVICE,
                **({"note": c.note} if not c.ranked else {}),
            })
    return out


def refit_from_candidates(samples: Samples, model: Model, fit: FitResult,
                           cands: list[Candidate], alpha_each: float) -> FitResult | None:
    """The current model refitted from the optimum of each significant candidate whose
    effect is not identified, with that effect at zero: a better fit of the current model
    when its likelihood rises (the gain came from the current fit, not from the effect)."""
    assert fit.loglik is not None
    best = None
    for c in cands:
        if c.identified or c.p_value >= alpha_each or c.result is None:
            continue
        start = {k: v for k, v in c.result.values.items() if k in model.param_names}
        try:
            r = ml(samples, model, start=start)
        except GyrostandError:
            continue
        assert r.loglik is not None
        if r.loglik > fit.loglik + REFIT_GAIN and (best is None or r.loglik > (best.loglik or
                                                                                -np.inf)):
            best = r
    return best
