"""``gyrostand demo``: the paper's 2000-s scenario, identified by all three methods."""

from __future__ import annotations

import argparse
from typing import Any

from ..core.identify import identify
from ..core.model import Model
from ..core.profiles import paper_profile
from ..core.simulate import simulate

TRUTH = {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.01,
         "white.sigma": 0.01, "bias.b": 0.0}


def add_parser(sub: Any) -> None:
    p = sub.add_parser("demo", help="run the paper's scenario and identify it")
    p.add_argument("--seed", type=int, default=1)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    model = Model.parse("markov,temp,bias")
    samples = simulate(model, TRUTH, paper_profile(), seed=args.seed)
    print("paper scenario C1 (2000 s, 20->45->35 degC), truth:",
          ", ".join(f"{k}={v:g}" for k, v in TRUTH.items()))
    for method, opts in (("lsq", {}), ("lkf", {"iterate": True}), ("ml", {})):
        r = identify(samples, model, method, **opts)
        print()
        print(r.summary())
    return 0
