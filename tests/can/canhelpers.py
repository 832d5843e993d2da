"""Helpers of the CAN-edge tests: truths, ingest, and a live virtual-bus rig (two real
python-can virtual buses and a can.Notifier). Fixtures are in conftest.py."""

from __future__ import annotations

import itertools
import time
from pathlib import Path

import can
import numpy as np

from gyrostand.can.binning import Binner
from gyrostand.can.ingest import Ingest
from gyrostand.can.receive.listener import DecodingListener
from gyrostand.can.routes import ChannelMap

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
_channels = itertools.count()


def smooth_truth(n: int = 60, k: int = 0):
    """Any smooth 1-s series: drift (deg/h) and a ramp-and-hold temperature (degC)."""
    from gyrostand.can.framesim import Truth

    t = np.arange(float(n))
    drift = 0.5 * np.sin(t / 7.0 + k) + 0.1 * k
    temp = 20.0 + np.minimum(t, n / 2) * 0.25 + k
    return Truth(t, drift, temp)


def damaged(raw: bytes, data, first: int) -> tuple[bytes, str, int]:
    """``raw`` damaged the way hypothesis's ``data`` draws it, at or after byte ``first``
    (a BLF file's header is kept): cut short, overwritten with random bytes, one bit
    flipped, or zeroed over a stretch; with the kind of damage and its offset."""
    from hypothesis import strategies as st

    out = bytearray(raw)
    kind = data.draw(st.sampled_from(["truncate", "overwrite", "flip", "zero"]))
    at = data.draw(st.integers(first, len(out) - 1))
    if kind == "truncate":
        out = out[:at]
    elif kind == "overwrite":
        n = data.draw(st.integers(1, 300))
        out[at:at + n] = data.draw(st.binary(min_size=n, max_size=n))
    elif kind == "flip":
        out[at] ^= 1 << data.draw(st.integers(0, 7))
    else:
        n = data.draw(st.integers(1, 2000))
        out[at:at + n] = bytes(min(n, len(out) - at))
    return bytes(out), kind, at


def make_ingest(cfg, capacity: int | None = None) -> Ingest:
    cm = ChannelMap.from_config(cfg)
    lst = DecodingListener(cfg.db, cm, capacity=capacity or cfg.sampling.buffer,
                           command=cfg.responses.command, max_gap=cfg.sampling.max_gap,
                           dt=cfg.sampling.dt)
    return Ingest(lst, Binner(cm.gyros, cfg.sampling.dt, cfg.sampling.epoch,
                              cfg.sampling.max_gap))


class VirtualRig:
    """A sender bus and a receiving bus with a Notifier on one fresh virtual channel."""

    def __init__(self, listeners):
        ch = f"gyrostand-test-{next(_channels)}"
        self.tx = can.Bus(interface="virtual", channel=ch, preserve_timestamps=True)
        self.rx = can.Bus(interface="virtual", channel=ch)
        self.notifier = can.Notifier(self.rx, list(listeners), timeout=0.05)

    def send_all(self, frames) -> int:
        n = 0
        for f in frames:
            self.tx.send(f)
            n += 1
        return n

    def wait(self, listener: DecodingListener, n: int, timeout: float = 20.0) -> None:
        deadline = time.monotonic() + timeout
        while listener.stats().received < n:
            if time.monotonic() > deadline:
                raise TimeoutError(f"received {listener.stats().received} of {n} frames")
            time.sleep(0.01)

    def close(self) -> None:
        self.notifier.stop()
        self.tx.shutdown()
        self.rx.shutdown()
