"""Printing shared by the run/replay/demo subcommands; argument types of numbers."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import TextIO

from ..session.final import result_table
from ..session.pipeline import RunOutcome


def print_outcome(outcome: RunOutcome, out: TextIO,
                  truths: dict[str, dict[str, float]] | None = None) -> None:
    """The final table of every gyro, the counts, and the paths."""
    dec = outcome.stats.get("decoder", {})
    print(f"stopped: {outcome.stop_reason} (state {outcome.state}); frames "
          f"{dec.get('received', 0)} received, {dec.get('decoded', 0)} decoded, "
          f"{dec.get('rejected_total', 0)} rejected", file=out)
    for f in outcome.finals:
        print(f"\ngyro {f.gyro}: {f.bins} bins, {f.gaps} gaps", file=out)
        print(result_table(f, (truths or {}).get(f.gyro)), file=out)
    print(f"\nrun folder: {outcome.run_dir}", file=out)
    for label, path in (("result:    ", outcome.result_json), ("report:    ", outcome.report)):
        print(f"{label} {path}" if path.is_file() else f"{label} not written", file=out)
    for err in outcome.stats.get("unwritten", []):
        print(f"error: {err}", file=out)


def number(*, positive: bool = False, nonnegative: bool = False) -> Callable[[str], float]:
    """An argparse ``type``: a finite float (``positive``: > 0; ``nonnegative``: >= 0);
    anything else is a usage error naming the argument (exit status 2)."""
    def parse(text: str) -> float:
        try:
            x = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text[:40]!r}") from None
        if not math.isfinite(x):
            raise argparse.ArgumentTypeError(f"must be finite, got {text[:40]!r}")
        if positive and not x > 0:
            raise argparse.ArgumentTypeError(f"must be > 0, got {text[:40]!r}")
        if nonnegative and x < 0:
            raise argparse.ArgumentTypeError(f"must be >= 0, got {text[:40]!r}")
        return x
    parse.__name__ = "number"
    return parse
