"""What the workbench reads: one input rule for ``identify``, ``diagnose``, ``fit``,
``report`` and ``allan`` (:func:`read_input`).

An input is one of

* a **run folder** written by ``gyrostand run``/``replay`` (``result.json`` names the gyros,
  their configured models and the session file; ``<gyro>/samples.csv`` holds the bins);
* a **samples CSV** with columns ``t, drift, temp`` (and ``n_drift``, a run's frame
  counts); one at ``<run>/<gyro>/samples.csv`` takes its gyro and units from its run;
* the project's **Parquet export** (``<gyro>/samples.parquet`` of ``gyrostand export
  --parquet``): its gyro and units from the file's schema;
* a **raw CAN log** (BLF, ASC, MF4, candump ``.log``, TRC, python-can's CSV: whatever
  :class:`can.LogReader` reads) with ``--config SESSION.yaml``: decoded through the
  session's DBC mapping and binned by the receive path a replay uses
  (:func:`gyrostand.session.offline.log_samples`; nothing is written), so it gives the
  numbers of the run folder its replay makes; gyro, model and units from the session.

The drift's unit is the DBC signal's (through the run's or the given session file), the
Parquet field's, or ``--unit``; ``y`` (the drift's unit, unnamed) only for a CSV that
names none. A run folder's ledger is ``<run>/ledger.jsonl``; any other input's is
``<stem>.ledger.jsonl`` beside the file.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..core.data import Samples
from ..core.summary import DRIFT_UNIT
from ..errors import (
    DataError,
    GyrostandError,
    MissingPackageError,
    NoInputError,
    UsageError,
)
from ..runfolder import LEDGER, RESULT, csv_ledger_path, read_result, samples_path

__all__ = ["Input", "read_input", "input_kind", "RAW_LOG_SUFFIXES", "DEFAULT_MODEL"]

DEFAULT_MODEL = "markov,temp,bias"

#: file suffixes of raw CAN logs (python-can's readers; ``.gz`` of a text log too); a
#: ``.csv`` is a raw log when its header is python-can's (:func:`input_kind`)
RAW_LOG_SUFFIXES = (".blf", ".asc", ".log", ".mf4", ".trc", ".db")

#: the first columns of python-can's CSV log format (``can.CSVWriter``)
_CAN_CSV_HEADER = "timestamp,arbitration_id"

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Input:
    """One gyro's series as an input holds it: ``configured`` the model the input names
    (the session's; :data:`DEFAULT_MODEL` for a CSV or Parquet file), ``origin`` one of
    ``run``, ``csv``, ``parquet``, ``log``, ``unit`` the drift's unit."""

    samples: Samples
    gyro: str
    configured: tuple[str, ...]
    ledger: Path
    run_dir: Path | None
    origin: str
    unit: str


def input_kind(path: str | Path) -> str:
    """``run``, ``parquet``, ``log`` or ``csv`` (any other file: read as a samples CSV);
    ``missing`` when nothing is there."""
    path = Path(path)
    if path.is_dir():
        return "run"
    if not path.is_file():
        return "missing"
    suffixes = [s.lower() for s in path.suffixes[-2:]]
    suffix = suffixes[-2] if suffixes[-1:] == [".gz"] and len(suffixes) == 2 else (
        suffixes[-1] if suffixes else "")
    if suffix == ".parquet":
        return "parquet"
    if suffix in RAW_LOG_SUFFIXES:
        return "log"
    if suffix == ".csv":
        try:
            with path.open("r", encoding="utf-8-sig", errors="replace") as fh:
                head = fh.readline(200).replace(" ", "").lower()
        except OSError:
            return "csv"  # read_csv names the problem
        if head.startswith(_CAN_CSV_HEADER):
            return "log"
    return "csv"


def read_input(path: str | Path, *, gyro: str | None = None, dt: float | None = None,
               config: str | Path | None = None) -> Input:
    """One gyro's series from a run folder, a samples CSV, a Parquet export or a raw log
    (with ``config``, the session file that decodes it); see the module docstring.

    ``gyro``: which gyro (needed when the input holds several); ``dt``: a CSV's grid step
    (default its most common step). Bad input is a :class:`DataError` or
    :class:`ConfigError` naming the file."""
    path = Path(path)
    kind = input_kind(path)
    if kind == "missing":
        if path.exists():  # a FIFO, a socket, a device: reading it could block for ever
            raise NoInputError(f"{path}: not a regular file or a run folder (a pipe or a "
                               "device): give a run folder, a CSV, a Parquet export or a log")
        raise NoInputError(f"{path}: no such run folder or file")
    if config is not None and kind != "log":
        raise UsageError(f"--config {config}: only a raw CAN log needs a session file "
                         f"({path} is a {'run folder' if kind == 'run' else kind + ' file'},"
                         " which names its own units)")
    if kind == "run":
        return _run_input(path, gyro)
    if kind == "log":
        return _log_input(path, gyro, config)
    if kind == "parquet":
        return _parquet_input(path, gyro, dt)
    samples = Samples.read_csv(path, dt=dt)
    name, unit = gyro or path.stem, DRIFT_UNIT
    run = _run_of_csv(path)
    if run is not None:  # <run>/<gyro>/samples.csv: the run's gyro and units
        name, unit = gyro or path.parent.name, _session_unit(run, path.parent.name)
    return Input(samples, name, tuple(DEFAULT_MODEL.split(",")), csv_ledger_path(path),
                 None, "csv", unit)


def _choose(where: Path, gyros: list[str], gyro: str | None) -> str:
    """The gyro asked for, or the only one."""
    if gyro is None:
        if len(gyros) != 1:
            raise DataError(f"{where}: the run has gyros {', '.join(gyros) or 'none'}; "
                            "choose one with --gyro")
        return gyros[0]
    if gyro not in gyros:
        raise DataError(f"{where}: no gyro {gyro!r} (the run has {', '.join(gyros)})")
    return gyro


def _session_unit(info: dict[str, Any], gyro: str) -> str:
    """The drift signal's unit in the run's DBC (through its session file), else ``y``."""
    from ..config import load_config

    path = info.get("config")
    if not path:
        return DRIFT_UNIT
    try:
        cfg = load_config(path)
        return cfg.gyro(gyro).drift.unit or DRIFT_UNIT
    except (GyrostandError, OSError, ValueError, KeyError) as exc:
        log.info("drift unit unknown (session %s not readable: %s)", path, exc)
        return DRIFT_UNIT


def _run_of_csv(path: Path) -> dict[str, Any] | None:
    """``result.json`` of the run folder a ``<run>/<gyro>/samples.csv`` lies in, else
    None."""
    result = path.parent.parent / RESULT
    if path.name != samples_path(Path("."), path.parent.name).name or not result.is_file():
        return None
    try:
        info = json.loads(result.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    ok = isinstance(info, dict) and path.parent.name in (info.get("gyros") or {})
    return info if ok else None


def _run_input(path: Path, gyro: str | None) -> Input:
    info = read_result(path)
    gyros = info.get("gyros", {})
    name = _choose(path, list(gyros), gyro)
    spath = samples_path(path, name)
    if not spath.exists():
        raise DataError(f"{path}: no samples for gyro {name!r} ({spath} is missing)")
    s = Samples.read_csv(spath, dt=float(info.get("dt", 1.0)))
    t = s.t - s.t[0]  # time from the first bin (the absolute epoch times stay in the file)
    t.setflags(write=False)
    configured = tuple(gyros[name].get("model", DEFAULT_MODEL.split(",")))
    return Input(s.replace(t=t), name, configured, path / LEDGER, path, "run",
                 _session_unit(info, name))


def _log_input(path: Path, gyro: str | None, config: str | Path | None) -> Input:
    if config is None:
        raise UsageError(f"{path}: a raw CAN log is read through the session file that "
                         "decodes it: give --config SESSION.yaml (its DBC mapping, gyros "
                         "and sampling; e.g. the one the run was recorded with)")
    from ..config import load_config
    from ..core.model import Model
    from ..session.offline import log_samples

    cfg = load_config(config)
    name = _choose(path, [g.name for g in cfg.gyros], gyro)
    series = log_samples(cfg, path)
    if name not in series:
        g = cfg.gyro(name)
        raise DataError(f"{path}: no frame of gyro {name!r} decoded (its messages "
                        f"{g.drift.signal.message.name}, {g.temperature.signal.message.name} "
                        f"of {cfg.path})")
    g = cfg.gyro(name)
    return Input(series[name], name, tuple(Model.parse(list(g.model)).names),
                 csv_ledger_path(path), None, "log", g.drift.unit or DRIFT_UNIT)


def _parquet_input(path: Path, gyro: str | None, dt: float | None) -> Input:
    try:
        import pyarrow.parquet as pq
    except ImportError:
        raise MissingPackageError(f"{path}: reading Parquet needs the pyarrow package: pip install "
                                  "'gyrostand[formats]'") from None
    try:
        table = pq.read_table(path)
    except Exception as exc:  # pyarrow's ArrowInvalid, OSError: not a Parquet file
        raise DataError(f"{path}: cannot read as Parquet: {exc}") from None
    meta = {k.decode(): v.decode() for k, v in (table.schema.metadata or {}).items()}
    missing = [c for c in ("t", "drift", "temp") if c not in table.column_names]
    if missing:
        what = f" ({meta['table']} table)" if "table" in meta else ""
        raise DataError(f"{path}: not a samples table{what}: missing column(s) "
                        f"{', '.join(missing)} (has {', '.join(table.column_names)})")
    cols = {c: table.column(c).to_numpy(zero_copy_only=False).astype(float)
            for c in ("t", "drift", "temp", "n_drift") if c in table.column_names}
    s = Samples.from_arrays(cols["t"], cols["drift"], cols["temp"], dt=dt, source=str(path),
                            counts=cols.get("n_drift"))
    t = s.t - s.t[0]
    t.setflags(write=False)
    field = table.schema.field("drift")
    unit = ((field.metadata or {}).get(b"unit", b"").decode() or DRIFT_UNIT)
    name = gyro or meta.get("gyro") or path.parent.name
    return Input(s.replace(t=t), name, tuple(DEFAULT_MODEL.split(",")),
                 csv_ledger_path(path), None, "parquet", unit)
