"""Cells the plain-text documents share (:mod:`.text`, :mod:`.joint_text`): an estimate
with its std and unit, and the name of the law a candidate's p is from."""

from __future__ import annotations

from typing import Any

from ..core.summary import unit_text

__all__ = ["TEST_TEXT", "estimate", "law", "tests_used"]


def estimate(value: float, std: float, unit: str, fixed: bool = False,
             drift_unit: str = "y") -> str:
    """``value ± std unit`` (``fixed`` for a held value), the unit as printed."""
    sd = "fixed" if fixed else f"± {std:.3g}"
    return f"{value:.6g} {sd} {unit_text(unit, drift_unit)}"


def law(name: str) -> str:
    """`` (the test)`` after an LR's df when it is not plain χ²(df)."""
    short = {"chi2 mixture": "½χ²(0) + ½χ²(df)", "chi2 +1 df": "χ², one df more",
             "sup over shape": "sup over its shape",
             "LR and score": "score test: the LR overshoots its law"}
    return "" if name == "chi2" else f" ({short.get(name, name)})"


#: what each candidate test (``Candidate.test``) refers the LR to
TEST_TEXT = {
    "chi2": "χ²(df)",
    "chi2 mixture": "½χ²(0) + ½χ²(df) (null on a boundary)",
    "chi2 +1 df": "χ²(df), one df for a parameter unidentified under the null",
    "sup over shape": "sup over the shape of a χ²(df) process (Davies/Euler "
                      "characteristic; df = coefficients)",
    "score test": "score (LM) test, χ²(df), screened: not refitted",
    "LR and score": "the score (LM) test's p at the current fit, larger than the LR's by its "
                    "law (a refit that trades the term against the random part overshoots "
                    "it)",
    "simulated": "the LR's law simulated under the current model (a random walk it "
                 "looks like is in it; scaled χ² from 40 replicates)",
}


def tests_used(cands: Any) -> str:
    """Which reference distribution gave each candidate's p, grouped: ``χ²(df): trend,
    temp2; sup over the shape ...: temp_rate, hysteresis``."""
    groups: dict[str, list[str]] = {}
    for c in cands:
        groups.setdefault(c.test, []).append(c.term)
    return "; ".join(f"{TEST_TEXT.get(t, t)}: {', '.join(terms)}"
                     for t, terms in groups.items())
