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
    for label, path in (("result:    ", outcome.result_json), ("report:    ", outcome.report)):
        print(f"{label} {path}" if path.is_file() else f"{label} not written", file=out)
    for err in outcome.stats.get("unwritten", []):
        print(f"error: {err}", file=out)
