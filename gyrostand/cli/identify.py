"""``gyrostand identify RUN|CSV|PARQUET|LOG [--config SESSION.yaml] --method {lsq,lkf,ml}
[--model ...] [--sigma S] [--unit U] [--dt S] [--format text|json|html]
[--variant relin|paper]``: the inputs of every workbench command
(:mod:`gyrostand.workbench.inputs`)."""

from __future__ import annotations

import argparse
import dataclasses
from typing import Any

from ..core import registry
from ..core.names import LKF_VARIANTS, METHODS
from ..errors import UsageError
from ..plugins import available_terms
from .common import add_format_args, emit, number
from .workbench_args import add_subject_args, subject_of, subjects_of

#: the model of a CSV or Parquet input when --model is not given
DEFAULT_MODEL = "markov,temp,bias"


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "identify",
        help="identify drift-model parameters of a run (or a CSV, a Parquet export, a raw "
             "log)",
        description="Identify the drift model of a gyro's 1-s samples: from a run folder, "
                    "a CSV with columns t (s), drift, temp, the Parquet export or a raw CAN "
                    "log with --config.",
    )
    add_subject_args(p, several=True, model_help=(
        f"comma-separated model terms of: {', '.join(available_terms())}; 'white' "
        "measurement noise is always included (default: the run's current model; for a "
        f"CSV or Parquet file {DEFAULT_MODEL})"))
    p.add_argument("--method", choices=sorted(METHODS), default="ml",
                   help="identifier: lsq (the paper's least squares), lkf (its linearized "
                        "Kalman filter), ml (exact maximum likelihood; default)")
    p.add_argument("--sigma", type=number(positive=True), default=None,
                   help="known stationary drift std σ (markov.sigma, > 0), as in the paper")
    add_format_args(p)
    g = p.add_argument_group("lsq options")
    g.add_argument("--regressor", choices=("previous", "current"), default="previous",
                   help="lsq regressor Y_{k-1} (standard, default) or Y_k (the paper's text)")
    g = p.add_argument_group("lkf options")
    g.add_argument("--variant", choices=LKF_VARIANTS, default="relin",
                   help="relin (default): the converging filter run to its fixed point "
                        "(re-linearised, noise levels re-estimated); paper: the paper's "
                        "single pass at a fixed point (warns when it stays there or β <= 0)")
    g.add_argument("--beta0", type=number(positive=True), default=None,
                   help="linearisation point β₀ (1/s); relin: its start (default: the "
                        "lsq/ml fit), paper: default the paper's 1e-4")
    g.add_argument("--gamma0", type=number(), default=None, help="linearisation point γ₀")
    g.add_argument("--iterate", action="store_true",
                   help="paper variant: re-linearise at the previous estimate until it "
                        "settles")
    p.set_defaults(func=run)


def options_for(args: argparse.Namespace) -> Any:
    """The typed options of ``--method`` from the command line: each option of the
    identifier's options class given here under its own name (``--regressor`` for lsq;
    ``--variant``, ``--beta0``, ``--gamma0``, ``--iterate`` for lkf; ``--sigma`` for all)."""
    return registry.get(args.method).cli_options(args)


def run(args: argparse.Namespace) -> int:
    if len(args.run) > 1:
        from ..core.ml.joint import joint_ml

        if args.method != "ml":
            raise UsageError(f"several runs are identified jointly by ml only (--method "
                             f"{args.method} fits one run)")
        subjects = subjects_of(args)
        emit(joint_ml([s.samples for s in subjects], subjects[0].model, sigma=args.sigma),
             args.format)
        return 0
    args.run = args.run[0]
    subject = subject_of(args)
    samples = subject.samples
    opts = options_for(args)
    beta0 = getattr(opts, "beta0", None)  # a linearisation point (lkf)
    if beta0 is not None and beta0 * samples.dt >= 1.0:
        raise UsageError(f"--beta0 {beta0:g} 1/s must be below 1/dt = "
                         f"{1.0 / samples.dt:g} of {args.run}")
    result = registry.get(args.method).fit(samples, subject.model, opts)
    if subject.unit != result.unit:
        result = dataclasses.replace(result, unit=subject.unit)
    emit(result, args.format)
    return 0
