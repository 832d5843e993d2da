"""Make the fixed raw log and the golden hashes of ``tests/session/test_runfolder_golden.py``.

Run from the repository root (``.venv/bin/python tests/data/runfolder/make_golden.py``):

1. ``replay.blf``: the demo stand's frames (configs/demo.yaml, seed 42) for 600 s at 20 Hz
   drift / 10 Hz temperature, with the demo's jitter, drops and quantization, and no frame
   at all in [200 s, 205 s) so the run has gap bins (``nan`` cells, n = 0);
2. ``golden.json``: the sha256 and size of ``az/samples.csv`` and ``az/estimates.csv`` of
   a replay of that log, and the first and last rows of each.

The log is made once and kept (frames are the fixed input; regenerating it only when the
frame simulator changes on purpose). The hashes were recorded on main c05478b, before the
run-folder module existed: a replay must give the same bytes after any refactoring.
"""

from __future__ import annotations

import copy
import hashlib
import json
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[2]
sys.path.insert(0, str(ROOT))
import tests  # noqa: E402, F401  (the suite's pinned numerics, before can imports numpy)

# isort: split
import can  # noqa: E402
import yaml  # noqa: E402

from gyrostand.config import parse_config  # noqa: E402
from gyrostand.session.offline import run_replay, simulated_frames  # noqa: E402

LOG = HERE / "replay.blf"
GOLDEN = HERE / "golden.json"
GAP = (1700000200.0, 1700000205.0)  # s: no frames (gap bins)


def config(out: Path):
    d = yaml.safe_load((ROOT / "configs" / "demo.yaml").read_text())
    d = copy.deepcopy(d)
    d["session"]["output"] = str(out)
    d["simulate"]["duration"] = 600
    d["simulate"]["rates"] = {"drift": 20, "temperature": 10}
    return parse_config(d, source="golden.yaml", base_dir=ROOT / "configs")


def digest(path: Path) -> dict[str, object]:
    data = path.read_bytes()
    lines = data.decode().split("\n")
    return {"sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data),
            "rows": len(lines) - 2, "first": lines[1], "last": lines[-2]}


def replay_digests(log_path: Path, out: Path) -> dict[str, dict[str, object]]:
    rep = run_replay(config(out), log_path, out=out)
    return {name: digest(rep.run_dir / "az" / name)
            for name in ("samples.csv", "estimates.csv")}


def main() -> None:
    if not LOG.exists():
        with tempfile.TemporaryDirectory() as tmp:
            frames = [m for m in simulated_frames(config(Path(tmp)))
                      if not GAP[0] <= m.timestamp < GAP[1]]
        with can.BLFWriter(str(LOG)) as w:
            for m in frames:
                w.on_message_received(m)
    with tempfile.TemporaryDirectory() as tmp:
        got = replay_digests(LOG, Path(tmp))
    GOLDEN.write_text(json.dumps(got, indent=1) + "\n")
    print(json.dumps(got, indent=1))


if __name__ == "__main__":
    main()
