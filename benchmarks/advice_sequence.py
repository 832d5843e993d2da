"""The workbench's advice followed as a user follows it (issue 23's acceptance): on runs with
hidden effects, ``diagnose``; while it says NOT ADEQUATE and ranks a significant candidate,
``fit --add`` the first one; when it is ADEQUATE but names a redundant term, ``fit
--remove`` it; stop at ADEQUATE, or when nothing in the vocabulary is significant. A run counts as right when the sequence ends with exactly the true terms and
ADEQUATE — or, for a shape outside the vocabulary, NOT ADEQUATE naming an effect outside
the vocabulary and no wrong term added. Also: the headline's unexplained share of the
open-loop error before the right term (target ≥ 50 %) and the fall of that unexplained
part when the first right term is added (target ≥ 70 %; with two hidden effects the second
still stands in it).

Each run: a seeded 4-h chamber cycle (benchmarks/reference_fit.run: the sensor quantised to
0.05 °C with 0.01 °C noise), 1 % of the 1-s bins dropped at random (a frame lost) and the
first and last bins partial (half the frames: their noise doubled). Model markov,temp,bias.

Run: ``.venv/bin/python benchmarks/advice_sequence.py [SEEDS [KIND ...]]`` (default 5, all)
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.reference_fit import HIDDEN, run  # noqa: E402
from gyrostand.core.data import Samples  # noqa: E402
from gyrostand.core.diagnose.verdict import diagnose  # noqa: E402
from gyrostand.core.model import Model  # noqa: E402

#: kind -> (true terms beyond markov,temp,bias; extra truth)
KINDS: dict[str, tuple[list[str], dict[str, float]]] = {
    k: v for k, v in HIDDEN.items() if "outside" not in k}
KINDS.update({
    "temp_rate+trend": (["temp_rate", "trend"], {"temp_rate.k": 5.0, "trend.c": 1e-5}),
    "warmup+temp2": (["warmup", "temp2"], {"warmup.A": 0.5, "warmup.tau": 900.0,
                                           "temp2.gamma2": 5e-6}),
    "random_walk": (["random_walk"], {"random_walk.q": 2e-3}),
    "temp_lag+random_walk": (["temp_lag", "random_walk"], {"temp_lag.tau": 600.0,
                                                          "random_walk.q": 1e-3}),
    "clean": ([], {}),
    "cubic in T (outside)": ([], {}),
})
MAX_STEPS = 6


def data(kind: str, seed: int, tmp: Path) -> Samples:
    """The kind's run with drops and partial end bins."""
    HIDDEN_SAVED = dict(HIDDEN)
    HIDDEN[kind] = KINDS[kind]
    try:
        s = run(kind, seed, 4.0, tmp)
    finally:
        HIDDEN.clear()
        HIDDEN.update(HIDDEN_SAVED)
    rng = np.random.default_rng(seed + 77)
    drift = s.drift.copy()
    drift[rng.random(len(s)) < 0.01] = np.nan
    # the first and last bins hold half the frames: their mean is noisier
    drift[[0, -1]] += 0.02 * rng.standard_normal(2)
    return Samples.from_arrays(s.t, drift, s.temp)


def sequence(s: Samples) -> tuple[list[str], bool, list[str], list[tuple[float, float]]]:
    """Follow the advice: (terms added, final verdict, final reasons, (rms, unexplained)
    of the open-loop error at each diagnosis)."""
    model = Model.parse("markov,temp,bias")
    added: list[str] = []
    errors = []
    for _ in range(MAX_STEPS):
        rep = diagnose(s, model)
        h = rep.model_error.headline()
        errors.append((h["rms"], h["unexplained"] or 0.0))
        if rep.adequate and rep.redundant:  # next: fit --remove the redundant term
            gone = rep.redundant[0]["term"]
            added.remove(gone)
            model = model.remove(gone)
            continue
        if rep.adequate or not rep.significant:
            return added, rep.adequate, list(rep.reasons), errors
        term = rep.significant[0].term
        added.append(term)
        model = model.add(term)
    return added, False, ["steps exhausted"], errors


def main() -> None:
    seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 5
    kinds = sys.argv[2:] or list(KINDS)
    with tempfile.TemporaryDirectory() as tmp:
        for kind in kinds:
            truth = set(KINDS[kind][0])
            outside = "outside" in kind
            right, share, fall, wrong = 0, [], [], []
            t0 = time.perf_counter()
            for i in range(seeds):
                s = data(kind, 500 + i, Path(tmp))
                added, adequate, reasons, errs = sequence(s)
                if outside:
                    ok = not adequate and not added and any(
                        "outside the vocabulary" in r for r in reasons)
                else:
                    ok = adequate and set(added) == truth and len(added) == len(truth)
                right += ok
                if not ok:
                    wrong.append(f"seed {500 + i}: +{','.join(added) or '-'} "
                                 f"{'ADEQUATE' if adequate else 'NOT ADEQUATE'}")
                if truth and errs[0][0] > 0:
                    share.append(errs[0][1] / errs[0][0])
                if truth and added and added[0] in truth and len(errs) > 1 and errs[0][1] > 0:
                    fall.append(1 - errs[1][1] / errs[0][1])
            line = f"{kind:<24} right {right}/{seeds}"
            if share:
                line += f"; unexplained share before {np.min(share):.0%}..{np.max(share):.0%}"
            if fall:
                line += f"; unexplained falls after the first right term {np.min(fall):.0%}.." \
                        f"{np.max(fall):.0%}"
            line += f" ({(time.perf_counter() - t0) / seeds:.0f} s a run)"
            print(line + ("\n    " + "; ".join(wrong) if wrong else ""), flush=True)


if __name__ == "__main__":
    main()
