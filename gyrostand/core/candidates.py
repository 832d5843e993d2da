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
the LR over it exceeds χ²(df); we measured false alarms of ``temp_lag`` at 2 of 4 seeds
with χ²(1)/2 when ``temp_rate`` is in the model, so such candidates are tested
conservatively with one more degree of freedom and no halving. Candidates are ranked by
ΔBIC, best first (BIC's ln n per parameter prefers the simpler of two effects that fit
alike — a trend over a warm-up with a very long time constant — where AIC would not). The verdict is ``adequate`` when the innovations are white (Ljung–Box
p ≥ 0.01) and no candidate is significant at 5 % after a Bonferroni correction for the
number of candidates tried.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import GyrostandError
from .data import Samples
from .diagnostics import Diagnosis, diagnose_fit
from .ml import ml
from .model import Model
from .results import Estimate, FitResult
from .terms import TERMS, VOCABULARY

log = logging.getLogger(__name__)

#: candidates whose null hypothesis lies on the boundary (p-value halved)
BOUNDARY = {"random_walk"}
#: candidates with a parameter unidentified under the null: one more df in the p-value
NUISANCE = {"temp_lag", "markov2"}

#: what temperature profile tells two look-alike effects apart
SEPARATE = {
    frozenset({"temp_rate", "temp_lag"}):
        "a lag τ acts like −τ·γ·dT/dt during slow ramps; fast ramps or steps (faster than "
        "1/τ) followed by long soaks separate them: the lag keeps acting after the ramp "
        "ends, the rate term stops at once",
    frozenset({"temp_rate", "hysteresis"}):
        "both follow dT/dt; ramps of clearly different rates separate them: the rate term "
        "scales with the ramp rate, hysteresis does not",
    frozenset({"hysteresis", "temp_lag"}):
        "long soaks after each ramp separate them: a lag decays during the soak, "
        "hysteresis holds until the direction changes",
    frozenset({"temp2", "temp_lag"}):
        "visit the same temperatures while heating and while cooling (a symmetric cycle): "
        "a quadratic term is the same both ways, a lag is not",
    frozenset({"temp2", "hysteresis"}):
        "a symmetric heating/cooling cycle over the same range separates them",
    frozenset({"trend", "random_walk"}):
        "a longer run or repeated cycles: a trend keeps its rate, a random walk wanders",
    frozenset({"trend", "warmup"}):
        "a longer record after switch-on: the warm-up settles, the trend does not",
    frozenset({"warmup", "random_walk"}):
        "repeat the switch-on: a warm-up repeats, a random walk does not",
    frozenset({"markov2", "random_walk"}):
        "a longer run: a second Gauss–Markov process levels off at its σ₂, a random walk "
        "keeps growing",
}
FALLBACK_ADVICE = ("a profile with ramps of several rates in both directions, steps and "
                   "long soaks, repeated")


@dataclass(frozen=True)
class Candidate:
    """One candidate term, refitted."""

    term: str
    lr_stat: float
    df: int
    p_value: float
    delta_aic: float
    delta_bic: float
    rms_after: float
    loglik_after: float
    effect: dict[str, Estimate]
    seconds: float
    result: FitResult | None = field(default=None, compare=False, repr=False)

    def to_dict(self) -> dict[str, Any]:
        return {
            "term": self.term, "lr_stat": self.lr_stat, "df": self.df,
            "p_value": self.p_value, "delta_aic": self.delta_aic,
            "delta_bic": self.delta_bic, "rms_after": self.rms_after,
            "loglik_after": self.loglik_after,
            "effect": {k: {**e.to_dict(), "unit": e.unit} for k, e in self.effect.items()},
            "seconds": self.seconds,
        }


@dataclass(frozen=True)
class Report:
    """The diagnosis of a model on a data set: fit, residuals, ranked candidates, verdict."""

    model: Model
    fit: FitResult
    diagnosis: Diagnosis
    candidates: tuple[Candidate, ...]
    adequate: bool
    alpha: float
    look_alikes: tuple[dict[str, Any], ...]
    reasons: tuple[str, ...]

    @property
    def significant(self) -> list[Candidate]:
        m = max(len(self.candidates), 1)
        return [c for c in self.candidates if c.p_value < self.alpha / m]

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": list(self.model.names),
            "adequate": self.adequate,
            "reasons": list(self.reasons),
            "parameters": {k: e.to_dict() for k, e in self.fit.parameters.items()},
            "loglik": self.fit.loglik,
            "residual": {"rms": self.diagnosis.rms,
                         "ljung_box_p": self.diagnosis.ljung_box_p,
                         **self.diagnosis.to_dict()},
            "candidates": [c.to_dict() for c in self.candidates],
            "look_alikes": [dict(x) for x in self.look_alikes],
            "alpha": self.alpha,
            "warnings": list(self.fit.warnings),
        }


def candidate_terms(model: Model) -> list[str]:
    """Vocabulary terms not in ``model`` that can be added to it."""
    have = set(model.names)
    return [t for t in VOCABULARY
            if t not in have and all(r in have for r in TERMS[t].requires)]


def refit(samples: Samples, model: Model, base: FitResult | None) -> FitResult:
    """ML fit of ``model``, started from ``base`` where it shares parameters."""
    return ml(samples, model, start=base.values if base is not None else None,
              n_local=2 if base is not None else None)


def rank_candidates(samples: Samples, model: Model, base: FitResult,
                    terms: list[str] | None = None) -> list[Candidate]:
    """Refit ``model + c`` for each candidate ``c``; ranked best first (ΔBIC, then p)."""
    from scipy.stats import chi2  # here, not at the top: scipy.stats costs 0.5 s to import

    n = base.n_observed
    out = []
    for term in terms if terms is not None else candidate_terms(model):
        t0 = time.perf_counter()
        bigger = model.add(term)
        try:
            r = refit(samples, bigger, base)
        except GyrostandError as exc:
            log.warning("candidate %s could not be fitted: %s", term, exc)
            continue
        assert base.loglik is not None and r.loglik is not None
        df = len(bigger.param_names) - len(model.param_names)
        lr = max(2.0 * (r.loglik - base.loglik), 0.0)
        p = float(chi2.sf(lr, df + (1 if term in NUISANCE else 0)))
        if term in BOUNDARY:
            p *= 0.5
        new = [k for k in bigger.param_names if k not in model.param_names]
        out.append(Candidate(
            term=term, lr_stat=lr, df=df, p_value=p, delta_aic=-lr + 2 * df,
            delta_bic=-lr + df * float(np.log(n)), rms_after=r.residual_rms,
            loglik_after=float(r.loglik), effect={k: r.parameters[k] for k in new},
            seconds=time.perf_counter() - t0, result=r,
        ))
    out.sort(key=lambda c: (c.delta_bic, c.p_value))
    return out


def look_alikes(cands: list[Candidate], alpha_each: float) -> list[dict[str, Any]]:
    """Significant candidates that explain the data about as well as the best one."""
    sig = [c for c in cands if c.p_value < alpha_each]
    if len(sig) < 2:
        return []
    best = min(sig, key=lambda c: c.delta_aic)
    out = []
    for c in sig:
        if c is best:
            continue
        if c.delta_aic - best.delta_aic < max(4.0, 0.1 * abs(best.delta_aic)):
            pair = frozenset({best.term, c.term})
            out.append({
                "terms": [best.term, c.term],
                "delta_aic": [best.delta_aic, c.delta_aic],
                "advice": SEPARATE.get(pair, FALLBACK_ADVICE),
            })
    return out


def diagnose(samples: Samples, model: Model, *, base: FitResult | None = None,
             alpha: float = 0.05, terms: list[str] | None = None) -> Report:
    """Fit ``model`` by ML (unless ``base`` is given), diagnose it, rank the candidates."""
    fit = base if base is not None else ml(samples, model)
    diag = diagnose_fit(fit, samples)
    cands = rank_candidates(samples, model, fit, terms)
    m = max(len(cands), 1)
    alpha_each = alpha / m
    reasons = []
    if not diag.white:
        reasons.append(f"innovations are not white (Ljung–Box p = {diag.ljung_box_p:.2g} "
                       f"over {diag.lags} lags)")
    sig = [c for c in cands if c.p_value < alpha_each]
    if sig:
        reasons.append(f"{', '.join(c.term for c in sig)} significant at {alpha:g} "
                       f"(Bonferroni over {m} candidates: p < {alpha_each:.2g})")
    return Report(model=model, fit=fit, diagnosis=diag, candidates=tuple(cands),
                  adequate=not reasons, alpha=alpha,
                  look_alikes=tuple(look_alikes(cands, alpha_each)), reasons=tuple(reasons))
