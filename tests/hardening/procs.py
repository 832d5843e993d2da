"""Real processes for the hardening tests: a python-can-remote server (``virtual`` bus
bridged on 127.0.0.1), ``gyrostand run`` as a subprocess, and a paced stand sending over
its own ``remote`` client. Built on the helpers of ``tests/session/test_session_remote.py``
(same server command line, same stdout-queue daemon), extended with restarts, kill -9,
extra arguments and peak-memory readings."""

from __future__ import annotations

import copy
import os
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import can
import yaml

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "configs" / "demo.yaml"
DBC = ROOT / "dbc" / "gyrostand.dbc"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_port(port: int, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise TimeoutError(f"nothing listens on 127.0.0.1:{port}")


class RemoteServer:
    """``python -m can_remote`` on 127.0.0.1:port over a fresh ``virtual`` channel; can be
    killed and started again on the same port (a new, empty virtual bus)."""

    def __init__(self, port: int | None = None) -> None:
        self.port = port or free_port()
        self.url = f"ws://127.0.0.1:{self.port}/"
        self.proc: subprocess.Popen | None = None
        self.starts = 0

    def start(self) -> RemoteServer:
        self.starts += 1
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "can_remote", "--interface", "virtual", "--channel",
             f"hard-{self.port}-{self.starts}", "--host", "127.0.0.1", "--port",
             str(self.port)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wait_port(self.port)
        return self

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)
        self.proc = None

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
        self.proc = None


def write_config(path: Path, out: Path, bus: dict, *, sim: dict | None = None,
                 **top: Any) -> Path:
    """configs/demo.yaml with ``bus``, output ``out``, ``simulate`` updated by ``sim`` and
    top-level sections merged from ``top`` (e.g. ``reconnect={...}``)."""
    d = yaml.safe_load(DEMO.read_text())
    d["session"]["output"] = str(out)
    d["bus"] = bus
    d["dbc"] = str(DBC.resolve())
    d["simulate"].update(sim or {})
    for k, v in top.items():
        if isinstance(v, dict) and isinstance(d.get(k), dict):
            d[k] = {**copy.deepcopy(d[k]), **v}
        else:
            d[k] = v
    path.write_text(yaml.safe_dump(d))
    return path


class Daemon:
    """``gyrostand run CONFIG ARGS...`` in a subprocess; stdout lines in a queue."""

    def __init__(self, cfg_path: Path, *args: str,
                 preexec_fn: Callable[[], None] | None = None) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "gyrostand", "run", str(cfg_path), *args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
            preexec_fn=preexec_fn)
        self.lines: queue.Queue[str] = queue.Queue()
        self.out: list[str] = []
        self.err = ""
        # stderr drained as it comes: an undrained pipe (64 KiB) would block the daemon
        self._err: list[str] = []
        self._err_reader = threading.Thread(target=self._read_err, daemon=True)
        self._err_reader.start()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def _read_err(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self._err.append(line)

    def stderr_text(self, wait: float = 2.0) -> str:
        """What the daemon wrote to stderr (all of it once the process has ended)."""
        if self.proc.poll() is not None:
            self._err_reader.join(wait)
        return "".join(self._err)

    def wait_for(self, prefix: str, timeout: float = 60.0) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=0.2)
            except queue.Empty:
                if self.proc.poll() is not None and self.lines.empty():
                    break
                continue
            self.out.append(line)
            if line.startswith(prefix):
                return line
        raise AssertionError(f"no {prefix!r} line; stdout {self.out}, "
                             f"stderr {self.stderr_text()}")

    def run_dir(self, ready: str) -> Path:
        return Path(ready.split(": ", 1)[1])

    def peak_rss_kb(self) -> int:
        """VmHWM of the daemon process (kB): its peak resident memory so far."""
        with open(f"/proc/{self.proc.pid}/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
        raise AssertionError("no VmHWM")

    def rss_kb(self) -> int:
        with open(f"/proc/{self.proc.pid}/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
        raise AssertionError("no VmRSS")

    def kill9(self) -> None:
        os.kill(self.proc.pid, signal.SIGKILL)
        self.proc.wait(10)

    def finish(self, timeout: float = 90.0) -> tuple[int, str]:
        try:
            rc = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            # the daemon hangs: its threads' stacks (faulthandler on SIGUSR1), then kill
            os.kill(self.proc.pid, signal.SIGUSR1)
            time.sleep(1.0)
            self.proc.kill()
            self.proc.wait(10)
            raise AssertionError(f"the daemon did not exit within {timeout} s; stdout "
                                 f"{self.out[-20:]}; stderr (with every thread's stack):\n"
                                 f"{self.stderr_text()[-12000:]}") from None
        time.sleep(0.05)
        while not self.lines.empty():
            self.out.append(self.lines.get())
        self.err = self.stderr_text()
        return rc, self.err

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)


class Observer:
    """A ``remote`` client that keeps every frame it receives (a thread reads)."""

    def __init__(self, url: str, ids: Sequence[int] | None = None) -> None:
        filters = None if ids is None else [{"can_id": i, "can_mask": 0x7FF,
                                             "extended": False} for i in ids]
        self.bus = can.Bus(interface="remote", channel=url, preserve_timestamps=True,
                           can_filters=filters)
        self.frames: list[can.Message] = []
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)
        self._t.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                f = self.bus.recv(0.1)
            except Exception:  # the server went away
                return
            if f is not None:
                self.frames.append(f)

    def close(self) -> None:
        self._stop.set()
        self._t.join(5)
        try:
            self.bus.shutdown()
        except Exception:
            pass


def send_paced(bus: can.BusABC, frames: Sequence[can.Message], speed: float,
               stop: threading.Event | None = None) -> int:
    """Send frames no faster than ``speed`` x their timestamps; return how many went out
    (stops early on ``stop`` or when the bus fails)."""
    if not frames:
        return 0
    t0, w0 = frames[0].timestamp, time.monotonic()
    n = 0
    for f in frames:
        if stop is not None and stop.is_set():
            break
        delay = w0 + (f.timestamp - t0) / speed - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        try:
            bus.send(f)
        except Exception:
            break
        n += 1
    return n


def frame_key(f: can.Message) -> tuple:
    return (round(f.timestamp, 6), f.arbitration_id, bytes(f.data))


def simulated_session(tmp: Path, duration: float = 300.0, drift_hz: float = 20,
                      temp_hz: float = 10) -> tuple[Path, list[can.Message]]:
    """A session file on the virtual bus in ``tmp`` and its simulated frames."""
    from gyrostand.config import load_config
    from gyrostand.session.offline import simulated_frames

    cfg_path = write_config(tmp / "s.yaml", tmp / "runs", {"interface": "virtual"},
                            sim={"duration": duration,
                                 "rates": {"drift": drift_hz, "temperature": temp_hz}})
    return cfg_path, list(simulated_frames(load_config(cfg_path)))
