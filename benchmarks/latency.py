"""Frame-to-result-frame latency at bin close, measured on the bus.

The daemon runs live on a virtual channel with ``responses.period = dt = 1 s``, so every
bin close triggers a result round. A sender replays stand frames paced in real time; all
buses stamp frames with the wall clock when they are sent (no ``preserve_timestamps``), so
an observer bus on the channel sees, on one clock, the frame that closes a bin (the first
data frame at or after a whole second) and the first ``GS_RESULT`` frame after it:

    latency = t(first result frame after the closing frame) − t(closing frame)

It includes the Notifier's receive, decode, the worker's poll interval (2 ms), binning,
the online LKF and LSQ updates, the estimates CSV row, and encoding + sending the round.
Two loads: the demo stand (1 gyro, 110 frames/s) and the three-gyro stand paced at a
saturated 1 Mbit/s bus (9,009 frames/s), each with ``session.fsync`` on (the default: the
once-a-second acknowledgement fdatasyncs the run files) and off. Printed: median, p99 and
max (ms) per load and setting.

    .venv/bin/python benchmarks/latency.py [--seconds 30] [--repeat 1]
"""

from __future__ import annotations

import argparse
import bisect
import copy
import logging
import statistics
import tempfile
import threading
import time
from pathlib import Path

import can
import yaml

from gyrostand.can.bus import FrameEncoder, open_bus
from gyrostand.can.replay import paced
from gyrostand.config import parse_config
from gyrostand.session.live import run_live
from gyrostand.session.offline import simulated_frames

ROOT = Path(__file__).resolve().parents[1]


def config(name: str, out: Path, channel: str, seconds: float, fsync: bool = True):
    path = ROOT / "configs" / name
    d = copy.deepcopy(yaml.safe_load(path.read_text()))
    d["session"]["output"] = str(out)
    d["session"]["fsync"] = fsync
    d["bus"] = {"interface": "virtual", "channel": channel}  # stamped at send: wall clock
    d["responses"]["period"] = 1.0
    d["simulate"]["duration"] = float(seconds)
    return parse_config(d, source=str(path), base_dir=path.parent)


def measure(cfg, frames, rate: float | None) -> tuple[list[float], int]:
    """Latencies (ms) of every bin close, and the frames sent."""
    observer = can.Bus(interface="virtual", channel=cfg.bus["channel"])
    ready, stop = threading.Event(), threading.Event()
    sent = [0]
    span = frames[-1].timestamp - frames[0].timestamp

    def send():
        ready.wait(30)
        bus = open_bus(cfg.bus)
        speed = 1.0 if rate is None else rate / (len(frames) / span)  # x frame time
        for f in paced(frames, speed=speed):
            bus.send(f)
            sent[0] += 1
        enc = FrameEncoder(cfg.db)
        time.sleep(0.2)
        bus.send(enc.command_frame(cfg.responses.command, "stop", 1, 1))
        bus.shutdown()

    th = threading.Thread(target=send, daemon=True)
    th.start()
    run_live(cfg, on_ready=lambda _d: ready.set(), stop_event=stop, handle_signals=False)
    th.join(5)
    seen = []
    while (f := observer.recv(0)) is not None:
        seen.append(f)
    observer.shutdown()
    data_ids = {g.drift.signal.message.frame_id for g in cfg.gyros} | \
        {g.temperature.signal.message.frame_id for g in cfg.gyros}
    result_ids = {g.result.values.frame_id for g in cfg.gyros if g.result}
    data_t = [f.timestamp for f in seen if f.arbitration_id in data_ids]
    res_t = sorted(f.timestamp for f in seen if f.arbitration_id in result_ids)
    lat = []
    first = int(data_t[0]) + 1
    for b in range(first + 1, int(data_t[-1]) + 1):  # skip the first bin (start-up)
        i = bisect.bisect_left(data_t, b)
        if i >= len(data_t):
            break
        tc = data_t[i]
        j = bisect.bisect_left(res_t, tc)
        if j < len(res_t) and res_t[j] - tc < 1.0:
            lat.append((res_t[j] - tc) * 1e3)
    return lat, sent[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--repeat", type=int, default=1,
                    help="runs per load and session.fsync setting, interleaved")
    args = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    for h in logging.getLogger().handlers:
        h.setLevel(logging.ERROR)
    out = Path(tempfile.mkdtemp(prefix="gyrostand_bench_latency_"))
    runs = (("demo stand, 110 frames/s", "demo.yaml", None, args.seconds),
            ("three gyros at 9,009 frames/s", "three-gyros.yaml", 9009.0,
             args.seconds * 9009.0 / 630.0))
    for label, name, rate, sim_seconds in runs:
        for rep in range(args.repeat):
            for fsync in (True, False):
                cfg = config(name, out, f"gyrostand-bench-latency-{name}-{rep}-{fsync}",
                             sim_seconds, fsync)
                frames = list(simulated_frames(cfg))
                lat, sent = measure(cfg, frames, rate)
                lat.sort()
                p99 = lat[min(len(lat) - 1, int(0.99 * len(lat)))]
                print(f"{label}, session.fsync {str(fsync).lower()}: {len(lat)} bin closes, "
                      f"{sent} frames; frame-to-result latency median "
                      f"{statistics.median(lat):.2f} ms, p99 {p99:.2f} ms, max {lat[-1]:.2f} ms")

if __name__ == "__main__":
    main()
