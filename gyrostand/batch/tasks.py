"""The task a Dask worker runs for one run of the batch, and the one place the batch calls
the rest of gyrostand (replay, load_config, open_subject, identify, run_diagnose): moving
those later means editing this file only.

A task:

1. makes the run's samples: a raw log is replayed (the daemon's pipeline, streamed frame
   batch by frame batch: a worker never holds more than a batch of frames and the run's
   own 1-s bins) into ``<batch>/replays/<run>/``; a run folder is used as it is, or, with
   ``replay`` in ``--do``, its raw segments are replayed again the same way. A finished
   replay in the batch folder is reused (the replay does not depend on the model);
2. for every gyro of the run: ``identify`` (``--method``, ``--model``) and/or
   ``diagnose`` (the verdict, the model error, the ranked candidates);
3. writes its record — the run's rows, or its error — to ``<batch>/results/<run>.json``
   atomically (a temporary file beside it, then :func:`os.replace`), so a batch killed at
   any moment leaves each run either done or not started, never half-written.

A failure of one gyro (e.g. too few samples) is that row's error; a failure of the run (a
log that cannot be read, a session file that does not load) is the run's error: the task
returns a record either way and never raises, so one bad run never stops the batch.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import socket
import time
import traceback
import uuid
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from ..errors import DataError
from ..runfolder.layout import REPORT, RESULT
from .inputs import RunSpec

__all__ = ["TaskOptions", "run_task", "failed_record", "result_path", "read_record",
           "DO_STEPS"]

log = logging.getLogger(__name__)

#: what ``--do`` may ask, in the order it is done
DO_STEPS = ("replay", "identify", "diagnose")
#: bump when a record's shape changes: older records are then redone
RECORD_VERSION = 1


@dataclass(frozen=True)
class TaskOptions:
    """What every task of the batch does (part of each record: a record made with other
    options is redone, e.g. after a model change)."""

    do: tuple[str, ...] = ("identify", "diagnose")
    model: str | None = None  # None: each gyro's current model (ledger, else configured)
    method: str = "ml"
    identify_options: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["do"] = list(self.do)
        return d


def result_path(out: str | Path, run: str) -> Path:
    return Path(out) / "results" / f"{run}.json"


def read_record(out: str | Path, run: str) -> dict[str, Any] | None:
    """The run's record, or None when there is none (or it is unreadable: redone)."""
    path = result_path(out, run)
    try:
        rec = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as exc:
        log.warning("%s: unreadable record, the run is redone (%s)", path, exc)
        return None
    return rec if isinstance(rec, dict) else None


def _write_record(out: str | Path, rec: dict[str, Any]) -> None:
    from ..runfolder import write_atomic

    path = result_path(out, rec["run"])
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, json.dumps(rec, indent=1, allow_nan=False) + "\n")


def _error_text(exc: BaseException) -> str:
    from ..errors import GyrostandError

    text = str(exc) if isinstance(exc, GyrostandError) else f"{type(exc).__name__}: {exc}"
    return text.strip()[:2000] or type(exc).__name__


def _finite(x: Any) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if v == v and abs(v) != float("inf") else None


# --- step 1: the run's samples ------------------------------------------------------------

def _replay_into(spec: RunSpec, out: Path) -> Path:
    """Replay the run into ``<out>/replays/<run>`` (reused when already finished)."""
    from ..config import load_config
    from ..runfolder import raw_segments
    from ..session.offline import run_replay

    dest = out / "replays" / spec.run
    done = dest / RESULT
    if done.is_file():
        try:
            info = json.loads(done.read_text(encoding="utf-8"))
            if info.get("state") not in ("running", "failed") and \
                    info.get("batch_source") == spec.path:
                return dest
        except (OSError, ValueError):
            pass
    if spec.kind == "folder":
        logs: list[Path] = raw_segments(Path(spec.path))
        if not logs:
            raise DataError(f"{spec.path}: no raw log (raw.blf) to replay")
        config = spec.config
        if config is None:
            info = json.loads((Path(spec.path) / RESULT).read_text(encoding="utf-8"))
            config = info.get("config")
            if not config:
                raise DataError(f"{spec.path}/{RESULT}: no 'config' to replay it with")
    else:
        logs = [Path(spec.path)]
        config = spec.config
    assert config is not None
    cfg = load_config(config)
    # a staging folder of its own (a task a killed client left running may still be
    # replaying the same run into another one)
    staging = out / "replays" / f".{spec.run}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    try:
        outcome = run_replay(cfg, logs[0] if len(logs) == 1 else logs, out=staging,
                             parallel=False)  # one core per worker; Dask workers are daemons
        info = json.loads(outcome.result_json.read_text(encoding="utf-8"))
        info["batch_source"] = spec.path
        (outcome.run_dir / RESULT).write_text(json.dumps(info, indent=2) + "\n",
                                                     encoding="utf-8")
        shutil.rmtree(dest, ignore_errors=True)
        os.replace(outcome.run_dir, dest)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return dest


def _run_info(run_dir: Path) -> dict[str, Any]:
    from ..cli.workbench_args import check_run_folder

    check_run_folder(run_dir)
    info = json.loads((run_dir / RESULT).read_text(encoding="utf-8"))
    if info.get("state") == "failed":
        raise DataError(f"{run_dir}: the run failed: {info.get('error', 'no reason given')}")
    return info


# --- step 2: one gyro ---------------------------------------------------------------------

def _gyro_row(run_dir: Path, gyro: str, ginfo: dict[str, Any], opts: TaskOptions
              ) -> dict[str, Any]:
    from ..core.registry import identify
    from ..workbench import open_subject, run_diagnose

    row: dict[str, Any] = {"gyro": gyro, "bins": ginfo.get("bins"), "gaps": ginfo.get("gaps"),
                           "observed": ginfo.get("observed")}
    subject = open_subject(run_dir, gyro=gyro, model=opts.model)
    row["model"] = ",".join(subject.model.names)
    row["unit"] = subject.unit
    fit = None
    if "diagnose" in opts.do:
        rep = run_diagnose(subject, record=False)  # the archive's ledgers stay untouched
        d = rep.diagnosis
        row.update(verdict="adequate" if rep.adequate else "not adequate",
                   reasons="; ".join(rep.reasons), rms=_finite(d.rms),
                   ljung_box_p=_finite(d.ljung_box_p))
        if rep.model_error is not None:
            row.update(model_error=_finite(rep.model_error.rms),
                       model_error_floor=_finite(rep.model_error.floor))
        top = rep.candidates[0] if rep.candidates else None
        sig = {c.term for c in rep.significant}
        row.update(top_candidate=top.term if top else None,
                   top_lr=_finite(top.lr_stat) if top else None,
                   top_p=_finite(top.p_value) if top else None,
                   top_delta_bic=_finite(top.delta_bic) if top else None,
                   top_significant=(top.term in sig) if top else None,
                   significant=",".join(c.term for c in rep.significant))
        if opts.method == "ml":
            fit = rep.fit
    if "identify" in opts.do and fit is None:
        fit = identify(subject.samples, subject.model, opts.method, **opts.identify_options)
    if fit is not None:
        row["method"] = fit.method
        row["loglik"] = _finite(fit.loglik)
        row.setdefault("rms", _finite(fit.residual_rms))
        row["params"] = {k: [float(e.value), float(e.std)] for k, e in fit.parameters.items()}
        if fit.warnings:
            row["warnings"] = "; ".join(fit.warnings)
    return row


def _peak_rss_mib() -> float | None:
    """This worker process's peak resident memory so far (MiB), where the OS tells."""
    try:
        import resource
    except ImportError:  # not on Windows
        return None
    kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    return round(kib / 1024, 1)


# --- the task -----------------------------------------------------------------------------

def run_task(spec: RunSpec, opts: TaskOptions, out: str) -> dict[str, Any]:
    """Do ``opts`` for one run; write and return its record (never raises)."""
    t0 = time.perf_counter()
    out_p = Path(out)
    rec: dict[str, Any] = {"version": RECORD_VERSION, "run": spec.run, "input": spec.to_dict(),
                           "options": opts.to_dict(), "host": socket.gethostname(),
                           "pid": os.getpid(), "rows": []}
    try:
        if spec.kind == "log" or "replay" in opts.do:
            run_dir = _replay_into(spec, out_p)
        else:
            run_dir = Path(spec.path)
        info = _run_info(run_dir)
        dec = info.get("stats", {}).get("decoder", {})
        rec["run_dir"] = str(run_dir)
        report = run_dir / "report.html"
        rec["report"] = str(report if report.is_file() else run_dir / REPORT)
        damage = info.get("stats", {}).get("log") or {}
        n_damage = sum(int(damage.get(k) or 0) for k in ("containers_skipped", "truncated",
                                                          "lines_skipped"))
        rec["counts"] = {"frames": dec.get("received"), "decoded": dec.get("decoded"),
                         "rejected": dec.get("rejected_total"), "log_damage": n_damage}
        if dec and not dec.get("received"):
            notes = "; ".join(str(n) for n in damage.get("notes") or ())
            raise DataError(f"{spec.path}: no CAN frame read from the log"
                             + (f" ({notes})" if notes else ""))
        gyros = info.get("gyros") or {}
        if not gyros:
            raise DataError(f"{run_dir}/{RESULT}: the run has no gyros")
        for gyro, ginfo in gyros.items():
            try:
                row = _gyro_row(run_dir, gyro, ginfo, opts)
                # fitted, but on a log with damage: not "ok" where people filter
                row["status"] = "damaged" if n_damage else "ok"
            except Exception as exc:  # noqa: BLE001 - the row says what failed
                log.info("%s gyro %s failed: %s", spec.run, gyro, exc)
                row = {"gyro": gyro, "status": "failed", "error": _error_text(exc),
                       "bins": ginfo.get("bins"), "gaps": ginfo.get("gaps")}
            rec["rows"].append(row)
        oks = sum(r["status"] in ("ok", "damaged") for r in rec["rows"])
        rec["status"] = "ok" if oks == len(rec["rows"]) else "partial" if oks else "failed"
        if not oks:
            rec["error"] = "; ".join(f"gyro {r['gyro']}: {r['error']}" for r in rec["rows"])
    except Exception as exc:  # noqa: BLE001 - a run's failure is its record, not the batch's
        rec["status"] = "failed"
        rec["error"] = _error_text(exc)
        rec["traceback"] = traceback.format_exc()[-4000:]
    rec["seconds"] = round(time.perf_counter() - t0, 3)
    rec["worker_peak_rss_mib"] = _peak_rss_mib()
    try:
        _write_record(out_p, rec)
    except Exception as exc:  # noqa: BLE001 - the client records it then
        rec["unwritten"] = _error_text(exc)
    return rec


def failed_record(spec: RunSpec, opts: TaskOptions, out: str | Path,
                  error: str) -> dict[str, Any]:
    """The record of a task Dask itself lost (e.g. its worker died, or was killed for
    exceeding its memory): written by the client."""
    rec = {"version": RECORD_VERSION, "run": spec.run, "input": spec.to_dict(),
           "options": opts.to_dict(), "rows": [], "status": "failed", "error": error[:2000],
           "seconds": None}
    _write_record(out, rec)
    return rec
