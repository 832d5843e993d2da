"""Replay throughput of the whole daemon pipeline vs bare ``can.LogReader`` iteration.

A 1-million-frame BLF of the three-gyro stand (``configs/three-gyros.yaml``: 3 gyros x
(200 Hz drift + 10 Hz temperature), jitter, drops) is generated once (cached in the temp
folder), then, in this one process:

* bare: ``for msg in can.LogReader(path): pass``;
* pipeline: ``gyrostand replay`` (``session.offline.run_replay``): decode, check, bin,
  online LKF + LSQ per bin, samples/estimates CSVs, response frames built; the final batch
  fits (LSQ, LKF, ML per gyro) are timed separately. As ``gyrostand replay`` does by
  default for a log this size, python-can's reader runs in a reader process
  (``gyrostand.can.logs.reader``) while this process decodes, bins and estimates;
* the same pipeline with the log parsed in this process (``--reader inline``), for
  comparison;
* the array path, what ``gyrostand replay`` now does by default for a BLF: containers
  parsed as arrays (``gyrostand.can.logs.blfarray``), mapped signals extracted as arrays and
  the listener's rules applied to whole batches (``DecodingListener.receive_arrays``),
  in this process (stretch anchor: >= 2 x bare). The two lines above are the per-frame
  path (``GYROSTAND_PER_FRAME=1``), as measured before the array path existed; the
  bins are byte-identical either way (tests/can/test_array_path.py).

* an independent script of the same job: ``can.LogReader`` + cantools'
  ``Database.decode_message`` + a dict of 1-s bin sums (anchor: the pipeline in
  <= 0.8 x its time).

Two layouts are measured: ours (``dbc/gyrostand.dbc``: standard ids, little-endian,
byte-aligned signals) and a foreign one (``benchmarks/data/foreign_triad.dbc``: extended
ids, Motorola signals of 22 and 11 bits, a scaled and offset unsigned temperature, 4-bit
counters), the same simulated triad encoded in each. Printed per layout: frames/s of
each, the ratio pipeline/bare (anchor: >= 0.7), the ratio pipeline/independent script,
and the CPU time (this process + the reader process) per frame.

    .venv/bin/python benchmarks/replay_throughput.py [--frames N] [--repeat R]
                                                     [--layout ours|foreign|both]
"""

from __future__ import annotations

import argparse
import copy
import logging
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import can
import yaml

from gyrostand.can.framesim import write_log
from gyrostand.config import parse_config
from gyrostand.session import offline
from gyrostand.session.offline import simulated_frames

ROOT = Path(__file__).resolve().parents[1]
TRIAD = ROOT / "configs" / "three-gyros.yaml"
FRAMES_PER_S = 3 * (200 + 10)


FOREIGN_DBC = ROOT / "benchmarks" / "data" / "foreign_triad.dbc"


def triad_cfg(frames: int, out: Path, layout: str = "ours"):
    return parse_config(triad_dict(frames, out, layout), source=str(TRIAD),
                        base_dir=TRIAD.parent)


def triad_dict(frames: int, out: Path, layout: str = "ours") -> dict:
    """The session document of :func:`triad_cfg` (its DBC path absolute)."""
    d = yaml.safe_load(TRIAD.read_text())
    d = copy.deepcopy(d)
    d["session"]["output"] = str(out)
    d["simulate"]["duration"] = float(round(frames / FRAMES_PER_S))
    if layout == "foreign":  # the same triad and simulation, another DBC: a logger stand
        d["dbc"] = str(FOREIGN_DBC)
        d.pop("responses", None)
        d["simulate"]["quantization"]["temperature"] = 0.1
        for g in d["gyros"]:
            ax = g["name"].upper()
            g.pop("result", None)
            g["drift"] = {"message": f"FOG_{ax}_RATE", "signal": f"{ax}Rate",
                          "counter": f"{ax}Seq"}
            g["temperature"] = {"message": f"FOG_{ax}_TEMP", "signal": f"{ax}Temp",
                                "counter": f"{ax}TSeq"}
    else:
        d["dbc"] = str((TRIAD.parent / d["dbc"]).resolve())
    return d


BARE_LOOP = "import can, sys\nfor msg in can.LogReader(sys.argv[1]):\n    pass\n"


def _child(argv: list[str], env: dict[str, str] | None = None) -> tuple[float, float]:
    """Wall and CPU (user + sys) s of one command in a fresh process, run in this
    checkout's root (``python -m gyrostand`` imports the gyrostand of its working folder
    first: the one measured is this script's own, whatever the caller's folder)."""
    before = os.times()
    t = time.perf_counter()
    p = subprocess.run(argv, capture_output=True, text=True, env=env, cwd=ROOT)
    wall = time.perf_counter() - t
    after = os.times()
    if p.returncode != 0:
        raise SystemExit(f"{argv[:4]} failed ({p.returncode}): {p.stderr[-1500:]}")
    return wall, (after.children_user - before.children_user
                  + after.children_system - before.children_system)


def whole_command(layout: str, frames: int, path: Path, out: Path, pairs: int,
                  bytecode_cache: bool = True) -> None:
    """The whole ``gyrostand replay`` command (a fresh process: imports, stream, final
    fits, result.json, report.txt) against the bare ``for msg in can.LogReader(path)``
    loop in a fresh process, in turn, ``pairs`` times: the ratio bare/whole pair by pair
    (>= 1.0: the command at least as fast as the bare loop; issue 25 item 5)."""
    cfg_path = out / f"triad_{layout}.yaml"
    cfg_path.write_text(yaml.safe_dump(triad_dict(frames, out, layout)))
    replay_cmd = [sys.executable, "-m", "gyrostand", "-q", "replay", str(cfg_path),
                  str(path), "--out", str(out / "whole")]
    bare_cmd = [sys.executable, "-c", BARE_LOOP, str(path)]
    # Both commands with their modules' bytecode cached, as in an installed package (pip
    # compiles it): with PYTHONDONTWRITEBYTECODE set (this machine's environment) an
    # editable install's own modules are compiled from source at every start (~0.5 s of
    # CPU for gyrostand's ~110 modules on the replay path) while python-can's come from
    # site-packages' .pyc files. The cache goes to a folder of its own (no __pycache__ in
    # the source tree); the warm-up runs fill it. --no-bytecode-cache: as the environment is.
    env = None
    if bytecode_cache:
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        env["PYTHONPYCACHEPREFIX"] = str(out / "pycache")
    head = subprocess.run(["git", "-C", str(ROOT), "log", "-1", "--format=%h"],
                          capture_output=True, text=True).stdout.strip() or "?"
    print(f"  (gyrostand of {ROOT} at {head}; "
          f"{'bytecode cached' if bytecode_cache else 'bytecode as the environment has it'}"
          f"; PYTHONDONTWRITEBYTECODE={os.environ.get('PYTHONDONTWRITEBYTECODE', '')!r} here)")
    _child(bare_cmd, env)  # warm: the file in the page cache, numba's kernels in their cache
    _child(replay_cmd, env)
    rows = [(*_child(bare_cmd, env), *_child(replay_cmd, env)) for _ in range(pairs)]
    for bw, bc, rw, rc in rows:
        print(f"  pair: bare loop {bw:6.2f} s wall {bc:5.2f} s CPU; whole replay {rw:6.2f} s "
              f"wall {rc:5.2f} s CPU: {bw / rw:.2f}x by wall, {bc / rc:.2f}x by CPU")
    wall = statistics.median(r[0] / r[2] for r in rows)
    cpu = statistics.median(r[1] / r[3] for r in rows)
    print(f"whole command ({layout}) vs the bare loop, median of {pairs} pairs: {wall:.2f}x "
          f"by wall, {cpu:.2f}x by CPU (anchor >= 1.0: {'PASS' if wall >= 1.0 else 'MISS'})")


def independent(cfg, path: Path) -> float:
    """s for read + decode + 1-s binning written plainly with python-can and cantools:
    the mapped signals' per-bin sums and counts, nothing checked, nothing estimated."""
    t = time.perf_counter()
    db = cfg.db
    wanted: dict[tuple[int, bool], list[tuple[str, int]]] = {}
    for g, gyro in enumerate(cfg.gyros):
        for c, ch in enumerate((gyro.drift, gyro.temperature)):
            ref = ch.signal.message
            wanted.setdefault((ref.frame_id, ref.is_extended), []).append(
                (ch.signal.name, 2 * g + c))
    sums: dict[tuple[int, int], list[float]] = {}
    for msg in can.LogReader(path):
        sigs = wanted.get((msg.arbitration_id, msg.is_extended_id))
        if sigs is None:
            continue
        values = db.decode_message(msg.arbitration_id, msg.data, decode_choices=False)
        k = int(msg.timestamp // 1.0)
        for name, col in sigs:
            acc = sums.setdefault((col, k), [0.0, 0])
            acc[0] += values[name]
            acc[1] += 1
    return time.perf_counter() - t


def bare(path: Path) -> tuple[int, float]:
    t = time.perf_counter()
    c = time.process_time()
    n = 0
    for _ in can.LogReader(path):
        n += 1
    bare.cpu = min(getattr(bare, "cpu", float("inf")), time.process_time() - c)  # type: ignore[attr-defined]
    return n, time.perf_counter() - t


def pipeline(cfg, path: Path, out: Path, parallel: bool | None = None,
             arrays: bool = False) -> tuple[float, float, float, dict]:
    """(streaming s, final-fit s, CPU s of streaming incl. the reader process, stats);
    the per-frame path unless ``arrays``."""
    os.environ["GYROSTAND_PER_FRAME"] = "0" if arrays else "1"
    marks: dict[str, float] = {}
    finish = offline.Pipeline.finish

    def timed_finish(self, *a, **k):
        marks["stream_end"] = time.perf_counter()
        marks["cpu_end"] = _cpu()
        return finish(self, *a, **k)

    offline.Pipeline.finish = timed_finish  # type: ignore[method-assign]
    try:
        cpu0 = _cpu()
        t = time.perf_counter()
        outcome = offline.run_replay(cfg, path, out=out, parallel=parallel)
        end = time.perf_counter()
    finally:
        offline.Pipeline.finish = finish  # type: ignore[method-assign]
    # the reader process has ended (and been waited for) before finish() runs
    return (marks["stream_end"] - t, end - marks["stream_end"], marks["cpu_end"] - cpu0,
            outcome.stats)


def ingest_only(cfg, path: Path, arrays: bool) -> tuple[float, list]:
    """(s, bins) of the receive path alone, as the pipeline builds it: read, decode,
    check, time and bin (gyrostand.can.replay.replay into an Ingest), nothing estimated
    or written; the array path or the per-frame one (log parsed in this process)."""
    from gyrostand.can.binning import Binner
    from gyrostand.can.ingest import Ingest
    from gyrostand.can.receive.listener import DecodingListener
    from gyrostand.can.replay import replay
    from gyrostand.can.routes import ChannelMap

    cm = ChannelMap.from_config(cfg)
    lst = DecodingListener(cfg.db, cm, capacity=cfg.sampling.buffer,
                           command=cfg.responses.command, max_gap=cfg.sampling.max_gap,
                           dt=cfg.sampling.dt)
    ing = Ingest(lst, Binner(cm.gyros, cfg.sampling.dt, cfg.sampling.epoch,
                             cfg.sampling.max_gap))
    t = time.perf_counter()
    bins = [b for batch in replay(path, ing, parallel=False, arrays=arrays) for b in batch]
    return time.perf_counter() - t, bins


def _cpu() -> float:
    """CPU s of this process and its waited-for children."""
    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def log_of(layout: str, frames: int, out: Path) -> Path:
    """The layout's BLF of ``frames`` frames, made once (cached in the temp folder)."""
    suffix = "" if layout == "ours" else f"_{layout}"
    path = Path(tempfile.gettempdir()) / f"gyrostand_bench_{frames}{suffix}.blf"
    if not path.is_file():
        t = time.perf_counter()
        n = write_log(path, simulated_frames(triad_cfg(frames, out, layout)))
        print(f"generated {n} frames into {path} in {time.perf_counter() - t:.1f} s")
    return path


def measure(layout: str, frames: int, repeat: int, out: Path) -> None:
    bare.cpu = float("inf")  # type: ignore[attr-defined]
    cfg = triad_cfg(frames, out, layout)
    path = log_of(layout, frames, out)
    logging.getLogger("gyrostand").setLevel(logging.ERROR)
    best_bare = best_stream = best_inline = best_indep = best_arr = float("inf")
    best_ing = best_ing_pf = float("inf")
    fit_s = cpu_s = cpu_arr = 0.0
    n = 0
    stats: dict = {}
    for _ in range(repeat):  # interleaved, best of R (the machine is shared)
        n, tb = bare(path)
        best_bare = min(best_bare, tb)
        ts, fit_s, cpu, stats = pipeline(cfg, path, out)
        if ts < best_stream:
            best_stream, cpu_s = ts, cpu
        best_inline = min(best_inline, pipeline(cfg, path, out, parallel=False)[0])
        best_indep = min(best_indep, independent(cfg, path))
        ta, _, cpu, stats_arr = pipeline(cfg, path, out, arrays=True)
        if ta < best_arr:
            best_arr, cpu_arr = ta, cpu
        if stats_arr["decoder"] != stats["decoder"] or stats_arr["binner"] != stats["binner"]:
            raise SystemExit("the array path's counts differ from the per-frame path's")
        ti, bins_arr = ingest_only(cfg, path, True)
        best_ing = min(best_ing, ti)
        ti, bins_pf = ingest_only(cfg, path, False)
        best_ing_pf = min(best_ing_pf, ti)
        if repr(bins_arr) != repr(bins_pf):
            raise SystemExit("the array path's bins differ from the per-frame path's")
    dec = stats["decoder"]
    print(f"layout {layout}: {cfg.dbc_path.name}; load average "
          + " ".join(f"{x:.2f}" for x in os.getloadavg()) + f" on {os.cpu_count()} CPUs")
    print(f"file: {path.name}, {n} frames, {path.stat().st_size / 1e6:.1f} MB")
    print(f"bare can.LogReader:  {n / best_bare:10,.0f} frames/s ({best_bare:.2f} s)")
    print(f"pipeline (replay):   {n / best_stream:10,.0f} frames/s ({best_stream:.2f} s); "
          f"decoded {dec['decoded']}, rejected {dec['rejected_total']}, "
          f"bins {stats['binner']['bins']}; CPU {cpu_s:.2f} s "
          f"({cpu_s / n * 1e6:.2f} us/frame, reader process included)")
    print(f"final batch fits:    {fit_s:.2f} s (3 gyros)")
    print(f"independent script:  {n / best_indep:10,.0f} frames/s ({best_indep:.2f} s): "
          "LogReader + cantools decode_message + 1-s bin sums")
    print(f"ratio pipeline/bare: {best_bare / best_stream:.2f}  (anchor >= 0.70)")
    print(f"  incl. final fits:  {best_bare / (best_stream + fit_s):.2f}")
    print(f"pipeline time / independent script time: {best_stream / best_indep:.2f}  "
          "(anchor <= 0.80)")
    print(f"log parsed inline:   {n / best_inline:10,.0f} frames/s ({best_inline:.2f} s), "
          f"ratio {best_bare / best_inline:.2f} (one core)")
    print(f"array path (default):{n / best_arr:10,.0f} frames/s ({best_arr:.2f} s); CPU "
          f"{cpu_arr:.2f} s ({cpu_arr / n * 1e6:.2f} us/frame), one process")
    print(f"ratio array path/bare: {best_bare / best_arr:.2f}  (stretch anchor >= 2.00); "
          f"vs the independent script {best_arr / best_indep:.2f} (<= 0.80); "
          f"incl. final fits {best_bare / (best_arr + fit_s):.2f}")
    print(f"by CPU time (less sensitive to a shared machine's load): bare "
          f"{bare.cpu:.2f} s, array path {cpu_arr:.2f} s: "  # type: ignore[attr-defined]
          f"{bare.cpu / cpu_arr:.2f} x bare")  # type: ignore[attr-defined]
    print(f"receive path alone (read, decode, check, bin; no estimators, no files): "
          f"arrays {best_ing:.2f} s = {best_bare / best_ing:.2f} x bare (stretch >= 2.00); "
          f"per-frame inline {best_ing_pf:.2f} s = {best_bare / best_ing_pf:.2f} x bare; "
          "bins identical")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--layout", choices=("ours", "foreign", "both"), default="both")
    ap.add_argument("--no-bytecode-cache", action="store_true",
                    help="with --whole: the children as the environment has them (no "
                         "bytecode written when PYTHONDONTWRITEBYTECODE is set)")
    ap.add_argument("--whole", type=int, default=0, metavar="PAIRS",
                    help="only the whole command against the bare loop, PAIRS pairs each")
    args = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    for h in logging.getLogger().handlers:  # run.log lowers gyrostand's level to INFO
        h.setLevel(logging.ERROR)
    out = Path(tempfile.mkdtemp(prefix="gyrostand_bench_replay_"))
    for layout in (("ours", "foreign") if args.layout == "both" else (args.layout,)):
        if args.whole:
            whole_command(layout, args.frames, log_of(layout, args.frames, out), out,
                          args.whole, bytecode_cache=not args.no_bytecode_cache)
        else:
            measure(layout, args.frames, args.repeat, out)
        print()


if __name__ == "__main__":
    main()
