"""Bus outage (issue 5, item 3): the python-can-remote server under a running
``gyrostand run`` is killed and, seconds later, started again on the same port.

The daemon must log the outage, retry opening the bus with exponential backoff, come
back by itself, report the outage (``run.log``, heartbeat page 2 ``Outages``,
``result.json`` ``stats.bus``), and show the outage in ``samples.csv`` as bins with
n = 0, never invented data; the raw log replays to the same samples, byte for byte.
Without a bus for ``reconnect.max_time`` s the run ends in ``fault`` (tested in
``tests/session/test_session_remote.py``).
"""

from __future__ import annotations

import datetime as dt
import json
import re
import time
from pathlib import Path

import can
import pytest

from gyrostand import exitcodes
from gyrostand.can.bus import FrameEncoder
from gyrostand.config import load_config
from gyrostand.session.offline import run_replay, simulated_frames

from .procs import Daemon, RemoteServer, send_paced, write_config

pytest.importorskip("can_remote")

SPEED = 40.0


def _wait_heartbeat(url: str, cfg, timeout: float = 30.0) -> tuple[can.BusABC, list]:
    """Connect a client and wait for a heartbeat from the daemon (it has reconnected)."""
    deadline = time.monotonic() + timeout
    bus = can.Bus(interface="remote", channel=url, preserve_timestamps=True)
    seen = []
    while time.monotonic() < deadline:
        f = bus.recv(0.2)
        if f is not None:
            seen.append(f)
            if f.arbitration_id == cfg.responses.status.frame_id:
                return bus, seen
    bus.shutdown()
    raise AssertionError("the daemon did not come back on the restarted server")


def _outages(tmp_path: Path, downs: list[float]) -> None:
    srv = RemoteServer().start()
    cfg_path = write_config(
        tmp_path / "outage.yaml", tmp_path / "runs",
        {"interface": "remote", "channel": srv.url, "preserve_timestamps": True},
        sim={"duration": 60.0 * (len(downs) + 1), "rates": {"drift": 50, "temperature": 10}},
        reconnect={"max_time": 60, "first_delay": 0.1, "max_delay": 0.8})
    cfg = load_config(cfg_path)
    frames = list(simulated_frames(cfg))
    t_first = float(round(frames[0].timestamp))  # the profile's t = 0 (frames jitter)
    daemon = Daemon(cfg_path, "--out", str(tmp_path / "runs"))
    stand = None
    sent_windows: list[tuple[float, float]] = []
    lost_windows: list[tuple[float, float]] = []
    seen: list[can.Message] = []
    try:
        run_dir = daemon.run_dir(daemon.wait_for("ready: "))
        stand = can.Bus(interface="remote", channel=srv.url, preserve_timestamps=True)
        for i, down in enumerate(downs):
            # 40 s of frames, acknowledged, then the server disappears for `down` s
            a, b = t_first + 60 * i, t_first + 60 * i + 40
            chunk = [f for f in frames if a <= f.timestamp < b]
            send_paced(stand, chunk, SPEED)
            sent_windows.append((a, b))
            lost_windows.append((b, b + 20))  # the stand's frames of [b, b + 20) are lost
            deadline = time.monotonic() + 20
            samples = run_dir / "az" / "samples.csv"
            while time.monotonic() < deadline and f"\n{b - 2!r}," not in samples.read_text():
                time.sleep(0.05)  # until the daemon has acknowledged the chunk's bins
            stand.shutdown()
            srv.kill()
            time.sleep(down)
            srv.start()
            stand, got = _wait_heartbeat(srv.url, cfg)
            seen += got
        a = t_first + 60 * len(downs)
        rest = [f for f in frames if f.timestamp >= a]
        send_paced(stand, rest, SPEED)
        sent_windows.append((a, rest[-1].timestamp + 1))
        enc = FrameEncoder(cfg.db)
        stand.send(enc.command_frame(cfg.responses.command, "stop", 5, 1,
                                     timestamp=rest[-1].timestamp + 0.01))
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and daemon.proc.poll() is None:
            f = stand.recv(0.1)
            if f is not None:
                seen.append(f)
        rc, err = daemon.finish()
    finally:
        daemon.close()
        if stand is not None:
            stand.shutdown()
        srv.stop()
    assert rc == 0, err

    # reported: run.log, result.json, heartbeat page 2
    log = (run_dir / "run.log").read_text()
    for i in range(1, len(downs) + 1):
        assert f"bus outage {i} at frame time" in log and f"bus outage {i} ended" in log
    doc = json.loads((run_dir / "result.json").read_text())
    assert doc["stats"]["bus"]["outages"] == len(downs)
    assert doc["stats"]["bus"]["outage_s"] >= sum(downs) * 0.8
    st = cfg.db.get_message_by_name("GS_STATUS")
    pages2 = [st.decode(f.data) for f in seen if f.arbitration_id == st.frame_id
              and f.data[0] & 0x0F == 2]
    assert pages2 and pages2[-1]["Outages"] == len(downs)
    # retried with exponential backoff, bounded by max_delay
    for i in range(1, len(downs) + 1):
        stamps = [dt.datetime.strptime(m, "%Y-%m-%d %H:%M:%S,%f").timestamp() for m in
                  re.findall(rf"^(\S+ \S+) INFO .*bus outage {i}: attempt \d+ failed", log,
                             re.M)]
        assert len(stamps) >= 2, f"outage {i}: {len(stamps)} failed attempts logged"
        waits = [b - a for a, b in zip(stamps, stamps[1:], strict=False)]
        assert all(w <= 0.8 + 0.5 for w in waits), waits
        if len(waits) >= 2:
            assert waits[-1] > waits[0], waits
    # the outage is a gap: n = 0 in every bin of the lost frames, data only where sent
    rows = [r.split(",") for r in (run_dir / "az" / "samples.csv").read_text().split("\n")[1:]
            if r]
    ts = [float(r[0]) for r in rows]
    assert all(b - a == 1.0 for a, b in zip(ts, ts[1:], strict=False))
    for r in rows:
        t, n_d, n_t = float(r[0]), int(r[3]), int(r[4])
        if any(a + 1 <= t < b - 1 for a, b in lost_windows):
            assert n_d == 0 and n_t == 0 and r[1] == "nan", r
        if n_d or n_t:
            assert any(a - 1 <= t < b for a, b in sent_windows), f"invented data: {r}"
    # and the raw log replays to exactly these samples
    rep = run_replay(cfg, run_dir / "raw.blf", out=tmp_path / "replay")
    assert (rep.run_dir / "az" / "samples.csv").read_bytes() == \
        (run_dir / "az" / "samples.csv").read_bytes()


def test_remote_server_restart_is_an_outage_with_a_gap(tmp_path):
    _outages(tmp_path, [1.5])


@pytest.mark.slow
def test_three_outages_of_growing_length(tmp_path):
    _outages(tmp_path, [0.5, 3.0, 8.0])


def test_daemon_waits_for_a_bus_that_is_not_up_yet(tmp_path):
    """``reconnect.at_start``: the server comes up 1 s after the daemon said it waits
    (its ``waiting:`` line, not a sleep that races the daemon's start-up); the daemon
    retries with backoff, opens the bus, runs, and stops on a command."""
    srv = RemoteServer()  # its port is chosen, nothing listens there yet
    cfg_path = write_config(
        tmp_path / "late.yaml", tmp_path / "runs",
        {"interface": "remote", "channel": srv.url, "preserve_timestamps": True},
        sim={"duration": 20.0, "rates": {"drift": 20, "temperature": 10}},
        reconnect={"at_start": 60, "first_delay": 0.1, "max_delay": 0.4})
    cfg = load_config(cfg_path)
    daemon = Daemon(cfg_path, "--out", str(tmp_path / "runs"))
    stand = None
    try:
        waiting = daemon.wait_for("waiting: ", timeout=60)
        assert "for the bus, up to 60 s (reconnect.at_start)" in waiting
        t0 = time.monotonic()
        time.sleep(1.0)  # the daemon is known to be waiting: this is no race
        assert daemon.proc.poll() is None  # still waiting, not failed
        srv.start()
        run_dir = daemon.run_dir(daemon.wait_for("ready: ", timeout=30))
        assert time.monotonic() - t0 >= 1.0
        stand = can.Bus(interface="remote", channel=srv.url, preserve_timestamps=True)
        frames = list(simulated_frames(cfg))
        send_paced(stand, frames, SPEED)
        stand.send(FrameEncoder(cfg.db).command_frame(
            cfg.responses.command, "stop", 1, 1, timestamp=frames[-1].timestamp + 0.01))
        rc, err = daemon.finish()
    finally:
        daemon.close()
        if stand is not None:
            stand.shutdown()
        srv.stop()
    assert rc == 0, err
    assert "waiting for the bus, up to 60 s (reconnect.at_start)" in err
    opened = re.search(r"bus opened after ([\d.]+) s \((\d+) attempts\)", err)
    # 1 s at delays 0.1, 0.2, 0.4, 0.4, ...: at least 4 attempts before the server is up
    assert opened and float(opened.group(1)) >= 1.0 and int(opened.group(2)) >= 4, err
    doc = json.loads((run_dir / "result.json").read_text())
    assert doc["gyros"]["az"]["bins"] >= 19


def test_start_without_a_bus_gives_up_after_at_start_and_at_once_when_hopeless(tmp_path):
    srv = RemoteServer()  # never started
    cfg_path = write_config(
        tmp_path / "none.yaml", tmp_path / "runs",
        {"interface": "remote", "channel": srv.url},
        reconnect={"at_start": 1.5, "first_delay": 0.1, "max_delay": 0.4})
    t0 = time.monotonic()
    rc, err = Daemon(cfg_path, "--out", str(tmp_path / "runs")).finish(60)
    assert rc == exitcodes.UNAVAILABLE and time.monotonic() - t0 >= 1.5
    assert "cannot open CAN bus (interface='remote'" in err
    assert re.search(r"giving up after 1\.\d s and \d+ attempts, reconnect\.at_start 1\.5 s",
                     err), err
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())
    # an interface python-can does not have never opens: no waiting
    cfg_path = write_config(
        tmp_path / "bad.yaml", tmp_path / "runs", {"interface": "no_such_if", "channel": "x"},
        reconnect={"at_start": 60})
    t0 = time.monotonic()
    rc, err = Daemon(cfg_path, "--out", str(tmp_path / "runs")).finish(60)
    assert rc == exitcodes.CONFIG and time.monotonic() - t0 < 20
    assert "Unknown interface type" in err and "waiting" not in err
