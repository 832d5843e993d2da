"""Batch scaling: ``gyrostand batch`` (replay + diagnose of every run) on 1 and 2 Dask
workers over an archive of simulated 6-h runs.

The archive (``--runs`` runs of ``--duration`` s, the demo stand's session with 10 Hz
drift and temperature frames, jitter, drops, quantization; seeds 0..runs-1; the paper's
temperature profile stretched over the run) is generated once with the project's
simulator and cached in the temp folder. Then for each worker count a fresh batch folder
and a fresh ``LocalCluster`` (127.0.0.1, processes, one thread each); the workers import
gyrostand before the clock starts (a warm cluster, as a lab's is), and the batch's wall
time from submitting the first run to the last record is measured. Printed:

* runs/min with 1 and 2 workers, and their ratio (anchor: >= 1.7 on 2 free cores);
* the per-run cost (mean task seconds on 1 worker) and peak resident memory per worker
  (the most any worker process reached: one run streamed through the replay, its 1-s
  samples for the diagnosis);
* the extrapolation to a 16-worker cluster: per-run cost x runs / 16 (no scheduler
  overhead counted: a run's task is tens of seconds, Dask's per-task overhead ~1 ms).

    .venv/bin/python benchmarks/batch_scale.py [--runs 50] [--duration 21600]
                                               [--workers 1,2] [--do replay,diagnose]

Needs the 'fleet' extra. Run it on a quiet machine: the ratio measures cores, and a core
another process uses is not there to scale onto.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "configs" / "demo.yaml"
DBC = ROOT / "dbc" / "gyrostand.dbc"


def session_file(path: Path, seed: int, duration: float) -> Path:
    d = copy.deepcopy(yaml.safe_load(DEMO.read_text()))
    d["session"]["output"] = str(path.parent / "runs")
    d["dbc"] = str(DBC)
    d["gyros"][0]["identifiers"] = ["ml"]
    sim = d["simulate"]
    sim["seed"] = seed
    sim["duration"] = duration
    sim["rates"] = {"drift": 10, "temperature": 10}
    f = duration / 2000.0  # the demo's 2000-s profile, stretched
    sim["temperature"] = [[t * f, temp] for t, temp in sim["temperature"]]
    path.write_text(yaml.safe_dump(d))
    return path


def archive(root: Path, runs: int, duration: float) -> Path:
    """``root/manifest.csv`` over ``runs`` logs (made once; an existing log is kept)."""
    from gyrostand.can.framesim import write_log
    from gyrostand.config import load_config
    from gyrostand.session.offline import simulated_frames

    root.mkdir(parents=True, exist_ok=True)
    lines = ["run,path,config,serial,date,type"]
    for i in range(runs):
        cfg = session_file(root / f"run{i:03d}.yaml", i, duration)
        log = root / f"run{i:03d}.blf"
        if not log.is_file():
            t = time.perf_counter()
            tmp = log.with_name(f".tmp-{log.name}")  # the suffix picks the format
            n = write_log(tmp, simulated_frames(load_config(cfg)))
            os.replace(tmp, log)
            print(f"  generated {log.name}: {n} frames in {time.perf_counter() - t:.1f} s",
                  flush=True)
        lines.append(f"run{i:03d},{log.name},{cfg.name},S{i % 10:02d},"
                     f"2026-{1 + i // 10 % 12:02d}-01,FOG-A")
    manifest = root / "manifest.csv"
    manifest.write_text("\n".join(lines) + "\n")
    return manifest


def _warm() -> int:
    """Import the replay and the workbench, and load the numba kernels (a short ML fit)."""
    import gyrostand.session.offline  # noqa: F401
    import gyrostand.workbench  # noqa: F401
    from gyrostand.core.ml.fit import ml
    from gyrostand.core.model import Model
    from gyrostand.core.profiles import paper_profile
    from gyrostand.core.simulation import simulate

    m = Model.parse("markov,temp")
    ml(simulate(m, {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.001,
                    "white.sigma": 0.0}, paper_profile(), seed=1), m)
    return os.getpid()


def measure(manifest: Path, out: Path, workers: int, do: str) -> dict:
    from distributed import Client, LocalCluster

    from gyrostand.batch.inputs import collect_runs
    from gyrostand.batch.runner import run_batch
    from gyrostand.batch.tasks import TaskOptions

    shutil.rmtree(out, ignore_errors=True)
    specs = collect_runs([], manifest=manifest)
    opts = TaskOptions(do=tuple(s for s in ("replay", "identify", "diagnose")
                                if s in do.split(",")))
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      host="127.0.0.1", dashboard_address=None) as cluster, \
            Client(cluster) as client:
        client.run(_warm)
        t = time.perf_counter()
        counts = run_batch(client, specs, opts, out)
        wall = time.perf_counter() - t
    recs = [json.loads((out / "results" / f"{s.run}.json").read_text()) for s in specs]
    bad = [r["run"] for r in recs if r["status"] != "ok"]
    if bad:
        raise SystemExit(f"runs failed: {bad}: {recs[0].get('error')}")
    secs = [r["seconds"] for r in recs]
    return {"workers": workers, "runs": len(specs), "wall": wall, "done": counts.done,
            "per_run": statistics.mean(secs),
            "peak_mib": max(r.get("worker_peak_rss_mib") or 0 for r in recs)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--duration", type=float, default=21600.0)
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--do", default="replay,diagnose")
    ap.add_argument("--cache", type=Path, default=None,
                    help="archive folder (default: <tmp>/gyrostand-batch-scale-<runs>x<s>)")
    args = ap.parse_args()
    cache = args.cache or (Path(tempfile.gettempdir()) /
                           f"gyrostand-batch-scale-{args.runs}x{args.duration:g}")
    print(f"archive: {cache} ({args.runs} runs of {args.duration:g} s, 10 Hz frames)")
    manifest = archive(cache, args.runs, args.duration)
    print(f"load average before: {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")
    res = {}
    for n in [int(x) for x in args.workers.split(",")]:
        r = measure(manifest, cache / f"batch-{n}w", n, args.do)
        res[n] = r
        print(f"{n} worker(s): {r['runs']} runs in {r['wall']:.1f} s = "
              f"{60 * r['runs'] / r['wall']:.2f} runs/min; per-run cost {r['per_run']:.1f} s; "
              f"peak memory per worker {r['peak_mib']:.0f} MiB", flush=True)
    if 1 in res and 2 in res:
        ratio = res[1]["wall"] / res[2]["wall"]
        print(f"throughput ratio 2 workers / 1 worker: {ratio:.2f}x (anchor >= 1.7x on 2 "
              f"free cores)")
    one = res[min(res)]
    est = one["per_run"] * one["runs"] / 16
    print(f"extrapolation: 16 workers: per-run cost {one['per_run']:.1f} s x {one['runs']} "
          f"runs / 16 = {est:.0f} s; for a 500-run archive {one['per_run'] * 500 / 16 / 60:.1f}"
          f" min")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
