"""``gyrostand demo``: the stand simulator and the daemon in one process on python-can's
``virtual`` bus (``configs/demo.yaml``): the paper's 2000-s scenario sent as fast as the
machine allows (frame timestamps still advance as on a real stand), then a stop command;
prints the final table and the paths of result.json and the report."""

from __future__ import annotations

import argparse
import sys
import threading
import time
from pathlib import Path
from typing import Any

from ..can.bus import FrameEncoder, open_bus
from ..can.framesim import send_frames
from ..config import SessionConfig, load_config
from ..errors import ConfigError
from ..session.live import run_live
from ..session.offline import simulated_frames, truth_params
from .common import print_outcome

#: where the demo config lives: the repository next to the package, else the cwd
CANDIDATES = (Path(__file__).resolve().parents[2] / "configs" / "demo.yaml",
              Path("configs") / "demo.yaml")


def find_demo_config() -> Path:
    for p in CANDIDATES:
        if p.is_file():
            return p
    raise ConfigError("cannot find configs/demo.yaml (looked in "
                      f"{', '.join(str(p) for p in CANDIDATES)}); pass --config")


def add_parser(sub: Any) -> None:
    p = sub.add_parser("demo", help="simulator + daemon on a virtual bus (the paper's scenario)",
                       description=__doc__)
    p.add_argument("--config", default=None, help="session file (default configs/demo.yaml)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="parent folder of the run folder (default: session.output)")
    p.set_defaults(func=run)


class _Stand(threading.Thread):
    """The simulated stand: waits for the daemon, sends every frame, then a stop command,
    and reads the acknowledgement.

    Flow control: sending as fast as possible could outrun the daemon's bounded receive
    buffer on a loaded machine (a real bus cannot outrun it: 1 Mbit/s is ~9,000 frames/s).
    The stand reads the daemon's heartbeat (frames decoded + rejected) from the bus and
    keeps at most ``window`` frames ahead of it.
    """

    window = 20_000

    def __init__(self, cfg: SessionConfig, ready: threading.Event,
                 stop: threading.Event) -> None:
        super().__init__(name="simulated-stand", daemon=True)
        self.cfg, self.ready, self.stop = cfg, ready, stop
        self.sent = 0
        self.handled = 0
        self._status = cfg.db.get_message_by_name(cfg.responses.status.name) \
            if cfg.responses.status is not None else None
        self.ack: dict[str, float] | None = None
        self.error: BaseException | None = None

    def run(self) -> None:
        cfg = self.cfg
        try:
            if not self.ready.wait(60):
                raise TimeoutError("the daemon did not become ready")
            bus = open_bus({**cfg.bus, "preserve_timestamps": True})
            try:
                last = [0.0]

                def frames():
                    for n, f in enumerate(simulated_frames(cfg)):
                        last[0] = f.timestamp
                        if n % 1000 == 0:
                            self._throttle(bus, n)
                        yield f
                self.sent = send_frames(bus, frames())
                if cfg.responses.command is None:
                    self.stop.set()
                    return
                enc = FrameEncoder(cfg.db)
                bus.send(enc.command_frame(cfg.responses.command, "stop", 1,
                                           cfg.responses.node, timestamp=last[0] + 1e-3))
                self.ack = self._await_ack(bus)
            finally:
                bus.shutdown()
        except BaseException as exc:  # reported by the main thread
            self.error = exc
            self.stop.set()

    def _throttle(self, bus, sent: int) -> None:
        ref = self.cfg.responses.status
        if ref is None:
            return
        deadline = time.monotonic() + 30
        while True:
            f = bus.recv(0)
            while f is not None:
                if f.arbitration_id == ref.frame_id and f.data[0] & 0x0F == 1:
                    d = self._status.decode(f.data, decode_choices=False)
                    self.handled = int(d["FramesDecoded"]) + int(d["FramesRejected"])
                f = bus.recv(0)
            if sent - self.handled <= self.window or time.monotonic() > deadline:
                return
            time.sleep(0.005)

    def _await_ack(self, bus) -> dict[str, float] | None:
        ref = self.cfg.responses.ack
        if ref is None:
            return None
        msg = self.cfg.db.get_message_by_name(ref.name)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            f = bus.recv(0.5)
            if f is not None and f.arbitration_id == ref.frame_id:
                return dict(msg.decode(f.data, decode_choices=False))
        return None


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config or find_demo_config())
    sim = cfg.simulate
    if sim is None:
        raise ConfigError(f"{cfg.path}: simulate: missing (the demo needs the simulator)")
    truths = truth_params(cfg)
    print(f"demo: session {cfg.name!r}, {len(cfg.gyros)} gyro(s) on "
          f"{cfg.bus.get('interface')}:{cfg.bus.get('channel')}; profile "
          f"{' -> '.join(f'{T:g}' for _, T in sim.temperature)} degC over "
          f"{sim.duration or sim.temperature[-1][0]:g} s; truth "
          + "; ".join(f"{g}: " + ", ".join(f"{k}={v:g}" for k, v in p.items())
                      for g, p in truths.items()), flush=True)
    ready, stop = threading.Event(), threading.Event()
    stand = _Stand(cfg, ready, stop)
    stand.start()
    t0 = time.monotonic()
    outcome = run_live(cfg, out=args.out, on_ready=lambda _d: ready.set(), stop_event=stop,
                       truths=truths)
    wall = time.monotonic() - t0
    stand.join(5)
    if stand.error is not None:
        raise stand.error
    ack = stand.ack
    print(f"simulated stand sent {stand.sent} frames; daemon ran {wall:.1f} s wall for "
          f"{sim.duration or sim.temperature[-1][0]:g} s of frame time; stop "
          + ("acknowledged" if ack and ack.get("Result") == 0 else "not acknowledged"))
    print_outcome(outcome, sys.stdout, truths)
    return 0 if outcome.ok else 1
