"""Continuing a run folder after a crash or a stop (``gyrostand run --resume``).

What a resumed run keeps: every *acknowledged* 1-s sample (a row of ``<gyro>/samples.csv``
on disk; the daemon writes a row only after the raw log holds every frame it was binned
from, see :class:`~gyrostand.runfolder.SamplesWriter`), the online estimates of those
bins (``estimates.csv``), the ledger, ``run.log`` (appended) and the earlier raw segments.
What it does:

* a torn last line of ``samples.csv`` / ``estimates.csv`` (no line end: the process died
  while appending it) is cut off; estimate rows of bins that never reached
  ``samples.csv`` are cut off too, so both files end at the same bin;
* the online identifiers are rebuilt by feeding them the kept bins again (estimate rows
  missing for kept bins are written then);
* binning continues on the same grid after each gyro's last kept bin: bins until the
  first new frame are gaps (n = 0; at most ``sampling.max_gap`` of them, a longer pause
  shows as a jump of ``t``), older frames are late;
* the raw log continues in a new segment, ``raw-2.blf``, ``raw-3.blf``, ...
  (:func:`~gyrostand.runfolder.raw_segments`); ``gyrostand replay CONFIG RUN_DIR``
  replays them in order.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..config import SessionConfig
from ..core.model import Model
from ..errors import ConfigError, OutputError
from ..runfolder import (
    RESULT,
    cut_estimates_after,
    cut_torn_tail,
    estimate_columns,
    estimates_path,
    latest_run_dir,
    next_raw_segment,
    read_header,
    read_result_or_none,
    read_samples_csv,
    samples_path,
)
from .final import channels_of
from .online import ONLINE

__all__ = ["ResumeState", "prepare_resume", "find_resume_dir", "check_compatible"]

log = logging.getLogger(__name__)


@dataclass
class ResumeState:
    """What a resumed pipeline continues from: per gyro the kept bins' columns (as
    :func:`read_samples_csv` gives them) and the ``t`` of its last estimates row; the grid
    origin ``t0`` (s) and the raw segment to record into."""

    run_dir: Path
    segment: Path
    t0: float | None
    columns: dict[str, dict[str, list[float]]] = field(default_factory=dict)
    estimates_until: dict[str, float] = field(default_factory=dict)

    def last_k(self, dt: float) -> dict[str, int]:
        """Index on the grid of each gyro's last kept bin."""
        if self.t0 is None:
            return {}
        return {g: round((c["t"][-1] - self.t0) / dt) for g, c in self.columns.items()
                if c["t"]}


def find_resume_dir(cfg: SessionConfig, where: str | Path | None,
                    out: str | Path | None = None) -> Path:
    """``where`` if given (a run folder), else the newest run folder of the session under
    ``out`` (default ``session.output``)."""
    if where:
        p = Path(where)
        if not p.is_dir():
            raise OutputError(f"{p}: no such run folder to resume")
        return p
    return latest_run_dir(out or cfg.output, cfg.name, live_only=True)


def _terms(model: Any) -> tuple[str, ...] | None:
    try:
        return tuple(Model.parse(list(model)).names)
    except Exception:  # a model this version cannot parse: compare as written
        return tuple(str(m) for m in model)


def check_compatible(cfg: SessionConfig, run_dir: Path) -> None:
    """Refuse to resume ``run_dir`` with a session whose ``sampling.dt``,
    ``sampling.epoch``, a gyro's ``model`` or its online ``identifiers`` differ from the
    folder's (``result.json``, each ``estimates.csv`` header): its bins, grid and
    estimate columns would no longer match. Raises :class:`ConfigError` naming the key."""
    src = cfg.path
    rp = run_dir / RESULT
    doc = read_result_or_none(run_dir)
    if doc is None:
        log.warning("%s: unreadable; resuming without comparing dt and epoch", rp)
    if isinstance(doc, dict):
        source = doc.get("source")
        if isinstance(source, str) and source != "live":
            raise ConfigError(f"{run_dir}: a folder of a {source!r}, not of a live run: "
                              f"--resume continues a live run's folder (its raw log is the "
                              f"bus's); replay the logs again instead")
        was_ch = doc.get("channels")
        if isinstance(was_ch, dict):
            now = channels_of(cfg)
            for i, g in enumerate(cfg.gyros):
                old = was_ch.get(g.name)
                for role in ("drift", "temperature"):
                    if isinstance(old, dict) and old.get(role) not in (None,
                                                                       now[g.name][role]):
                        raise ConfigError(
                            f"{src}: gyros[{i}].{role}: {now[g.name][role]} differs from "
                            f"the run folder's {old[role]} ({rp}): two sensors would be "
                            "mixed in one samples.csv; resume with the session it was "
                            "started with")
        dt = doc.get("dt")
        if isinstance(dt, (int, float)) and not isinstance(dt, bool) and \
                float(dt) != cfg.sampling.dt:
            raise ConfigError(f"{src}: sampling.dt: {cfg.sampling.dt:g} differs from the run "
                              f"folder's {float(dt):g} ({rp}): resume with the session it "
                              f"was started with")
        if "epoch" in doc and doc["epoch"] != cfg.sampling.epoch:
            raise ConfigError(f"{src}: sampling.epoch: {cfg.sampling.epoch!r} differs from "
                              f"the run folder's {doc['epoch']!r} ({rp})")
        gyros = doc.get("gyros")
        for i, g in enumerate(cfg.gyros):
            was = gyros.get(g.name) if isinstance(gyros, dict) else None
            model = was.get("model") if isinstance(was, dict) else None
            if isinstance(model, list) and _terms(model) != _terms(g.model):
                raise ConfigError(f"{src}: gyros[{i}].model: {list(g.model)} differs from "
                                  f"the run folder's {model} ({rp})")
    for i, g in enumerate(cfg.gyros):
        ep = estimates_path(run_dir, g.name)
        header = read_header(ep)
        if header is None:
            continue
        online = [x for x in g.identifiers if x in ONLINE]
        want = estimate_columns(online, Model.parse(g.model).param_names)
        if header != want:
            was = list(dict.fromkeys(c.split(":", 1)[0] for c in header[1:]))
            key = "identifiers" if was != online else "model"
            raise ConfigError(f"{src}: gyros[{i}].{key}: the online estimates "
                              f"({', '.join(online) or 'none'}; {len(want)} columns) differ "
                              f"from the run folder's ({', '.join(was) or 'none'}; "
                              f"{len(header)} columns, {ep}): resume with the session it "
                              f"was started with")


def prepare_resume(cfg: SessionConfig, run_dir: Path) -> ResumeState:
    """Check and repair the run folder's growing files; return what to continue from.
    A session that does not match the folder is refused first (:func:`check_compatible`)."""
    check_compatible(cfg, run_dir)
    if not any(samples_path(run_dir, g.name).is_file() for g in cfg.gyros):
        raise OutputError(f"{run_dir}: not a run folder of session {cfg.name!r} (no "
                          f"<gyro>/samples.csv of gyros {', '.join(g.name for g in cfg.gyros)})")
    state = ResumeState(run_dir, next_raw_segment(run_dir), None)
    firsts: list[float] = []
    for g in cfg.gyros:
        sp = samples_path(run_dir, g.name)
        if not sp.is_file():
            continue
        try:
            cut_torn_tail(sp)
            if sp.stat().st_size == 0:  # even the header was torn: start the file over
                continue
            cols = read_samples_csv(sp)
        except OSError as exc:
            raise OutputError(f"{sp}: cannot resume from it: {exc.strerror or exc}") from exc
        state.columns[g.name] = cols
        if cols["t"]:
            firsts.append(cols["t"][0])
        ep = estimates_path(run_dir, g.name)
        if ep.is_file() and ep.stat().st_size > 0:
            cut_torn_tail(ep)
            last = cut_estimates_after(ep, cols["t"][-1] if cols["t"] else None)
            if last is not None:
                state.estimates_until[g.name] = last
    if cfg.sampling.epoch is not None:
        state.t0 = cfg.sampling.epoch
    elif firsts:
        state.t0 = min(firsts)
    n = {g: len(c["t"]) for g, c in state.columns.items()}
    log.info("resuming %s: kept bins %s; raw log continues in %s", run_dir, n,
             state.segment.name)
    return state
