"""``diagnose`` of several runs of one gyro: the joint fit (:mod:`~gyrostand.core.ml.joint`),
each run's residual check, each run's level shift and periodic line against its own
saturated reference (an event of one run — a bias jump, its chamber's cycling — is that
run's, and the joint fit absorbs it), and the missing effects ranked on the runs together,
a shared one only where it repeats from run to run (:mod:`.repeats`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from ..data import Samples
from ..ml.joint import JointFit, joint_ml
from ..model import Model
from .candidates import rank_candidates
from .periodic import PERIODIC_ALPHA, Periodic, periodic
from .reference import reference_fit
from .repeats import Repeats, mark_unrepeated, model_repeats, slow_process
from .results import significant
from .shift import SHIFT_ALPHA, LevelShift, level_shift, whitened
from .verdict import redundant_terms

__all__ = ["JointDiagnosis", "joint_diagnose", "WHITE_ALPHA"]


@dataclass(frozen=True)
class JointDiagnosis:
    """``diagnose`` of several runs: the joint fit, each run's residual check, and the
    missing effects ranked on the joint model (each candidate refitted jointly: its LR is
    the joint LR, a per-run effect's parameters counted once per run)."""

    fit: JointFit
    candidates: tuple[Any, ...]  # candidates.Candidate, best first
    alpha: float
    adequate: bool
    reasons: tuple[str, ...]
    unit: str = "y"
    #: terms of an adequate joint model that no longer earn their place
    #: (:func:`~.verdict.redundant_terms` on the runs together): ``fit --remove`` them
    redundant: tuple[dict[str, Any], ...] = ()
    #: each run's largest level shift and strongest periodic line against its own
    #: reference (:func:`run_events`; their levels Bonferroni over the runs)
    events: tuple[tuple[LevelShift | None, Periodic | None], ...] = ()
    #: whether each shared effect of the model repeats across the runs (each run fitted
    #: alone; :func:`~.repeats.model_repeats`)
    repeats: tuple[Repeats, ...] = ()

    @property
    def significant(self) -> list[Any]:
        """Ranked candidates significant on the runs together after Bonferroni, in the
        order proposed (as :attr:`~.results.DiagnoseResult.significant`)."""
        return significant(self.candidates, self.alpha)

    def _events(self) -> tuple[tuple[LevelShift | None, Periodic | None], ...]:
        return self.events or tuple((None, None) for _ in self.fit.runs)

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": list(self.fit.model.names), "adequate": self.adequate,
            "reasons": list(self.reasons), "alpha": self.alpha,
            "fit": self.fit.to_dict(),
            "repeatability": (self.fit.repeatability.to_dict()
                              if self.fit.repeatability is not None else None),
            "runs": [{"source": r.source, **dict(r.info.get("residual_check", {})),
                      **({"level_shift": ev[0].to_dict()} if ev[0] is not None else {}),
                      **({"periodic": ev[1].to_dict()} if ev[1] is not None else {})}
                     for r, ev in zip(self.fit.runs, self._events(), strict=True)],
            "candidates": [c.to_dict(self.unit) for c in self.candidates],
            "redundant": [dict(x) for x in self.redundant],
            "repeats": [r.to_dict() for r in self.repeats],
        }


#: each run's whiteness test at this level (Bonferroni over the runs)
WHITE_ALPHA = 0.01


def run_events(runs: Sequence[Samples], model: Model, fit: JointFit
               ) -> tuple[tuple[LevelShift | None, Periodic | None], ...]:
    """Each run's largest level shift and strongest periodic line against its own
    saturated reference (the model at the run's joint estimate beside the run's rich
    basis), at :data:`~.shift.SHIFT_ALPHA` and :data:`~.periodic.PERIODIC_ALPHA` over the
    number of runs (Bonferroni)."""
    out = []
    for s, r in zip(runs, fit.runs, strict=True):
        ref = reference_fit(s, model, r)
        at = whitened(s, ref)
        out.append((level_shift(s, ref, alpha=SHIFT_ALPHA / len(runs), at=at),
                    periodic(s, ref, alpha=PERIODIC_ALPHA / len(runs), at=at)))
    return tuple(out)


def joint_diagnose(runs: Sequence[Samples], model: Model, *, alpha: float = 0.05,
                   terms: list[str] | None = None, unit: str = "y") -> JointDiagnosis:
    """Fit ``model`` to every run jointly, check each run's innovations, rank the missing
    effects by their joint likelihood ratio (:func:`~.candidates.rank_candidates` on the
    runs together); an adequate model's terms that no longer earn their place on the runs
    together are named (``redundant``), as ``diagnose`` of one run names them."""
    fit = joint_ml(runs, model)
    cands = rank_candidates(tuple(runs), model, fit, terms,  # type: ignore[arg-type]
                            alpha=alpha)
    alpha_each = alpha / max(len(cands), 1)
    # a shared effect must repeat from run to run (:mod:`.repeats`): one that does not is
    # a random process's or one run's, and the next candidate is proposed
    cands = mark_unrepeated(runs, model, cands, alpha_each)
    reasons = []
    for r in fit.runs:
        chk = r.info.get("residual_check", {})
        if chk and chk["ljung_box_p"] < WHITE_ALPHA / len(runs):
            reasons.append(f"run {r.info['run']} ({r.source}): innovations are not white "
                           f"(Ljung–Box p = {chk['ljung_box_p']:.2g} over {chk['lags']} lags)")
    events = run_events(runs, model, fit)
    repeats = model_repeats(runs, model, fit)
    for rep in repeats:
        if not rep.repeats:
            reasons.append(f"the model's {rep.term} {rep.text()}: one value for every "
                           "switch-on does not describe these runs (an effect it stands in "
                           "for is missing, or the runs differ)")
    for r, (jump, cycle) in zip(fit.runs, events, strict=True):
        for what, found, like in (("a level shift of the drift", jump, "a bias jump"),
                                  ("a periodic disturbance of the drift", cycle,
                                   "its chamber's compressor or fan cycling")):
            if found is not None and found.significant:
                reasons.append(
                    f"run {r.info['run']} ({r.source}): {what} {found.text(unit)}: an event "
                    f"of that run outside the vocabulary ({like}); its plugin term is that "
                    "run's next step (term new --from it, README: plugins)")
    sig = significant(cands, alpha)
    unrepeated = [c for c in cands if c.repeats is not None and not c.repeats.repeats]
    if unrepeated and not sig and not slow_process(model):
        # nothing else proposed and no second random process in the model to stand for it
        c = unrepeated[0]
        assert c.repeats is not None
        reasons.append(f"{c.term} is significant on the {len(runs)} runs together (p = "
                       f"{c.p_value:.2g}) but {c.repeats.text()}: not an effect of the "
                       "gyro; a random process or one run's event stands in for it, and "
                       "the model has no random process but its first")
    if sig:
        reasons.append(f"{', '.join(c.term for c in sig)} significant at {alpha:g} on the "
                       f"{len(runs)} runs together (Bonferroni over {len(cands)} candidates: "
                       f"p < {alpha_each:.2g})")
    redundant = tuple(redundant_terms(tuple(runs), model, fit, alpha)  # type: ignore[arg-type]
                      ) if not reasons else ()
    return JointDiagnosis(fit=fit, candidates=tuple(cands), alpha=alpha,
                          adequate=not reasons, reasons=tuple(reasons), unit=unit,
                          redundant=redundant, events=events, repeats=repeats)
