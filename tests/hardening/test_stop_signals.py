"""Signals (issue 28, finding 3): SIGHUP, and Ctrl-C pressed again while the daemon
finishes, end ``gyrostand run`` as SIGTERM does: final fits, ``result.json`` and
``report.txt`` written, exit status 0. Before: SIGHUP killed the process at once (exit -1,
``result.json`` still ``"state": "running"``, no report); a SIGINT landing after the stop
handler was given back (the bus closing, the interpreter's shutdown) gave exit -2.

A real daemon process over python-can-remote (:mod:`tests.hardening.procs`)."""

from __future__ import annotations

import json
import signal
import time

import can
import pytest

from gyrostand.config import load_config
from gyrostand.session.offline import simulated_frames

from .procs import Daemon, RemoteServer, write_config

pytest.importorskip("can_remote")


def _daemon_with_frames(tmp_path, srv):
    """A daemon on ``srv`` that has decoded 121 s of the demo's frames (10 Hz): its
    heartbeat says so. Returns (daemon, run folder, frames sent)."""
    cfg_path = write_config(tmp_path / "sig.yaml", tmp_path / "runs",
                            {"interface": "remote", "channel": srv.url,
                             "preserve_timestamps": True},
                            sim={"duration": 120.0, "rates": {"drift": 10,
                                                              "temperature": 10}})
    cfg = load_config(cfg_path)
    status = cfg.db.get_message_by_name("GS_STATUS")
    daemon = Daemon(cfg_path, "--out", str(tmp_path / "runs"))
    run = daemon.run_dir(daemon.wait_for("ready: "))
    client = can.Bus(interface="remote", channel=srv.url, preserve_timestamps=True)
    try:
        frames = list(simulated_frames(cfg))
        for f in frames:
            client.send(f)
        deadline = time.monotonic() + 30
        decoded = -1
        while time.monotonic() < deadline and decoded != len(frames):
            f = client.recv(0.2)
            if f is not None and f.arbitration_id == status.frame_id and f.data[0] & 0x0F == 1:
                decoded = int(status.decode(f.data, decode_choices=False)["FramesDecoded"])
        assert decoded == len(frames)
    finally:
        client.shutdown()
    return daemon, run, len(frames)


def _assert_finished(daemon, run, rc, err, n_frames, reason):
    assert rc == 0, err
    assert any(line.startswith(f"stopped: {reason} (state stopped)")
               for line in daemon.out), daemon.out
    assert f"report:     {run}/report.txt" in daemon.out
    doc = json.loads((run / "result.json").read_text())
    assert doc["state"] == "finished"
    assert doc["stats"]["stop_reason"] == reason
    assert doc["stats"]["decoder"]["received"] == n_frames
    assert doc["gyros"]["az"]["bins"] == 121
    assert set(doc["gyros"]["az"]["fits"]) == {"lkf", "lkf_batch", "lsq", "ml"}
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert (run / "report.txt").read_text().strip()


def test_sighup_ends_the_daemon_as_sigterm_does(tmp_path):
    srv = RemoteServer().start()
    try:
        daemon, run, n = _daemon_with_frames(tmp_path, srv)
        try:
            daemon.proc.send_signal(signal.SIGHUP)
            rc, err = daemon.finish()
        finally:
            daemon.close()
    finally:
        srv.stop()
    _assert_finished(daemon, run, rc, err, n, "SIGHUP")


def test_ctrl_c_again_while_finishing_does_not_cut_the_end_short(tmp_path):
    """SIGINT, then SIGINT every 5 ms until the process has exited (a user holding
    Ctrl-C): the first stops the run, the others change nothing, wherever in the ending
    they land."""
    srv = RemoteServer().start()
    try:
        daemon, run, n = _daemon_with_frames(tmp_path, srv)
        try:
            sent = 0
            deadline = time.monotonic() + 90
            while daemon.proc.poll() is None and time.monotonic() < deadline:
                try:
                    daemon.proc.send_signal(signal.SIGINT)
                except ProcessLookupError:
                    break
                sent += 1
                time.sleep(0.005)
            rc, err = daemon.finish()
        finally:
            daemon.close()
    finally:
        srv.stop()
    assert sent >= 10  # the ending took at least 50 ms: later signals landed in it
    _assert_finished(daemon, run, rc, err, n, "SIGINT")
