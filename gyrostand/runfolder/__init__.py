"""The run folder: the one owner of its layout, its writers and its readers.

A run (``gyrostand run``, ``replay``, ``demo``) writes one folder; every layer that
touches it goes through this package:

* :mod:`.layout`: every file and sub-folder name, how a run folder is named, found
  (newest, live only), locked (``.lock``) and how its raw log continues in segments;
* :mod:`.files`: the rules the files share: atomic rewrite (temporary file + rename),
  ``fdatasync``, and the single torn-last-line rule of the growing files
  (:func:`read_lines`, :func:`cut_torn_tail`);
* :mod:`.tables`: ``<gyro>/samples.csv`` and ``<gyro>/estimates.csv``, both written by one
  committed-CSV writer (:class:`CommittedCSV`) and read back by :func:`read_samples_csv`,
  :func:`read_estimates_csv`;
* :mod:`.records`: ``result.json`` read back, ``segments.json``, ``run.log``.

The content of ``result.json`` and ``report.txt`` is the session's
(:mod:`gyrostand.session.final`), the ledger's entries the workbench's
(:mod:`gyrostand.workbench.ledger`); they are written and read through the functions here.
Imports only the standard library and :mod:`gyrostand.errors` (any layer may use it).
"""

from .files import append_line, cut_torn_tail, datasync, read_lines, read_text, write_atomic
from .layout import (
    ESTIMATES,
    LEDGER,
    LOCK,
    RAW_LOG,
    REPORT,
    RESULT,
    RUN_LOG,
    SAMPLES,
    SEGMENTS_FILE,
    SNAPSHOT,
    RunLock,
    check_writable,
    csv_ledger_path,
    estimates_path,
    latest_run_dir,
    make_run_dir,
    next_raw_segment,
    raw_segments,
    samples_path,
)
from .records import (
    RunLog,
    SegmentLog,
    finite,
    json_safe,
    read_result,
    read_result_or_none,
    read_segments,
    write_json,
)
from .tables import (
    SAMPLES_COLUMNS,
    CommittedCSV,
    EstimatesWriter,
    SamplesWriter,
    cut_estimates_after,
    estimate_columns,
    read_estimates_csv,
    read_header,
    read_samples_csv,
)

__all__ = ["append_line", "cut_torn_tail", "datasync", "read_lines", "read_text",
           "write_atomic", "ESTIMATES", "LEDGER", "LOCK", "RAW_LOG", "REPORT", "RESULT",
           "RUN_LOG", "SAMPLES", "SEGMENTS_FILE", "SNAPSHOT", "RunLock", "check_writable",
           "csv_ledger_path", "estimates_path", "latest_run_dir", "make_run_dir",
           "next_raw_segment", "raw_segments", "samples_path", "RunLog", "SegmentLog", "finite",
           "json_safe",
           "read_result", "read_result_or_none", "read_segments", "write_json",
           "SAMPLES_COLUMNS", "CommittedCSV", "EstimatesWriter", "SamplesWriter",
           "cut_estimates_after", "estimate_columns", "read_estimates_csv", "read_header",
           "read_samples_csv"]
