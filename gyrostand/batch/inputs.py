"""What a batch runs on: a list of :class:`RunSpec`, one per run.

A run is either

* a **run folder** written by ``gyrostand run`` / ``replay`` (``result.json`` and the
  gyros' ``samples.csv``; its raw segments ``raw.blf``, ``raw-2.blf``, ... when it is to be
  replayed again), or
* a **raw log** (BLF, ASC, candump .log, CSV, ... whatever python-can reads) with the
  session file that decodes it: ``--config`` for every log, or the manifest's ``config``
  column per log.

Inputs are paths or globs (``'archive/**/*.blf'``, expanded here, so a quoted pattern works
where a shell would not expand it), and a **manifest** CSV: one row per run, a ``path``
column (a run folder or a log, relative to the manifest's folder), optionally ``config``
(a log's session file, relative likewise) and ``run`` (the run's name in the table), and
any other column a run attribute copied into the fleet table as it is (``serial``, ``date``,
``orientation``, ``test``, ``type`` ...).

A run's name (``run``, the key of its result in the batch folder and of its rows in the
table) is the manifest's ``run``, else the file's stem or the folder's name, with a short
hash of the absolute path appended when two inputs would share a name: the same input gets
the same name in every batch, whatever the order of the inputs.
"""

from __future__ import annotations

import csv
import glob
import hashlib
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import ConfigError, DataError, NoInputError

__all__ = ["RunSpec", "collect_runs", "read_manifest"]

#: manifest columns that are not run attributes
RESERVED = ("path", "config", "run")
_NAME_RE = re.compile(r"[^A-Za-z0-9_.+-]+")


@dataclass(frozen=True)
class RunSpec:
    """One run of the batch: ``kind`` ``"folder"`` or ``"log"``, absolute paths."""

    run: str
    kind: str
    path: str
    config: str | None = None
    attrs: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, object]:
        return {"run": self.run, "kind": self.kind, "path": self.path,
                "config": self.config, "attrs": dict(self.attrs)}


def _is_run_folder(p: Path) -> bool:
    return (p / "result.json").is_file() or any(p.glob("raw*.blf"))


def _expand(item: str) -> list[Path]:
    """A path, or a glob's matches (sorted); a glob that matches nothing is an error."""
    if glob.has_magic(item):
        hits = sorted(glob.glob(item, recursive=True))
        if not hits:
            raise NoInputError(f"{item}: the pattern matches no file or folder")
        return [Path(h) for h in hits]
    return [Path(item)]


def _resolve(path: Path, where: str = "") -> Path:
    """``path`` made absolute with its symlinks resolved; a symlink loop is an error naming
    it (Python 3.11 raises RuntimeError, later versions OSError ELOOP)."""
    try:
        return path.resolve()
    except (RuntimeError, OSError) as exc:
        raise NoInputError(f"{where}{path}: cannot resolve the path ({exc})") from None


def _spec(path: Path, config: str | Path | None, attrs: dict[str, str], name: str | None,
          where: str) -> tuple[str | None, RunSpec]:
    path = _resolve(path, where)
    if path.is_dir():
        if not _is_run_folder(path):
            raise NoInputError(f"{where}{path}: not a run folder (no result.json, no raw.blf)")
        kind = "folder"
    elif path.is_file():
        kind = "log"
        if config is None:
            raise ConfigError(f"{where}{path}: a raw log needs the session file that decodes "
                              "it: --config FILE, or a 'config' column in the manifest")
    else:
        raise NoInputError(f"{where}{path}: no such run folder or log file")
    cfg = str(_resolve(Path(config), where)) if config is not None else None
    if cfg is not None and not Path(cfg).is_file():
        raise ConfigError(f"{where}{cfg}: no such session file")
    stem = path.name if kind == "folder" else path.stem
    return name, RunSpec(run=_NAME_RE.sub("_", name or stem), kind=kind, path=str(path),
                         config=cfg, attrs=attrs)


def read_manifest(path: str | Path) -> list[tuple[str | None, RunSpec]]:
    """The manifest's runs (see the module docstring); a bad row names its line."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise DataError(f"{path}: cannot read the manifest: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    reader = csv.DictReader(text.splitlines())
    try:
        cols = [c.strip() for c in (reader.fieldnames or [])]
        rows = list(reader)
    except csv.Error as exc:  # e.g. a cell over csv.field_size_limit() (128 KiB)
        raise DataError(f"{path}: line {reader.reader.line_num}: not CSV ({exc})") from None
    if "path" not in cols:
        raise DataError(f"{path}: line 1: the manifest needs a 'path' column (got "
                        f"{', '.join(cols) or 'no header'})")
    base = _resolve(path).parent
    out = []
    for line, row in enumerate(rows, start=2):
        row = {(k or "").strip(): (v or "").strip() for k, v in row.items() if k is not None}
        if not any(row.values()):
            continue
        if not row.get("path"):
            raise DataError(f"{path}: line {line}: empty 'path'")
        attrs = {k: v for k, v in row.items() if k not in RESERVED}
        cfg = base / row["config"] if row.get("config") else None
        out.append(_spec(base / row["path"], cfg, attrs, row.get("run") or None,
                         f"{path}: line {line}: "))
    return out


def collect_runs(inputs: Sequence[str], *, config: str | Path | None = None,
                 manifest: str | Path | None = None) -> list[RunSpec]:
    """Every run of the batch, in input order, each once (a run listed twice — by a glob
    and in the manifest — keeps the manifest's attributes); names unique."""
    found: list[tuple[str | None, RunSpec]] = []
    if manifest is not None:
        found += read_manifest(manifest)
    for item in inputs:
        for p in _expand(item):
            found.append(_spec(p, config, {}, None, ""))
    if not found:
        raise DataError("no runs given: run folders, logs, globs or --manifest CSV")
    seen: dict[str, tuple[str | None, RunSpec]] = {}
    for named, spec in found:
        seen.setdefault(spec.path, (named, spec))
    specs = list(seen.values())
    counts: dict[str, int] = {}
    named_runs: set[str] = set()
    for named, s in specs:
        counts[s.run] = counts.get(s.run, 0) + 1
        if named:
            if s.run in named_runs:
                raise DataError(f"run name {s.run!r} given to more than one run of the "
                                "manifest")
            named_runs.add(s.run)
    out = []
    for named, s in specs:
        if counts[s.run] > 1 and not named:
            h = hashlib.sha1(s.path.encode("utf-8")).hexdigest()[:8]
            s = RunSpec(run=f"{s.run}-{h}", kind=s.kind, path=s.path, config=s.config,
                        attrs=s.attrs)
        out.append(s)
    return out
