"""A simulated test stand on a bus: sends frames to a daemon, commands it, reads its answers.

Used by ``gyrostand demo``, the tests and the benchmarks. It runs on its own thread, waits
for the daemon's ready signal (frames sent before a receiver listens are lost), sends every
frame as fast as the bus takes them, then (optionally) a ``stop`` command, and waits for the
acknowledgement. Every frame it receives from the bus (the daemon's results, summaries,
heartbeats, acks) is kept in :attr:`SimulatedStand.received`.

Flow control: sending as fast as possible could outrun the daemon's bounded receive buffer
on a loaded machine (a real bus cannot: 1 Mbit/s carries ~9,000 frames/s). The stand reads
the daemon's heartbeat (frames decoded + rejected, ``GS_STATUS`` page 1) and stays at most
``window`` frames ahead of it.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterable, Mapping
from typing import Any

import can

from ..can.bus import FrameEncoder, open_bus
from ..config import SessionConfig

__all__ = ["SimulatedStand"]

log = logging.getLogger(__name__)


class SimulatedStand(threading.Thread):
    """Send ``frames`` on a bus opened with ``bus`` (default: the session's bus with
    ``preserve_timestamps``) once ``ready`` is set; then a stop command when ``send_stop``.
    On any error it sets ``stop`` (so the daemon ends) and keeps the error in :attr:`error`.
    """

    def __init__(self, cfg: SessionConfig, frames: Iterable[can.Message],
                 ready: threading.Event, stop: threading.Event, *,
                 bus: Mapping[str, Any] | None = None, send_stop: bool = True,
                 window: int = 20_000, ack_timeout: float = 60.0) -> None:
        super().__init__(name="simulated-stand", daemon=True)
        self.cfg, self.frames, self.ready, self.stop = cfg, frames, ready, stop
        self.bus_cfg = dict(bus) if bus is not None else {**cfg.bus,
                                                           "preserve_timestamps": True}
        self.send_stop, self.window, self.ack_timeout = send_stop, window, ack_timeout
        self.sent = 0
        self.handled = 0
        self.last_t = 0.0
        self.received: list[can.Message] = []
        self.ack: dict[str, float] | None = None
        self.error: BaseException | None = None
        st = cfg.responses.status
        self._status = cfg.db.get_message_by_name(st.name) if st is not None else None

    def run(self) -> None:
        try:
            if not self.ready.wait(60):
                raise TimeoutError("the daemon did not become ready within 60 s")
            bus = open_bus(self.bus_cfg)
            try:
                self._send_all(bus)
                if self.send_stop:
                    self.command(bus, "stop", 1)
            finally:
                bus.shutdown()
        except BaseException as exc:  # reported by whoever joins the thread
            log.error("simulated stand failed: %s", exc)
            self.error = exc
            self.stop.set()

    def _send_all(self, bus: can.BusABC) -> None:
        for f in self.frames:
            if self.sent % 1000 == 0:
                self._throttle(bus)
            bus.send(f, timeout=5.0)
            self.sent += 1
            self.last_t = f.timestamp

    def command(self, bus: can.BusABC, name: str, sequence: int) -> dict[str, float] | None:
        """Send a command (timestamped just after the last frame) and wait for its ack."""
        ref = self.cfg.responses.command
        if ref is None:
            self.stop.set()
            return None
        enc = FrameEncoder(self.cfg.db)
        bus.send(enc.command_frame(ref, name, sequence, self.cfg.responses.node,
                                   timestamp=self.last_t + 1e-3))
        self.ack = self._await_ack(bus, sequence)
        return self.ack

    def _take(self, f: can.Message) -> None:
        self.received.append(f)
        st = self.cfg.responses.status
        if st is not None and self._status is not None and f.arbitration_id == st.frame_id \
                and f.data[0] & 0x0F == 1:
            d = self._status.decode(f.data, decode_choices=False)
            self.handled = int(d["FramesDecoded"]) + int(d["FramesRejected"])

    def _throttle(self, bus: can.BusABC) -> None:
        deadline = time.monotonic() + 30
        while True:
            f = bus.recv(0)
            while f is not None:
                self._take(f)
                f = bus.recv(0)
            if self._status is None or self.sent - self.handled <= self.window \
                    or time.monotonic() > deadline:
                return
            time.sleep(0.005)

    def _await_ack(self, bus: can.BusABC, sequence: int) -> dict[str, float] | None:
        ref = self.cfg.responses.ack
        if ref is None:
            return None
        msg = self.cfg.db.get_message_by_name(ref.name)
        deadline = time.monotonic() + self.ack_timeout
        while time.monotonic() < deadline:
            f = bus.recv(0.2)
            if f is None:
                continue
            self._take(f)
            if f.arbitration_id == ref.frame_id:
                d = dict(msg.decode(f.data, decode_choices=False))
                if int(d["Sequence"]) == sequence:
                    return d
        return None

    def collect(self, bus: can.BusABC, seconds: float) -> None:
        """Keep reading the bus for ``seconds`` (e.g. the final result round)."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            f = bus.recv(0.05)
            if f is not None:
                self._take(f)
