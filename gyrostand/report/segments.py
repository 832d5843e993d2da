"""Where the open-loop model error fails, per segment of the temperature profile: one line
for a short run, a table by kind of segment for a long one (a 24-h chamber cycle has ~50
segments: one line of them hid which kind of segment fails)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

__all__ = ["LINE_MAX", "number", "open_loop_by_segment"]

#: at most this many segments are listed on one line; more: a table by kind
LINE_MAX = 6


def number(x: float | None, fmt: str = ".3g") -> str:
    """A model-error figure as the text shows it (``—`` for none)."""
    return "—" if x is None else format(x, fmt)


def open_loop_by_segment(ranges: Sequence[Mapping[str, Any]],
                         rows: Sequence[Mapping[str, Any]], window_s: float,
                         unit: str) -> list[str]:
    """The open-loop error per segment (``rows[i]`` of ``ranges[i]``, index 0 the whole
    run): each segment on one line for a short run, else per kind of segment (heating,
    soak, cooling …) how many segments exceed the 99 % point of their floor, the median
    RMS, and the worst segment with its times (from the run's start) and floor."""
    segs = [(ranges[i], rows[i]) for i in range(1, len(rows)) if rows[i]["rms"] is not None]
    if not segs:
        return []
    t0 = float(ranges[0]["t_start"])  # times from the run's start (a log's are epoch s)

    def span(g: Mapping[str, Any]) -> str:
        return f"{g['t_start'] - t0:.0f}–{g['t_stop'] - t0:.0f} s"

    head = f"  open loop per segment ({window_s:g}-s means, {unit})"
    if len(segs) <= LINE_MAX:
        return [head + ": " + "; ".join(
            f"{g['kind']} {span(g)} {number(r['rms'])}"
            for g, r in segs)]
    kinds = list(dict.fromkeys(str(g["kind"]) for g, _ in segs))
    lines = [head + f", {len(segs)} segments by kind "
             "(above: RMS beyond the 99 % point of the segment's floor):",
             f"    {'kind':<10} {'segments':>8} {'above':>6} {'median RMS':>11}  worst"]
    for kind in kinds:
        mine = [(g, r) for g, r in segs if g["kind"] == kind]
        above = sum(1 for _, r in mine if (r.get("unexplained") or 0.0) > 0.0)
        g, r = max(mine, key=lambda gr: gr[1]["rms"])
        med = float(np.median([r_["rms"] for _, r_ in mine]))
        lines.append(f"    {kind:<10} {len(mine):>8} {above:>6} {number(med):>11}  "
                     f"{number(r['rms'])} at {span(g)} (floor {number(r.get('floor'))})")
    return lines
