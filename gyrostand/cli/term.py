"""``gyrostand term new --from RUN [--name NAME] [--out DIR]``: write a plugin term of the
shape the run's saturated reference shows missing (an effect outside the vocabulary), as a
package to review, ``pip install -e`` and test with ``fit --add NAME``."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .common import workbench_command
from .workbench_args import INPUT_HELP


def add_parser(sub: Any) -> None:
    p = sub.add_parser("term", help="write a plugin term of the shape a run's reference "
                                    "shows missing", description=__doc__)
    tsub = p.add_subparsers(dest="term_command", required=True)
    n = tsub.add_parser("new", help="a plugin term from a run's missing shape",
                        description=__doc__)
    n.add_argument("--from", dest="run", required=True, metavar="RUN", help=INPUT_HELP)
    n.add_argument("--name", default="shape", help="the term's name (default: shape)")
    n.add_argument("--out", default=None, metavar="DIR",
                   help="the package folder (default: gyrostand-<name>/ in the run folder, "
                        "or beside the data file)")
    n.add_argument("--force", action="store_true", help="overwrite an existing module")
    n.add_argument("--config", default=None, metavar="SESSION.yaml",
                   help="the session file that decodes a raw CAN log (as for diagnose)")
    n.add_argument("--gyro", default=None, help="which gyro of a multi-gyro run")
    n.add_argument("--model", default=None,
                   help="the model whose missing shape to write (default: the run's "
                        "current model)")
    n.add_argument("--unit", default=None, help="the drift's unit (as for diagnose)")
    n.add_argument("--dt", type=float, default=None, help="a CSV's sampling step in s")
    n.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..workbench.newterm import new_term
    from .workbench_args import subject_of

    subject = subject_of(args)
    out = new_term(subject, args.name, Path(args.out) if args.out else None, args.force)
    f, q = out.formula, out.partial
    if out.shift is not None:
        print(f"missing shape: a level shift of the drift {out.shift.text(subject.unit)}: "
              "a step at that instant (a bias jump: look at the run's log there)")
    elif out.cycle is not None:
        print(f"missing shape: a periodic disturbance {out.cycle.text(subject.unit)}: a sine "
              "and a cosine at that period, each its own coefficient (what runs at it?)")
    else:
        assert q is not None
        print(f"missing shape: the partial effect of {q.variable} (Wald {q.wald:.1f} on "
              f"{q.df} df, p = {q.p_value:.2g}; the model's lack of fit p = "
              f"{out.lack_of_fit_p:.2g})")
    print(f"formula: a · g({f.variable}), g = "
          + " ".join(f"{c:+.4g}·{n}" for (n, _), c in zip(f.forms, f.coef, strict=True))
          + " (normalised to peak 1); "
          + (f"score LM {f.score:.1f} at the current fit, " if f.score is not None else "")
          + (f"R² {f.r2:.3f} of the reference's curve; "
             if out.shift is None and out.cycle is None else "")
          + f"a ≈ {f.amplitude:.4g} {subject.unit}"
          + "".join(f"; + b{n.rsplit('^', 1)[1]}·{n} at the output, its own coefficient "
                    f"(≈ {c:.4g} {subject.unit})" for n, _, c in f.lower))
    print(f"wrote {out.module}")
    print(f"      {out.folder / 'pyproject.toml'}")
    fit = workbench_command(args, "fit")
    print("next: review the module, then")
    print(f"  {_pip()} install -e {_q(out.folder)}")
    print(f"  {fit} --add {out.name}")
    return 0


def _pip() -> str:
    import shlex
    import sys

    return f"{shlex.quote(sys.executable)} -m pip"


def _q(p: Path) -> str:
    import shlex

    return shlex.quote(str(p))
