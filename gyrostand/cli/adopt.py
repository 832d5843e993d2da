"""``gyrostand adopt RUN [--config FILE] [--gyro G] [--dry-run]``: the run's current model
(the workbench ledger's, each gyro) written into its session file for the daemon's next
run: a minimal text edit of each gyro's ``model:`` (:mod:`gyrostand.config.edit`), a
backup beside the file, the unified diff printed, the edited file validated as ``run
--check`` validates it (the backup restored and exit 78 when it fails). A daemon reads its
session file when a run starts: a running one keeps its model until its run ends."""

from __future__ import annotations

import argparse
import difflib
import shlex
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .. import exitcodes
from ..errors import ConfigError, DataError, GyrostandError, NoInputError, SessionFileNotFoundError

if TYPE_CHECKING:
    from ..config import SessionConfig


def add_parser(sub: Any) -> None:
    p = sub.add_parser("adopt", help="write a run's current model (the ledger's) into its "
                                     "session file, for the daemon's next run",
                       description=__doc__)
    p.add_argument("run", help="a run folder (its result.json names its session file, its "
                               "ledger.jsonl the current model of each gyro)")
    p.add_argument("--config", default=None, metavar="FILE",
                   help="the session file to edit (default: the run's own)")
    p.add_argument("--gyro", action="append", default=None, metavar="G",
                   help="only this gyro (repeatable; default every gyro of the run)")
    p.add_argument("--dry-run", action="store_true",
                   help="print the diff only; the file is not changed")
    p.set_defaults(func=run)


def _validated(path: Path) -> SessionConfig:
    """The session file loaded and its bus resolved, as ``run --check`` does (without
    command-line bus options)."""
    from ..config import load_config
    from .common import with_bus_overrides

    return with_bus_overrides(load_config(path), argparse.Namespace())


def adopted_models(run_dir: Path, gyros: list[str] | None = None
                   ) -> dict[str, tuple[str, ...]]:
    """Each gyro's current model in the run (its ledger's last step), by gyro name; a
    gyro without a ledger step is left out (its model is the one the run was configured
    with: adopting it could only undo a later edit of the session file)."""
    from ..runfolder import LEDGER, read_result
    from ..workbench import read_ledger
    from ..workbench.subject import current_model

    info = read_result(run_dir)
    known = info.get("gyros", {})
    for g in gyros or []:
        if g not in known:
            raise DataError(f"{run_dir}: no gyro {g!r} (the run has {', '.join(known)})")
    stepped = {e.get("gyro") for e in read_ledger(run_dir / LEDGER) if "model" in e}
    return {g: current_model(run_dir / LEDGER, g, known[g].get("model") or ()).names
            for g in (gyros or list(known)) if g in stepped}


def plan(text: str, models: dict[str, tuple[str, ...]], source: str
         ) -> tuple[dict[str, tuple[str, ...]], dict[str, tuple[str, ...]], list[str]]:
    """What the edit changes: the gyros' new ``model`` lists (``white`` written only where
    the file lists it), their ``identifiers`` where a listed one cannot identify the new
    model (left out, as the loader leaves it out of an unlisted default), and a note each."""
    from ..config.edit import gyro_lists
    from ..core import registry
    from ..core.model import Model

    lists = gyro_lists(text, source)
    new_models: dict[str, tuple[str, ...]] = {}
    new_ids: dict[str, tuple[str, ...]] = {}
    notes: list[str] = []
    for g, names in models.items():
        if g not in lists:
            raise ConfigError(f"{source}: gyros: no gyro {g!r} (the file has "
                              f"{', '.join(lists) or 'none'}); choose --gyro or --config")
        written = lists[g]
        if set(Model.parse(list(written.model)).names) == set(names):
            continue
        keep_white = "white" in written.model
        new_models[g] = tuple(n for n in names if n != "white" or keep_white)
        if written.identifiers is not None:
            model = Model.parse(list(names))
            ids = tuple(i for i in written.identifiers if registry.get(i).refusal(model) is None)
            for i in written.identifiers:
                if i not in ids:
                    notes.append(f"gyro {g}: identifier {i} left out: "
                                 f"{registry.get(i).refusal(model)}")
            if ids != written.identifiers:
                new_ids[g] = ids or ("ml",)
    return new_models, new_ids, notes


def _backup_path(path: Path) -> Path:
    """``FILE.bak``, or ``FILE.<UTC time>.bak`` when that exists (a backup is never
    overwritten)."""
    bak = path.with_name(path.name + ".bak")
    if not bak.exists():
        return bak
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    bak, n = path.with_name(f"{path.name}.{stamp}.bak"), 1
    while bak.exists():
        n += 1
        bak = path.with_name(f"{path.name}.{stamp}-{n}.bak")
    return bak


def run(args: argparse.Namespace) -> int:
    from ..config.edit import edit_models
    from ..runfolder import read_result, write_atomic
    from .common import invocation

    run_dir = Path(args.run)
    if not run_dir.is_dir():
        raise NoInputError(f"{run_dir}: not a run folder (adopt writes a run's current model "
                           "into its session file)")
    info = read_result(run_dir)
    path = Path(args.config or info.get("config") or "")
    if not str(path) or not path.is_file():
        raise SessionFileNotFoundError(f"{run_dir}: the session file "
                                       f"{str(path) or '(none recorded)'} "
                          "is not there: give --config FILE")
    try:
        _validated(path)
    except GyrostandError as exc:
        raise ConfigError(f"{path} does not validate before the edit (nothing changed): "
                          f"{exc}") from exc
    text = path.read_text(encoding="utf-8")
    models = adopted_models(run_dir, args.gyro)
    if not models:
        print(f"{run_dir}: its ledger has no model step (diagnose, fit): the run's model is "
              f"the one it was configured with; nothing to adopt into {path}")
        return 0
    new_models, new_ids, notes = plan(text, models, str(path))
    if not new_models:
        now = "; ".join(f"{g}: {','.join(m)}" for g, m in models.items())
        print(f"{path}: the session's models are the run's current ones ({now}): nothing "
              "to adopt")
        return 0
    edited = edit_models(text, new_models, new_ids, str(path))
    diff = difflib.unified_diff(text.splitlines(keepends=True),
                                edited.splitlines(keepends=True),
                                fromfile=f"{path}", tofile=f"{path} (adopted from {run_dir})")
    print("".join(diff), end="")
    for note in notes:
        print(f"note: {note}")
    prog = invocation()
    if args.dry_run:
        print(f"dry run: {path} not changed; without --dry-run: {prog} adopt "
              f"{shlex.quote(str(run_dir))}"
              + (f" --config {shlex.quote(str(path))}" if args.config else ""))
        return 0
    bak = _backup_path(path)
    write_atomic(bak, text)
    write_atomic(path, edited)
    try:
        cfg = _validated(path)
    except GyrostandError as exc:
        write_atomic(path, text)
        print(f"error: the edited {path} does not validate as `run --check` does: {exc}; "
              f"restored it (the backup stays: {bak})", file=sys.stderr)
        return exitcodes.CONFIG
    print(f"wrote {path} (backup: {bak}); valid as `run --check`: "
          + "; ".join(f"gyro {g.name}: model {','.join(g.model)}, identifiers "
                      f"{','.join(g.identifiers)}" for g in cfg.gyros if g.name in new_models))
    print("the daemon reads its session file when a run starts: a running daemon keeps its "
          "model until its run ends; the next run uses the adopted one (as a service: "
          "systemctl restart gyrostand@STAND)")
    print(f"next: {prog} run {shlex.quote(str(path))} --check")
    return 0
