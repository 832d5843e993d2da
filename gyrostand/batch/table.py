"""The fleet table: one row per run x gyro, from the batch's records.

Columns, in order (a column is left out when no row has it):

* ``run``, then the manifest's attributes (``serial``, ``date``, ...), ``gyro``;
* ``status`` (``ok``; ``damaged``: fitted, but the log had damaged containers, truncated
  objects or skipped lines, ``log_damage`` of them; ``failed``: the run or this gyro;
  ``missing``: not done yet) and
  ``error`` (what failed, for a failed row);
* ``kind`` (``log`` / ``folder``), ``source`` (the input), ``config``;
* ``frames``, ``decoded``, ``rejected``, ``log_damage`` (the run's decoder counts),
  ``bins``, ``gaps``, ``observed`` (the gyro's 1-s bins, gaps, bins with data);
* ``model``, ``method``, ``loglik``, ``rms`` (innovation RMS);
* ``model_error``, ``model_error_floor`` (diagnose's open-loop model error of 60-s means
  and the floor the model's own noise leaves, in the drift's ``unit``);
* ``verdict`` (``adequate`` / ``not adequate``), ``reasons``, ``ljung_box_p``;
* ``top_candidate``, ``top_lr``, ``top_p``, ``top_delta_bic``, ``top_significant`` (the
  best-ranked missing effect and its likelihood-ratio statistic), ``significant`` (every
  significant one);
* ``outliers`` (each parameter flagged by its robust z within the gyro type, ``name
  z=…``) and ``max_abs_z`` (:func:`~.fleet.with_outliers`; empty where a type has too few
  ok runs to judge);
* per parameter ``<term>.<param>`` and ``<term>.<param>_std``;
* ``warnings``, ``seconds`` (the task's wall time), ``run_dir``, ``report``.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..runfolder import write_atomic
from .inputs import RunSpec
from .tasks import read_record

__all__ = ["fleet_rows", "write_table", "columns", "COLUMNS_HEAD", "COLUMNS_TAIL"]

COLUMNS_HEAD = ("status", "error", "kind", "source", "config", "frames", "decoded",
                "rejected", "log_damage", "bins", "gaps", "observed", "model", "method",
                "loglik", "rms", "unit", "model_error", "model_error_floor", "verdict",
                "reasons", "ljung_box_p", "top_candidate", "top_lr", "top_p",
                "top_delta_bic", "top_significant", "significant", "outliers",
                "max_abs_z")
COLUMNS_TAIL = ("warnings", "seconds", "run_dir", "report")


def fleet_rows(specs: Sequence[RunSpec], out: str | Path) -> list[dict[str, Any]]:
    """Every run x gyro of ``specs`` in input order, from the records under ``out``
    (a run with no record yet: one row, status ``missing``)."""
    rows = []
    for spec in specs:
        rec = read_record(out, spec.run)
        base: dict[str, Any] = {"run": spec.run, **spec.attrs, "kind": spec.kind,
                                "source": spec.path, "config": spec.config}
        if rec is None:
            rows.append({**base, "status": "missing"})
            continue
        counts = rec.get("counts") or {}
        base.update(counts)
        base.update(seconds=rec.get("seconds"), run_dir=rec.get("run_dir"),
                    report=rec.get("report"))
        if not rec.get("rows"):
            rows.append({**base, "gyro": None, "status": "failed",
                         "error": rec.get("error") or "no rows"})
            continue
        for r in rec["rows"]:
            row = {**base, **{k: v for k, v in r.items() if k != "params"}}
            for name, (value, std) in (r.get("params") or {}).items():
                row[name] = value
                row[f"{name}_std"] = std
            rows.append(row)
    return rows


def columns(rows: Sequence[dict[str, Any]], attrs: Sequence[str]) -> list[str]:
    """The fleet table's columns for ``rows`` in the order of the module doc (``attrs``
    the manifest's attributes), a column only where some row has it."""
    seen: set[str] = set()
    for r in rows:
        seen.update(r)
    head = ["run", *attrs, "gyro", *COLUMNS_HEAD]
    params = sorted(k for k in seen if k not in head and k not in COLUMNS_TAIL)
    return [c for c in (*head, *params, *COLUMNS_TAIL) if c in seen]


def write_table(rows: Sequence[dict[str, Any]], out: str | Path, attrs: Sequence[str] = (),
                *, parquet: bool = True) -> dict[str, Path]:
    """``<out>/fleet.csv`` and (with pyarrow) ``<out>/fleet.parquet``, each written
    atomically; returns the paths written."""
    out = Path(out)
    cols = columns(rows, attrs)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow(["" if r.get(c) is None else (f"{r[c]:.10g}" if isinstance(r[c], float)
                                                 else r[c]) for c in cols])
    paths = {"csv": out / "fleet.csv"}
    write_atomic(paths["csv"], buf.getvalue().encode("utf-8"))
    if parquet:
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError:
            return paths
        arrays = []
        for c in cols:
            vals = [r.get(c) for r in rows]
            kinds = {type(v) for v in vals if v is not None}
            if kinds <= {int, float} and kinds != {int} and kinds:
                vals = [None if v is None else float(v) for v in vals]
            elif len(kinds) > 1 or (kinds and not kinds <= {int, float, bool, str}):
                vals = [None if v is None else str(v) for v in vals]
            arrays.append(pa.array(vals) if kinds else pa.array(vals, type=pa.string()))
        table = pa.Table.from_arrays(arrays, names=cols)
        sink = pa.BufferOutputStream()
        pq.write_table(table, sink)
        paths["parquet"] = out / "fleet.parquet"
        write_atomic(paths["parquet"], sink.getvalue().to_pybytes())
    return paths
