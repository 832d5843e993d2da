"""Export a run folder for other tools: Parquet (pyarrow) for data people, MDF4 (asammdf)
for the measurement tools of the CAN world (CANape, asammdf's viewer).

Both carry the same data as the CSVs, values unchanged (float64; counts as integers):

* **Parquet**: ``<out>/<gyro>/samples.parquet`` (``t, drift, temp, n_drift, n_temp``) and
  ``<out>/<gyro>/estimates.parquet`` (``t``, ``<id>:<param>``, ``<id>:<param>:std`` and
  ``<id>:status`` as a dictionary-encoded string); each field's ``unit`` and the table's
  ``gyro``, ``run``, ``source`` in the schema metadata, and the same as pandas' attrs
  (schema key ``PANDAS_ATTRS``, pandas >= 2.1), so ``pd.read_parquet(p).attrs["units"]``
  maps each column to its unit (field metadata alone, pandas drops).
* **MDF4** (4.10): ``<out>/<run folder name>.mf4``, per gyro one channel group of samples
  (``<gyro>.drift``, ``<gyro>.temp``, ``<gyro>.n_drift``, ``<gyro>.n_temp``) and one of
  online estimates (``<gyro>.<id>.<param>``, ``...std``, ``<gyro>.<id>.status`` with a
  value-to-text conversion); master channel ``time`` (asammdf's name) in s since the
  run's first bin, the absolute time of that bin in the file header's start time; each
  channel with its unit.

Units: the drift's and temperature's from the run's session file (the DBC signals) when it
can still be read, else ``y`` and ``degC``; a parameter's unit from the model (``y``
replaced by the drift's unit, in the notation the commands print:
:func:`~gyrostand.core.summary.unit_text`, e.g. ``(deg/h)/(s·°C)``).

pyarrow and asammdf are optional (``pip install 'gyrostand[formats]'``): a missing one is a
clear error naming the extra.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..can.bus import STATUS_CODES
from ..core.model import Model
from ..core.summary import unit_text
from ..errors import DataError, GyrostandError, MissingPackageError, OutputError
from ..runfolder import (
    SAMPLES_COLUMNS,
    estimates_path,
    read_estimates_csv,
    read_result,
    read_samples_csv,
    samples_path,
)

__all__ = ["ExportError", "RunTables", "read_run_tables", "export_parquet", "export_mf4",
           "write_formats", "PANDAS_ATTRS"]

#: the schema metadata key pandas (>= 2.1) writes ``DataFrame.attrs`` under and
#: ``pd.read_parquet`` restores them from (``pyarrow``'s ``to_pandas()`` does not read it)
PANDAS_ATTRS = "PANDAS_ATTRS"

log = logging.getLogger(__name__)


class ExportError(MissingPackageError):
    """An export format whose optional package is not installed."""


@dataclass(frozen=True)
class RunTables:
    """One gyro's samples and online estimates, columns by name, with units."""

    gyro: str
    samples: dict[str, np.ndarray]
    estimates: dict[str, np.ndarray] | None
    units: dict[str, str]


def _units(run_dir: Path, info: dict[str, Any], gyro: str) -> tuple[str, str]:
    try:
        from ..config import load_config

        g = load_config(Path(info["config"])).gyro(gyro)
        return g.drift.unit or "y", g.temperature.unit or "degC"
    except Exception as exc:  # moved or changed session file: generic units
        log.info("%s: units of gyro %s unknown (%s): y, degC", run_dir, gyro, exc)
        return "y", "degC"


def _param_unit(model: Model | None, param: str, drift_unit: str) -> str:
    if model is None or param not in model.param_names:
        return ""
    return unit_text(model.unit(param), drift_unit)  # as every command prints it


def read_run_tables(run_dir: str | Path, gyros: Sequence[str] | None = None
                    ) -> tuple[dict[str, Any], list[RunTables]]:
    """``result.json`` of ``run_dir`` and, per gyro (all, or ``gyros``), its tables."""
    run_dir = Path(run_dir)
    info = read_result(run_dir)
    known = list(info.get("gyros", {}))
    chosen = list(gyros) if gyros else known
    for g in chosen:
        if g not in known:
            raise DataError(f"{run_dir}: no gyro {g!r} (the run has {', '.join(known)})")
    out = []
    for g in chosen:
        drift_unit, temp_unit = _units(run_dir, info, g)
        raw = read_samples_csv(samples_path(run_dir, g))
        samples = {k: np.asarray(raw[k], dtype=np.int64 if k.startswith("n_") else float)
                   for k in SAMPLES_COLUMNS}
        units = {"t": "s", "drift": drift_unit, "temp": temp_unit, "n_drift": "",
                 "n_temp": ""}
        est_path = estimates_path(run_dir, g)
        estimates = None
        if est_path.is_file():
            cols = read_estimates_csv(est_path)
            estimates = {k: np.asarray(v, dtype=object if k.endswith(":status") else float)
                         for k, v in cols.items()}
            try:
                model: Model | None = Model.parse(info["gyros"][g]["model"])
            except Exception:
                model = None
            for k in cols:
                if k == "t":
                    continue
                parts = k.split(":")
                units[k] = "" if parts[-1] == "status" else _param_unit(model, parts[1],
                                                                       drift_unit)
        out.append(RunTables(g, samples, estimates, units))
    return info, out


def _need(module: str, what: str) -> Any:
    try:
        return __import__(module)
    except ImportError:
        raise ExportError(f"{what} needs the {module} package: pip install "
                          "'gyrostand[formats]'") from None


def export_parquet(run_dir: str | Path, out: str | Path | None = None,
                   gyros: Sequence[str] | None = None) -> list[Path]:
    """Write ``<out>/<gyro>/samples.parquet`` and ``estimates.parquet`` (``out`` default:
    the run folder); return the paths."""
    _need("pyarrow", "export --parquet")
    import pyarrow as pa
    import pyarrow.parquet as pq

    run_dir = Path(run_dir)
    info, tables = read_run_tables(run_dir, gyros)
    out = Path(out) if out is not None else run_dir
    written: list[Path] = []
    for tab in tables:
        for kind, cols in (("samples", tab.samples), ("estimates", tab.estimates)):
            if cols is None:
                continue
            fields, arrays = [], []
            for name, values in cols.items():
                if values.dtype == object:
                    arr = pa.array(list(values), type=pa.string()).dictionary_encode()
                else:
                    arr = pa.array(values)
                arrays.append(arr)
                fields.append(pa.field(name, arr.type,
                                       metadata={"unit": tab.units.get(name, "")}))
            meta = {"gyro": tab.gyro, "run": run_dir.name, "source": str(info.get("source")),
                    "table": kind}
            units = {name: tab.units.get(name, "") for name in cols}
            # pandas' own key: pd.read_parquet restores it as DataFrame.attrs (pandas >= 2.1)
            meta[PANDAS_ATTRS] = json.dumps({**meta, "units": units}, ensure_ascii=False)
            table = pa.Table.from_arrays(arrays, schema=pa.schema(fields, metadata=meta))
            path = out / tab.gyro / f"{kind}.parquet"
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                pq.write_table(table, path)
            except OSError as exc:
                raise OutputError(f"{path}: cannot write: {exc.strerror or exc}") from exc
            written.append(path)
    return written


def export_mf4(run_dir: str | Path, out: str | Path | None = None,
               gyros: Sequence[str] | None = None) -> Path:
    """Write ``<out>/<run folder name>.mf4`` (``out`` default: the run folder); return it."""
    _need("asammdf", "export --mf4")
    from asammdf import MDF, Signal

    run_dir = Path(run_dir)
    info, tables = read_run_tables(run_dir, gyros)
    path = (Path(out) if out is not None else run_dir) / f"{run_dir.name}.mf4"
    starts = [float(t.samples["t"][0]) for t in tables if t.samples["t"].size]
    t0 = min(starts) if starts else 0.0
    mdf = MDF(version="4.10")
    mdf.header.start_time = dt.datetime.fromtimestamp(t0, tz=dt.UTC)
    mdf.header.comment = (f"gyrostand run {run_dir.name} ({info.get('source')}); t = s since "
                          "the first 1-s bin")
    status_conv: dict[str, Any] = {}
    for i, (text, code) in enumerate(sorted(STATUS_CODES.items(), key=lambda kv: kv[1])):
        status_conv[f"val_{i}"] = code
        status_conv[f"text_{i}"] = text.encode()
    for tab in tables:
        t = tab.samples["t"] - t0
        sigs = [Signal(tab.samples[k], t, name=f"{tab.gyro}.{k}", unit=tab.units[k],
                       comment=f"{k} of gyro {tab.gyro} (1-s bins)")
                for k in SAMPLES_COLUMNS if k != "t"]
        mdf.append(sigs, comment=f"{tab.gyro}: samples")
        if tab.estimates is not None and tab.estimates["t"].size:
            te = tab.estimates["t"] - t0
            esigs = []
            for k, v in tab.estimates.items():
                if k == "t":
                    continue
                name = f"{tab.gyro}." + k.replace(":", ".")
                if k.endswith(":status"):
                    codes = np.array([STATUS_CODES.get(str(s), 255) for s in v], dtype=np.uint8)
                    esigs.append(Signal(codes, te, name=name, conversion=status_conv,
                                        comment="online status"))
                else:
                    esigs.append(Signal(np.asarray(v, dtype=float), te, name=name,
                                        unit=tab.units.get(k, ""),
                                        comment=f"online estimate {k}"))
            mdf.append(esigs, comment=f"{tab.gyro}: online estimates")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        mdf.save(path, overwrite=True)
    except OSError as exc:
        raise OutputError(f"{path}: cannot write: {exc.strerror or exc}") from exc
    finally:
        mdf.close()
    return path


def write_formats(run_dir: str | Path, formats: Sequence[str]) -> list[Path]:
    """The run's end (``session.formats``, ``--data-format``): each of ``formats``
    (:data:`~gyrostand.runfolder.layout.DATA_FORMATS`) written into the run folder from
    its committed CSVs and ``result.json`` by :func:`export_parquet` / :func:`export_mf4`;
    the CSVs are only read. Any failure is an :class:`OutputError` naming the format."""
    written: list[Path] = []
    for fmt in formats:
        try:
            if fmt == "parquet":
                written += export_parquet(run_dir)
            elif fmt == "mf4":
                written.append(export_mf4(run_dir))
            else:
                raise DataError(f"unknown data format {fmt!r}")
        except OutputError:
            raise
        except GyrostandError as exc:  # no package, unreadable CSV: the file is not written
            raise OutputError(f"{run_dir}: {fmt} not written: {exc}") from exc
        log.info("%s: %s written", run_dir, fmt)
    return written
