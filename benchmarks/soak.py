"""Soak: a simulated 24-hour run at 100 Hz per signal through replay, memory and speed.

One gyro (``configs/demo.yaml``: online LKF + LSQ per bin, samples/estimates CSVs, response
frames built) fed 100-Hz drift and 100-Hz temperature frames (17.3 million frames in 24 h)
over a 24-h temperature cycle (20 -> 45 -> 45 -> 20 degC). The frames are generated
*streaming*, 256 s at a time (the 1-s truth of the whole run is 86,400 x 2 floats; the
frames of one chunk, ~51,000, are the only frames alive at any moment), and handed to
``run_replay`` through a generator: nothing holds the run's frames or bins in memory.

Printed, at 1 h, every few hours, and at the end of frame time: the process's peak
resident memory (``VmHWM``) and current RSS, which must stay flat (a pipeline that kept
every bin, estimate or frame would grow ~linearly); then the throughput, frames/s of the
whole (generation + replay) and of the replay alone (generation timed separately), and
the final batch fits' time (they re-read samples.csv, so they do scale with the run).

    .venv/bin/python benchmarks/soak.py [--hours H] [--out DIR]
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import logging
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import can
import numpy as np
import yaml

from gyrostand.can.framesim import FrameSimOptions, Truth, generate_frames
from gyrostand.can.routes import ChannelMap
from gyrostand.config import SessionConfig, parse_config
from gyrostand.session.offline import run_replay, simulated_truths

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "configs" / "demo.yaml"
RATE = 100.0
CHUNK = 256  # s of frames generated at once (x 100 Hz: a multiple of the 8-bit counter)


def status_kb() -> dict[str, int]:
    out = {}
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(("VmHWM:", "VmRSS:")):
                k, v = line.split(":")
                out[k] = int(v.split()[0])
    return out


def soak_cfg(hours: float, out: Path) -> SessionConfig:
    d = yaml.safe_load(DEMO.read_text())
    d = copy.deepcopy(d)
    d["session"]["output"] = str(out)
    s = 3600.0 * hours
    d["simulate"].update({
        "duration": s, "rates": {"drift": RATE, "temperature": RATE}, "jitter": 0.001,
        "drop": 0.001,
        "temperature": [[0, 20], [0.25 * s, 45], [0.5 * s, 45], [0.75 * s, 20], [s, 20]]})
    return parse_config(d, source="soak.yaml", base_dir=DEMO.parent)


def frames(cfg: SessionConfig, marks: list[float], report) -> Iterator[can.Message]:
    """The run's frames, chunk by chunk; ``report(hours)`` when frame time passes each
    mark (hours)."""
    truth = simulated_truths(cfg)[0]  # 1-s truth of the whole run (small)
    cmap = ChannelMap.from_config(cfg)
    base = FrameSimOptions.from_config(cfg.simulate)
    n = truth.t.size
    pending = list(marks)
    gen_s = 0.0
    for k, i0 in enumerate(range(0, n, CHUNK)):
        sl = slice(i0, min(n, i0 + CHUNK))
        part = Truth(truth.t[sl], truth.drift[sl], truth.temp[sl])
        opts = dataclasses.replace(base, seed=base.seed + k)
        w = time.perf_counter()
        chunk = list(generate_frames(cfg.db, cmap, [part], opts))
        gen_s += time.perf_counter() - w
        yield from chunk
        del chunk
        t_h = float(truth.t[sl][-1] + 1.0) / 3600.0
        while pending and t_h >= pending[0]:
            report(pending.pop(0), gen_s)
    frames.gen_s = gen_s  # type: ignore[attr-defined]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hours", type=float, default=24.0, help="frame time to run (h)")
    ap.add_argument("--out", default=None, help="run folder parent (default: a temp dir)")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    for h in logging.getLogger().handlers:  # the run's run.log lowers gyrostand's level
        h.setLevel(logging.WARNING)
    tmp = tempfile.TemporaryDirectory(prefix="hard_soak_") if args.out is None else None
    out = Path(args.out) if args.out else Path(tmp.name)  # type: ignore[union-attr]
    cfg = soak_cfg(args.hours, out)
    marks = sorted({m for m in (1.0, 2.0, 6.0, 12.0, 18.0, args.hours) if m <= args.hours})
    counted = {"frames": 0}
    t0 = time.perf_counter()
    rss: dict[float, dict[str, int]] = {}

    def report(h: float, gen_s: float) -> None:
        st = status_kb()
        rss[h] = st
        wall = time.perf_counter() - t0
        print(f"  {h:5.1f} h of frame time: peak RSS {st['VmHWM'] / 1024:7.1f} MB, RSS "
              f"{st['VmRSS'] / 1024:7.1f} MB; {counted['frames']:,} frames in {wall:6.1f} s "
              f"({counted['frames'] / wall:,.0f} frames/s incl. generation)", flush=True)

    def counting() -> Iterator[can.Message]:
        for f in frames(cfg, marks, report):
            counted["frames"] += 1
            yield f
        counted["end"] = time.perf_counter()  # type: ignore[assignment]

    print(f"soak: {args.hours:g} h at {RATE:g} Hz drift + {RATE:g} Hz temperature, "
          f"~{int(args.hours * 3600 * 2 * RATE):,} frames, through run_replay", flush=True)
    w = time.perf_counter()
    outcome = run_replay(cfg, counting(), out=out)
    total = time.perf_counter() - w
    st = status_kb()
    gen_s = getattr(frames, "gen_s", 0.0)
    fit_s = outcome.stats.get("timing", {})
    first, last = rss[marks[0]], rss[marks[-1]]
    n = counted["frames"]
    print(f"frames {n:,}; bins {outcome.finals[0].bins:,} ({outcome.finals[0].gaps} gaps)")
    print(f"peak RSS at {marks[0]:g} h: {first['VmHWM'] / 1024:.1f} MB, at {marks[-1]:g} h: "
          f"{last['VmHWM'] / 1024:.1f} MB (growth {(last['VmHWM'] - first['VmHWM']) / 1024:+.1f}"
          f" MB); after the final fits: {st['VmHWM'] / 1024:.1f} MB")
    stream_s = counted.get("end", time.perf_counter()) - w
    print(f"throughput: {n / stream_s:,.0f} frames/s overall ({stream_s:.0f} s, of which "
          f"generation {gen_s:.0f} s); replay alone ~{n / max(stream_s - gen_s, 1e-9):,.0f} "
          f"frames/s; final batch fits and files {total - stream_s:.1f} s")
    print(f"per-bin worker step: median {fit_s.get('step_ms_median', np.nan):.3f} ms, "
          f"p99 {fit_s.get('step_ms_p99', np.nan):.3f} ms")
    if tmp is not None:
        tmp.cleanup()


if __name__ == "__main__":
    main()
