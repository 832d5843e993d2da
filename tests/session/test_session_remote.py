"""``gyrostand run`` as a separate OS process, talking over python-can-remote's ``remote``
interface (a websocket server on 127.0.0.1 bridging a ``virtual`` bus): frames in, a stop
command acked (or SIGTERM), the final files written, exit code 0; the recorded BLF replays
to the same 1-s samples."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import can
import pytest
import yaml
from sessionhelpers import decode, write_cfg_yaml

from gyrostand.can.bus import FrameEncoder
from gyrostand.config import load_config
from gyrostand.session.offline import run_replay, simulated_frames

pytest.importorskip("can_remote")

from gyrostand import exitcodes
from tests.hardening.procs import Daemon  # noqa: E402
from tests.hardening.procs import free_port as _free_port  # noqa: E402
from tests.hardening.procs import wait_port as _wait_port  # noqa: E402


@pytest.fixture(scope="module")
def server():
    port = _free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "can_remote", "--interface", "virtual", "--channel",
         f"gyrostand-remote-{port}", "--host", "127.0.0.1", "--port", str(port)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        _wait_port(port)
        yield f"ws://127.0.0.1:{port}/"
    finally:
        proc.terminate()
        proc.wait(10)


def _start(tmp_path, server, duration):
    bus = {"interface": "remote", "channel": server, "preserve_timestamps": True}
    cfg_path = write_cfg_yaml(tmp_path / "remote.yaml", tmp_path / "runs", bus,
                              duration=duration, rates={"drift": 10, "temperature": 10})
    cfg = load_config(cfg_path)
    daemon = Daemon(cfg_path, "--out", str(tmp_path / "runs"))
    ready = daemon.wait_for("ready: ")
    client = can.Bus(interface="remote", channel=server, preserve_timestamps=True)
    return cfg, daemon, ready, client


def test_run_process_stops_on_a_command_and_replays_identically(tmp_path, server):
    cfg, daemon, ready, client = _start(tmp_path, server, 120.0)
    try:
        frames = list(simulated_frames(cfg))
        for f in frames:
            client.send(f)
        enc = FrameEncoder(cfg.db)
        client.send(enc.command_frame(cfg.responses.command, "stop", 77, 1,
                                      timestamp=frames[-1].timestamp + 0.01))
        got, deadline = [], time.monotonic() + 30
        while time.monotonic() < deadline:
            f = client.recv(0.2)
            if f is not None:
                got.append(f)
                if f.arbitration_id == cfg.responses.ack.frame_id:
                    break
        rc, err = daemon.finish()
    finally:
        client.shutdown()
    assert decode(cfg, got, "GS_ACK")[-1] == {"Command": 2, "Sequence": 77, "Result": 0,
                                             "Reason": 0, "Node": 1}
    assert rc == 0, err
    run_dir = ready.split(": ", 1)[1]
    assert any(line == f"result:     {run_dir}/result.json" for line in daemon.out)
    doc = json.loads((tmp_path / "runs" / run_dir.rsplit("/", 1)[1] / "result.json")
                     .read_text())
    assert doc["stats"]["stop_reason"] == "stop command"
    assert doc["stats"]["decoder"]["received"] == len(frames) + 1
    assert doc["stats"]["decoder"]["rejected_total"] == 0
    assert doc["gyros"]["az"]["bins"] == 121
    assert set(doc["gyros"]["az"]["fits"]) == {"lkf", "lkf_batch", "lsq", "ml"}
    assert "markov.beta" in doc["gyros"]["az"]["fits"]["ml"]["parameters"]
    # the raw log of the process replays to the same 1-s samples, byte for byte
    live = Path(run_dir)
    rep = run_replay(cfg, live / "raw.blf", out=tmp_path / "replay")
    assert (rep.run_dir / "az" / "samples.csv").read_bytes() == \
        (live / "az" / "samples.csv").read_bytes()


def test_run_process_stops_cleanly_on_sigterm(tmp_path, server):
    cfg, daemon, ready, client = _start(tmp_path, server, 60.0)
    try:
        frames = list(simulated_frames(cfg))
        for f in frames:
            client.send(f)
        # wait until the daemon has binned (a heartbeat says so), then SIGTERM
        deadline = time.monotonic() + 30
        seen: list[can.Message] = []
        while time.monotonic() < deadline:
            f = client.recv(0.2)
            if f is not None:
                seen.append(f)
            p1 = [p for p in decode(cfg, seen[-3:], "GS_STATUS") if p["Page"] == 1]
            if p1 and p1[-1]["FramesDecoded"] == len(frames):
                break
        daemon.proc.send_signal(signal.SIGTERM)
        rc, err = daemon.finish()
    finally:
        client.shutdown()
    assert rc == 0, err
    assert any(line.startswith("stopped: SIGTERM") for line in daemon.out), daemon.out
    run = Path(ready.split(": ", 1)[1])
    doc = json.loads((run / "result.json").read_text())
    assert doc["stats"]["decoder"]["received"] == len(frames)
    assert doc["gyros"]["az"]["bins"] == 61
    assert (run / "report.txt").is_file() and (run / "raw.blf").stat().st_size > 0


def test_run_process_ends_with_fault_when_the_bus_dies(tmp_path):
    port = _free_port()
    srv = subprocess.Popen(
        [sys.executable, "-m", "can_remote", "--interface", "virtual", "--channel",
         f"gyrostand-remote-dies-{port}", "--host", "127.0.0.1", "--port", str(port)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        _wait_port(port)
        bus = {"interface": "remote", "channel": f"ws://127.0.0.1:{port}/"}
        cfg_path = write_cfg_yaml(tmp_path / "dies.yaml", tmp_path / "runs", bus)
        d = yaml.safe_load(cfg_path.read_text())
        d["reconnect"] = {"max_time": 1.0, "first_delay": 0.1}  # retry 1 s, then fault
        cfg_path.write_text(yaml.safe_dump(d))
        daemon = Daemon(cfg_path, "--out", str(tmp_path / "runs"))
        ready = daemon.wait_for("ready: ")
    finally:
        srv.kill()  # the server goes away under the daemon
        srv.wait(10)
    rc, err = daemon.finish()
    assert rc == exitcodes.UNAVAILABLE, err
    assert any(line.startswith("stopped: bus failure") and "state fault" in line
               for line in daemon.out), daemon.out
    doc = json.loads((Path(ready.split(": ", 1)[1]) / "result.json").read_text())
    assert doc["stats"]["stop_reason"].startswith("bus failure")
    assert "no bus after" in doc["stats"]["stop_reason"]
    assert doc["stats"]["bus"]["outages"] == 1
    assert all("error" in f for f in doc["gyros"]["az"]["fits"].values())  # no bins
