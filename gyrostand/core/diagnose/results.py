"""What a diagnosis reports: each candidate term's test (:class:`Candidate`) and the
diagnosis of a model on a data set (:class:`DiagnoseResult`), with the reference distributions a
candidate's likelihood ratio is judged by (``Candidate.test``)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..model import Model
from ..results import Estimate, FitResult
from ..summary import DRIFT_UNIT, unit_text
from .diagnostics import ResidualDiagnostics
from .prederror import ModelError
from .reference import Reference

if TYPE_CHECKING:
    from .periodic import Periodic
    from .repeats import Repeats
    from .shift import LevelShift


@dataclass(frozen=True)
class Candidate:
    """One candidate term, refitted.

    ``df`` is the degrees of freedom of the p-value, ``test`` its reference distribution
    (:data:`TEST_CHI2` χ²(df), df the parameters the term adds; :data:`TEST_CHI2_EXTRA`
    one more for a parameter not identified under the null; :data:`TEST_MIXTURE` the
    boundary mixture; :data:`TEST_SUP` the supremum of a χ²(df) process over the shape,
    df its coefficients, ``shape_lkc`` the curvatures of the shape's range;
    :data:`TEST_GUARD` the score test's p, larger than the LR's by its law).
    ``n_params`` is the count of parameters in ΔAIC/ΔBIC. A candidate is *ranked* — can be
    significant — only when its own effect is identified (``identified``: every linear
    parameter it adds has |estimate| ≥ 2 std and no flat direction involves it) and no
    time constant or rate of it sits at a search bound (``at_bound``). ``stochastic`` marks
    a random process (markov2, random_walk); ``competes`` names the candidate of the other
    kind that explains the same failure (``tied``: and this record cannot rank the two:
    neither is significant given the other, a second run of the gyro decides),
    ``note`` says why one is not ranked, ``traded``
    names the random-part parameters its refit moved beyond ±3 std (the effect traded
    against the random part rather than explaining a failure of the deterministic one).
    ``score_stat``/``score_p``: its score (LM) test at the current fit (:mod:`.screen`;
    temp_lag's by its chord), taken where the model shows no lack of fit against its
    saturated reference, one run; ``None`` otherwise and for a random process. Where it is
    taken ``p_value`` is the larger of the LR's and the score's
    (:func:`~.candidates.guarded`). ``screened``: ruled out by that test and not
    refitted (then ``lr_stat``, ``df``, ``p_value`` and ΔAIC/ΔBIC are the LM test's,
    ``effect`` is empty and the candidate is not ranked); ``stand_in``: a random process
    standing in for a deterministic misfit of temperature that the saturated reference
    shows (:mod:`.standin`: not ranked, ``note`` says why). ``repeats``: on several runs,
    whether its effect repeats across them (:mod:`.repeats`; None: not tested); one that
    does not is not ranked.
    """

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
    identified: bool = True
    at_bound: tuple[str, ...] = ()
    stochastic: bool = False
    competes: str | None = None
    note: str = ""
    test: str = "chi2"
    shape_lkc: tuple[float, ...] = ()
    n_params: int | None = None
    traded: tuple[str, ...] = ()
    score_stat: float | None = None
    score_p: float | None = None
    screened: bool = False
    stand_in: bool = False
    tied: bool = False
    repeats: Repeats | None = None

    @property
    def ranked(self) -> bool:
        return (self.identified and not self.at_bound and not self.screened
                and not self.stand_in and (self.repeats is None or self.repeats.repeats))

    def to_dict(self, drift_unit: str = DRIFT_UNIT) -> dict[str, Any]:
        return {
            "term": self.term, "lr_stat": self.lr_stat, "df": self.df,
            "p_value": self.p_value, "delta_aic": self.delta_aic,
            "delta_bic": self.delta_bic, "rms_after": self.rms_after,
            "loglik_after": self.loglik_after,
            "effect": {k: {**e.to_dict(), "unit": unit_text(e.unit, drift_unit)}
                       for k, e in self.effect.items()},
            "seconds": self.seconds, "ranked": self.ranked, "identified": self.identified,
            "at_bound": list(self.at_bound), "stochastic": self.stochastic,
            "competes": self.competes, "note": self.note, "test": self.test,
            "shape_lkc": list(self.shape_lkc), "n_params": self.n_params,
            "traded": list(self.traded),
            "score_stat": self.score_stat, "score_p": self.score_p,
            "screened": self.screened, "stand_in": self.stand_in, "tied": self.tied,
            # several runs only (one run's JSON keeps its keys)
            **({"repeats": self.repeats.to_dict()} if self.repeats is not None else {}),
        }


def p_text(p: float) -> str:
    """A p-value as the diagnosis prints it: two digits, or ``< 1e-300`` below them (the
    lack of fit, the level shift, the periodic line)."""
    return f"{p:.2g}" if p >= 1e-300 else "< 1e-300"


def significant(cands: Sequence[Candidate], alpha: float) -> list[Candidate]:
    """The ranked candidates of ``cands`` significant at ``alpha`` after Bonferroni over
    them all, in their order (one run's diagnosis and several runs' alike)."""
    each = alpha / max(len(cands), 1)
    return [c for c in cands if c.ranked and c.p_value < each]


@dataclass(frozen=True)
class DiagnoseResult:
    """The diagnosis of a model on a data set: fit, residuals, ranked candidates, verdict."""

    model: Model
    fit: FitResult
    diagnosis: ResidualDiagnostics
    candidates: tuple[Candidate, ...]
    adequate: bool
    alpha: float
    look_alikes: tuple[dict[str, Any], ...]
    reasons: tuple[str, ...]
    model_error: ModelError | None = None
    notes: tuple[str, ...] = ()
    unit: str = DRIFT_UNIT
    reference: Reference | None = field(default=None, compare=False)
    #: terms of an adequate model that no longer earn their place
    #: (:func:`~.verdict.redundant_terms`): ``fit --remove`` them
    redundant: tuple[dict[str, Any], ...] = ()
    #: the largest level shift against the reference (:mod:`.shift`; one run only)
    level_shift: LevelShift | None = field(default=None, compare=False)
    #: the innovations' strongest periodic line against the reference (:mod:`.periodic`)
    periodic: Periodic | None = field(default=None, compare=False)

    @property
    def significant(self) -> list[Candidate]:
        """Ranked candidates significant after Bonferroni, in the order proposed."""
        return significant(self.candidates, self.alpha)

    @property
    def tie(self) -> tuple[str, str] | None:
        """The candidate proposed first and its competitor when this record ties them
        (:attr:`Candidate.tied`: a second run of the gyro tells them apart), else None."""
        sig = self.significant
        if sig and sig[0].tied and sig[0].competes:
            return sig[0].term, sig[0].competes
        return None

    @property
    def jump(self) -> bool:
        """Whether a level shift of the drift (a bias jump, :mod:`.shift`) fails the model:
        the ``term new`` step next, before any candidate (the candidates' LRs are measured
        with the jump in the data: a trend took LR 34.5 from a jump of 0.15 deg/h)."""
        return not self.adequate and self.level_shift is not None and \
            self.level_shift.significant

    @property
    def cycling(self) -> bool:
        """Whether a periodic disturbance (:mod:`.periodic`) fails the model: as a
        :attr:`jump`, the ``term new`` step next, before any candidate."""
        return not self.adequate and self.periodic is not None and self.periodic.significant

    @property
    def outside(self) -> bool:
        """Whether the failure is an effect outside the vocabulary, the ``term new`` step
        next: a level shift (:attr:`jump`), a periodic disturbance (:attr:`cycling`); or
        not adequate, no significant candidate, and
        the reference's lack of fit significant — at its level, or at
        :data:`~.reference.REPORT_ALPHA` where another check failed too (as
        :func:`~.verdict.verdict_reasons` says)."""
        ref = self.reference
        if self.jump or self.cycling:
            return True
        return not self.adequate and not self.significant and ref is not None and (
            ref.significant or (ref.reported and any(
                not r.startswith("lack of fit") for r in self.reasons)))

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": list(self.model.names),
            "adequate": self.adequate,
            "reasons": list(self.reasons),
            "parameters": {k: {**e.to_dict(), "unit": unit_text(e.unit, self.unit)}
                           for k, e in self.fit.parameters.items()},
            "unit": self.unit,
            "loglik": self.fit.loglik,
            "residual": {"rms": self.diagnosis.rms,
                         "ljung_box_p": self.diagnosis.ljung_box_p,
                         **self.diagnosis.to_dict()},
            "candidates": [c.to_dict(self.unit) for c in self.candidates],
            "look_alikes": [dict(x) for x in self.look_alikes],
            "alpha": self.alpha,
            "warnings": list(self.fit.warnings),
            **({"model_error": self.model_error.to_dict()} if self.model_error else {}),
            **({"reference": self.reference.to_dict()} if self.reference else {}),
            "notes": list(self.notes),
            "redundant": [dict(x) for x in self.redundant],
            **({"level_shift": self.level_shift.to_dict()} if self.level_shift else {}),
            **({"periodic": self.periodic.to_dict()} if self.periodic else {}),
        }


#: the reference distribution of a candidate's LR (``Candidate.test``)
TEST_CHI2 = "chi2"  # χ²(df)
TEST_MIXTURE = "chi2 mixture"  # ½χ²(0) + ½χ²(df): the null on a boundary
TEST_CHI2_EXTRA = "chi2 +1 df"  # χ²(df), df with one more for a parameter unidentified
TEST_SUP = "sup over shape"  # the supremum of a χ²(df) process over the shape (EC/Davies)
TEST_SCORE = "score test"  # a screened candidate's LM statistic (:mod:`.screen`)
TEST_SIM = "simulated"  # the LR's law simulated under the current model (:mod:`.simulated`)
#: the score test's p, larger than the LR's by its own law: p is the larger of the two (a
#: refit that trades the term against the random part overshoots the LR's law; see
#: :func:`~.candidates.guarded`)
TEST_GUARD = "LR and score"
