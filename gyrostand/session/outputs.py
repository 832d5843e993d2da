"""The run folder as the session used to name it: kept importable from here.

The run folder's layout, writers and readers are :mod:`gyrostand.runfolder`'s (the one
owner); these names are re-exported for the session's modules and older callers.
"""

from __future__ import annotations

from ..runfolder import (
    SEGMENTS_FILE,
    EstimatesWriter,
    RunLock,
    RunLog,
    SegmentLog,
    check_writable,
    estimate_columns,
    latest_run_dir,
    make_run_dir,
    next_raw_segment,
    raw_segments,
    read_estimates_csv,
    read_segments,
    write_atomic,
)

__all__ = ["make_run_dir", "RunLog", "EstimatesWriter", "estimate_columns", "write_atomic",
           "raw_segments", "next_raw_segment", "latest_run_dir", "RunLock", "check_writable",
           "SegmentLog", "read_segments", "SEGMENTS_FILE", "read_estimates_csv"]
