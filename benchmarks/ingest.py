"""Live ingest through the daemon on python-can's virtual bus at a saturated classic CAN
bus' frame rate: are all frames decoded, binned and recorded, with no drops?

The whole daemon runs (``session.live.run_live``: Notifier + decoding listener + BLF
recorder + worker loop with online LKF/LSQ + response frames) on a fresh virtual channel.
A sender thread replays the three-gyro stand's pre-generated frames paced in wall time at
``--rate`` frames/s (default 9,009: the most 8-byte standard-id frames a 1 Mbit/s bus
carries) for ``--seconds``; then sends a stop command. Frame timestamps are the
simulator's (``preserve_timestamps``), so the daemon's bins are those of the stand.

Printed: achieved rate, frames received/decoded/recorded, drops (sent − decoded, buffer
overflow, late samples), CPU share (process CPU time / wall time, both threads of the
daemon and the sender, over the sending window; the sender's own thread CPU is printed
separately and subtracted for the daemon's share), and a second,
unpaced run ("as fast as possible", with the stand's heartbeat flow control) for the
ceiling.

    .venv/bin/python benchmarks/ingest.py [--rate 9009] [--seconds 10]
"""

from __future__ import annotations

import argparse
import copy
import logging
import tempfile
import threading
import time
from pathlib import Path

import yaml

from gyrostand.can.bus import FrameEncoder, open_bus
from gyrostand.can.replay import paced
from gyrostand.config import parse_config
from gyrostand.session.live import run_live
from gyrostand.session.offline import simulated_frames
from gyrostand.session.stand import SimulatedStand

ROOT = Path(__file__).resolve().parents[1]
TRIAD = ROOT / "configs" / "three-gyros.yaml"
STAND_RATE = 3 * (200 + 10)  # frames per second of frame time in three-gyros.yaml


def triad_cfg(seconds_of_frames: float, out: Path, channel: str):
    d = copy.deepcopy(yaml.safe_load(TRIAD.read_text()))
    d["session"]["output"] = str(out)
    d["bus"] = {"interface": "virtual", "channel": channel, "preserve_timestamps": True}
    d["simulate"]["duration"] = float(round(seconds_of_frames))
    return parse_config(d, source=str(TRIAD), base_dir=TRIAD.parent)


class PacedSender(threading.Thread):
    """Send ``frames`` paced in wall time at ``rate`` frames/s (whatever their timestamps
    say), then a stop command; record wall time, process CPU time and this thread's CPU
    time over the sending window."""

    def __init__(self, cfg, frames, rate, ready, stop):
        super().__init__(daemon=True)
        self.cfg, self.frames, self.rate, self.ready, self.stop = cfg, frames, rate, ready, \
            stop
        self.sent, self.wall, self.cpu, self.own_cpu, self.error = 0, 0.0, 0.0, 0.0, None

    def run(self):
        try:
            self.ready.wait(30)
            bus = open_bus(self.cfg.bus)
            p0, c0, w0 = time.process_time(), time.thread_time(), time.perf_counter()
            for f in paced(self.frames, speed=self.rate / STAND_RATE):
                bus.send(f)
                self.sent += 1
            self.wall = time.perf_counter() - w0
            self.own_cpu = time.thread_time() - c0
            self.cpu = time.process_time() - p0
            enc = FrameEncoder(self.cfg.db)
            bus.send(enc.command_frame(self.cfg.responses.command, "stop", 1, 1,
                                       timestamp=self.frames[-1].timestamp + 1e-3))
            time.sleep(0.5)
            bus.shutdown()
        except BaseException as exc:
            self.error = exc
            self.stop.set()


def report(name, outcome, sent, wall, cpu, sender_cpu):
    st = outcome.stats
    dec, b, rec = st["decoder"], st["binner"], st["recorder"]
    drops = sent + 1 - dec["decoded"]
    print(f"{name}: sent {sent} frames in {wall:.2f} s = {sent / wall:,.0f} frames/s "
          f"({sent / wall / 9009:.2f} x the 1 Mbit/s bus limit of 9,009/s)")
    print(f"  received {dec['received']}, decoded {dec['decoded']}, recorded {rec['frames']}, "
          f"rejected {dec['rejected_total']} (overflow {dec['rejected']['overflow']}), "
          f"late samples {b['late']}, bins {b['bins']} (gaps {b['gaps']})")
    print(f"  drops: {drops}   CPU share: process {cpu / wall:.2f} of one core over the "
          f"sending time (sender thread alone {sender_cpu / wall:.2f}, daemon "
          f"{(cpu - sender_cpu) / wall:.2f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rate", type=float, default=9009.0)
    ap.add_argument("--seconds", type=float, default=10.0)
    args = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    for h in logging.getLogger().handlers:  # run.log lowers gyrostand's level to INFO
        h.setLevel(logging.ERROR)
    out = Path(tempfile.mkdtemp(prefix="gyrostand_bench_ingest_"))
    n_wanted = int(args.rate * args.seconds)
    cfg = triad_cfg(n_wanted / STAND_RATE, out, "gyrostand-bench-ingest")
    frames = list(simulated_frames(cfg))
    print(f"{len(frames)} frames of the three-gyro stand "
          f"({frames[-1].timestamp - frames[0].timestamp:.0f} s of frame time)")

    # 1) paced at the saturated-bus rate
    ready, stop = threading.Event(), threading.Event()
    sender = PacedSender(cfg, frames, args.rate, ready, stop)
    sender.start()
    outcome = run_live(cfg, on_ready=lambda _d: ready.set(), stop_event=stop,
                       handle_signals=False)
    sender.join(5)
    if sender.error:
        raise sender.error
    report("paced", outcome, sender.sent, sender.wall, sender.cpu, sender.own_cpu)

    # 2) unpaced ceiling (flow control through the heartbeat)
    cfg2 = triad_cfg(n_wanted / STAND_RATE, out, "gyrostand-bench-ingest-max")
    ready, stop = threading.Event(), threading.Event()
    stand = SimulatedStand(cfg2, frames, ready, stop, send_stop=True)
    stand.start()
    w0 = time.perf_counter()
    outcome2 = run_live(cfg2, on_ready=lambda _d: ready.set(), stop_event=stop,
                        handle_signals=False)
    wall2 = time.perf_counter() - w0
    stand.join(5)
    dec2 = outcome2.stats["decoder"]
    print(f"unpaced: {stand.sent} frames through the daemon in {wall2:.2f} s incl. start and "
          f"final fits = {stand.sent / wall2:,.0f} frames/s; decoded {dec2['decoded']}, "
          f"overflow {dec2['rejected']['overflow']}")


if __name__ == "__main__":
    main()
