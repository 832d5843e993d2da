"""systemd supervision: the daemon speaks sd_notify on NOTIFY_SOCKET (a unix datagram
socket the test binds in a tmp dir): READY once listening, STATUS with state, bins and
frames, WATCHDOG pings when WATCHDOG_USEC asks for them, STOPPING on stop; the pings come
from the worker loop, so a stalled worker stops them while the bus thread still receives."""

from __future__ import annotations

import os
import re
import signal
import socket
import tempfile
import threading
import time
from pathlib import Path

import can
import pytest
from sessionhelpers import make_cfg, write_cfg_yaml

from gyrostand.session import live
from gyrostand.session.notify import ServiceNotify
from gyrostand.session.offline import simulated_frames
from gyrostand.session.pipeline import Pipeline


class NotifySocket:
    """What systemd does: bind a datagram socket, keep (arrival time, message) pairs."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(str(path))
        self.sock.settimeout(0.1)
        self.got: list[tuple[float, dict[str, str]]] = []
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)
        self._t.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.sock.recv(4096)
            except TimeoutError:
                continue
            fields = dict(line.split("=", 1) for line in data.decode().split("\n"))
            self.got.append((time.monotonic(), fields))

    def times(self, key: str) -> list[float]:
        return [t for t, f in self.got if key in f]

    def statuses(self) -> list[str]:
        return [f["STATUS"] for _, f in self.got if "STATUS" in f]

    def wait_for(self, key: str, timeout: float = 60.0) -> float:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if (ts := self.times(key)):
                return ts[0]
            time.sleep(0.02)
        raise AssertionError(f"no {key} in {self.got}")

    def close(self) -> None:
        self._stop.set()
        self._t.join(5)
        self.sock.close()


@pytest.fixture
def notify_socket():
    d = tempfile.mkdtemp(prefix="gs-notify-")  # short: AF_UNIX paths hold 107 bytes
    ns = NotifySocket(Path(d) / "notify")
    yield ns
    ns.close()
    os.unlink(ns.path)
    os.rmdir(d)


def test_environment_and_message_format(notify_socket):
    n = ServiceNotify.from_environ({"NOTIFY_SOCKET": str(notify_socket.path),
                                    "WATCHDOG_USEC": "300000"})
    assert n.enabled and n.watchdog == pytest.approx(0.3)
    n.ready("listening")
    n.ping(100.0)
    n.ping(100.1)  # not due: half the period is 0.15 s
    n.ping(100.16)
    n.stopping("bye")
    n.close()
    notify_socket.wait_for("STOPPING")
    assert [f for _, f in notify_socket.got] == [
        {"READY": "1", "STATUS": "listening"}, {"WATCHDOG": "1"}, {"WATCHDOG": "1"},
        {"STOPPING": "1", "STATUS": "bye"}]
    # the watchdog is another process's, or not asked for; no socket: all no-ops
    other = ServiceNotify.from_environ({"NOTIFY_SOCKET": "/x", "WATCHDOG_USEC": "1000",
                                        "WATCHDOG_PID": str(os.getpid() + 1)})
    assert other.watchdog is None
    assert ServiceNotify.from_environ({"NOTIFY_SOCKET": "/x"}).watchdog is None
    off = ServiceNotify.from_environ({})
    assert not off.enabled and off.send(ready=1) is False


def test_abstract_socket_address():
    name = f"gyrostand-test-{os.getpid()}"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as srv:
        srv.bind("\0" + name)
        srv.settimeout(5)
        n = ServiceNotify(f"@{name}")
        assert n.send(status="hello")
        assert srv.recv(100) == b"STATUS=hello"
        n.close()


def test_a_missing_socket_is_logged_once_and_never_raises(tmp_path, caplog):
    n = ServiceNotify(str(tmp_path / "nobody"), watchdog=0.1)
    n.ready("x")
    n.ping(1.0)
    n.status("y")
    assert n.sent == 0 and caplog.text.count("sd_notify to") == 1


pytest.importorskip("can_remote")

from tests.hardening.procs import Daemon, RemoteServer, send_paced  # noqa: E402


def test_daemon_process_notifies_systemd(tmp_path, notify_socket, monkeypatch):
    """``gyrostand run`` in another process on python-can-remote, as systemd would start
    it (NOTIFY_SOCKET, WATCHDOG_USEC = 1 s): READY, growing STATUS lines, pings every
    half period (0.5 s; never a whole period without one), STOPPING on SIGTERM, exit 0."""
    srv = RemoteServer().start()
    monkeypatch.setenv("NOTIFY_SOCKET", str(notify_socket.path))
    monkeypatch.setenv("WATCHDOG_USEC", "1000000")
    monkeypatch.delenv("WATCHDOG_PID", raising=False)
    cfg_path = write_cfg_yaml(tmp_path / "svc.yaml", tmp_path / "runs",
                              {"interface": "remote", "channel": srv.url,
                               "preserve_timestamps": True},
                              duration=30.0, rates={"drift": 10, "temperature": 10})
    from gyrostand.config import load_config
    cfg = load_config(cfg_path)
    daemon = Daemon(cfg_path, "--out", str(tmp_path / "runs"))
    stand = None
    try:
        ready_line = daemon.wait_for("ready: ")
        t_ready = notify_socket.wait_for("READY")
        stand = can.Bus(interface="remote", channel=srv.url, preserve_timestamps=True)
        frames = list(simulated_frames(cfg))
        send_paced(stand, frames, 15.0)  # 31 s of frames in ~2 s
        time.sleep(3.0)
        daemon.proc.send_signal(signal.SIGTERM)
        rc, err = daemon.finish()
    finally:
        daemon.close()
        if stand is not None:
            stand.shutdown()
        srv.stop()
    assert rc == 0, err
    notify_socket.wait_for("STOPPING", 5)
    (ready,) = [f for _, f in notify_socket.got if "READY" in f]
    assert ready["STATUS"].startswith("listening on ") and \
        ready_line.split(": ", 1)[1] in ready["STATUS"]
    statuses = [s for s in notify_socket.statuses() if s.startswith("running: ")]
    bins = [int(re.match(r"running: (\d+) bins", s).group(1)) for s in statuses]
    assert len(statuses) >= 3 and bins == sorted(bins) and bins[-1] >= 30, statuses
    assert statuses[-1].endswith(f"frames {len(frames)} decoded, 0 rejected; 0 outages")
    pings = notify_socket.times("WATCHDOG")
    t_stop = notify_socket.times("STOPPING")[0]
    assert pings and pings[0] >= t_ready
    live_pings = [t for t in pings if t < t_stop]
    gaps = [b - a for a, b in zip([t_ready, *live_pings], live_pings, strict=False)]
    assert len(live_pings) >= (t_stop - t_ready) / 0.5 * 0.8, (len(live_pings), t_stop - t_ready)
    assert max(gaps) < 1.0, max(gaps)  # never a whole watchdog period without a ping
    assert notify_socket.got[-1][1] == {"STOPPING": "1", "STATUS": "stopping: SIGTERM"}


def test_a_stalled_worker_stops_the_pings(notify_socket, monkeypatch, tmp_path):
    """In-process on the virtual bus: the worker's pipeline step blocks (as a hung fit or
    a dead lock would) while the Notifier thread keeps receiving; no ping goes out until
    it is released, then the pings resume and the frames received meanwhile are there."""
    monkeypatch.setenv("NOTIFY_SOCKET", str(notify_socket.path))
    monkeypatch.setenv("WATCHDOG_USEC", "100000")  # a ping every 0.05 s when healthy
    cfg = make_cfg(tmp_path / "runs", duration=40.0)
    stall, release = threading.Event(), threading.Event()
    step = Pipeline.step

    def stalling_step(self, bins):
        if stall.is_set():
            release.wait(30)
            stall.clear()
        return step(self, bins)

    monkeypatch.setattr(Pipeline, "step", stalling_step)
    ready, stop = threading.Event(), threading.Event()
    outcome: list = []
    t = threading.Thread(target=lambda: outcome.append(live.run_live(
        cfg, on_ready=lambda _d: ready.set(), stop_event=stop, handle_signals=False)))
    stand = can.Bus(interface="virtual", channel=cfg.bus["channel"], preserve_timestamps=True)
    t.start()
    try:
        assert ready.wait(30)
        frames = list(simulated_frames(cfg))
        half = len(frames) // 2
        for f in frames[:half]:
            stand.send(f)
        time.sleep(0.5)
        stall.set()
        time.sleep(0.3)  # the worker enters the stall at its next step
        t_stalled = time.monotonic()
        for f in frames[half:]:
            stand.send(f)  # received by the Notifier's thread meanwhile
        time.sleep(1.5)
        t_release = time.monotonic()
        release.set()
        time.sleep(0.8)
        stop.set()
        t.join(60)
    finally:
        stand.shutdown()
    assert outcome and outcome[0].ok
    pings = notify_socket.times("WATCHDOG")
    during = [p for p in pings if t_stalled <= p < t_release]
    before = [p for p in pings if p < t_stalled]
    after = [p for p in pings if t_release <= p < t_release + 0.8]
    assert during == [], during
    assert len(before) >= 5 and len(after) >= 3, (len(before), len(after))
    resumed = [s for t_, f in notify_socket.got if t_ >= t_release and "STATUS" in f
               for s in [f["STATUS"]] if s.startswith("running")]
    assert resumed and f"frames {len(frames)} decoded" in resumed[-1], resumed
    assert "STOPPING" in notify_socket.got[-1][1]


def test_unit_file_is_valid_for_systemd(tmp_path):
    """deploy/gyrostand@.service: Type=notify with a watchdog, one instance per session
    file, not restarted after the exit statuses restarting cannot help (usage, data,
    input, config); systemd-analyze (where installed) accepts it with the venv's
    gyrostand."""
    import shutil
    import subprocess
    import sys

    unit = (Path(__file__).resolve().parents[2] / "deploy" / "gyrostand@.service").read_text()
    keys = dict(line.split("=", 1) for line in unit.splitlines()
                if "=" in line and not line.startswith(("#", " ")))
    assert keys["Type"] == "notify" and int(keys["WatchdogSec"]) > 0
    assert keys["ExecStart"].endswith("run /etc/gyrostand/%i.yaml --out /var/lib/gyrostand/%i")
    assert keys["ExecStartPre"].endswith("run /etc/gyrostand/%i.yaml --check")
    from gyrostand import exitcodes

    assert keys["RestartPreventExitStatus"].split() == [str(c) for c in exitcodes.NO_RESTART]
    if shutil.which("systemd-analyze") is None:
        pytest.skip("systemd-analyze is not installed")
    exe = Path(sys.executable).with_name("gyrostand")
    path = tmp_path / "gyrostand@demo.service"
    path.write_text(unit.replace("/opt/gyrostand/.venv/bin/gyrostand", str(exe)))
    r = subprocess.run(["systemd-analyze", "verify", str(path)], capture_output=True,
                       text=True, timeout=60)
    problems = [line for line in (r.stdout + r.stderr).splitlines()
                if "gyrostand@demo.service" in line]
    assert r.returncode == 0 and not problems, r.stdout + r.stderr
