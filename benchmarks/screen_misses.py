"""The score screen's false negatives (issue 25 item 2): on the hidden-effect runs of
benchmarks/advice_sequence.py (its data builder: a seeded 4-h chamber cycle, 1 % of the
bins dropped, partial end bins), every candidate is refitted (``screen=False``) and
score-tested (:mod:`gyrostand.core.diagnose.screen`, with the reference's random part as
``diagnose`` gives it); a *miss* is a candidate the screen rules out whose refit is
significant. Two steps per run: the base model (markov,temp,bias) and, for a kind with
hidden terms, that model with the first true term added (the step the advice takes next).

Counted: misses at the verdict's level (p < 0.05 / candidates, Bonferroni: target 0) and
at a nominal p < 0.05; how many candidates the screen rules out (the refits it saves).

Run: ``.venv/bin/python benchmarks/screen_misses.py [SEEDS [KIND ...]]`` (default 2, all)
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.advice_sequence import KINDS, data  # noqa: E402
from gyrostand.core.diagnose.candidates import candidate_terms, rank_candidates  # noqa: E402
from gyrostand.core.diagnose.reference import reference_fit, second_start  # noqa: E402
from gyrostand.core.diagnose.screen import score_tests, screenable, to_refit  # noqa: E402
from gyrostand.core.ml.fit import ml  # noqa: E402
from gyrostand.core.model import Model  # noqa: E402

ALPHA = 0.05


def one_step(s, model: Model) -> tuple[int, int, int, int, list[str]]:
    """(candidates, screened out, misses at Bonferroni, misses at 0.05, lines)."""
    fit = ml(s, model)
    ref = reference_fit(s, model, fit)
    also = second_start(ref)
    terms = candidate_terms(model)
    full = {c.term: c for c in rank_candidates(s, model, fit, terms, also=also,
                                                screen=False)}
    # as rank_candidates: screened only where the reference shows no lack of fit
    scores = score_tests(s, model, fit, [t for t in terms if screenable(s, model, t)])
    keep = to_refit(scores) if also is None else set(scores)
    out = [t for t in scores if t not in keep]
    level = ALPHA / max(len(full), 1)
    lines, miss_b, miss_n = [f"    lack of fit: {'yes, nothing screened' if also else 'no'} "
                             f"(reference p {ref.p_value:.2g})"], 0, 0
    for t in terms:
        c = full.get(t)
        if c is None:
            continue
        sc = scores.get(t)
        tag = "refit (not screenable)" if sc is None else (
            "screened OUT" if t in out else "passes")
        if t in out and c.p_value < ALPHA:
            miss_n += 1
            tag += " MISS(0.05)"
        if t in out and c.p_value < level and c.ranked:
            miss_b += 1
            tag += " MISS(Bonferroni)"
        lm = f"LM {sc.stat:8.2f} p {sc.p_value:8.2g}" if sc else " " * 23
        lines.append(f"    {t:<12} LR {c.lr_stat:8.2f} p {c.p_value:8.2g}  {lm}  {tag}")
    return len(full), len(out), miss_b, miss_n, lines


def main() -> None:
    seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 2
    kinds = sys.argv[2:] or list(KINDS)
    print(f"benchmarks/screen_misses.py: {seeds} seeds per kind, 4-h runs; load average "
          f"{', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    tot = [0, 0, 0, 0]
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for kind in kinds:
            truth = KINDS[kind][0]
            for seed in range(seeds):
                s = data(kind, 100 + seed, Path(tmp))
                models = [Model.parse("markov,temp,bias")]
                if truth:
                    models.append(models[0].add(truth[0]))
                for m in models:
                    n, out, mb, mn, lines = one_step(s, m)
                    for i, v in enumerate((n, out, mb, mn)):
                        tot[i] += v
                    print(f"{kind} seed {seed} model {','.join(m.names)}: {n} candidates, "
                          f"{out} screened out, misses {mb} (Bonferroni) {mn} (p<0.05)")
                    print("\n".join(lines), flush=True)
    print(f"TOTAL: {tot[0]} candidate tests, {tot[1]} screened out (refits saved), "
          f"misses {tot[2]} at the verdict's level (target 0), {tot[3]} at p < 0.05; "
          f"{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
