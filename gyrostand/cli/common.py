"""Printing shared by the run/replay/demo subcommands."""

from __future__ import annotations

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
    print(f"result:     {outcome.result_json}", file=out)
    print(f"report:     {outcome.report}", file=out)
