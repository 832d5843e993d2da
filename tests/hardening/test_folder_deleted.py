"""A run folder removed while ``gyrostand run`` writes it is a failed write, exit 74
(IOERR) naming the file (issue 28, "Exit codes"; before: exit 2, bad input, which systemd does not restart:
a raw FileNotFoundError reached the command line)."""

from __future__ import annotations

import shutil
import threading
import time

import can
import pytest

from gyrostand import exitcodes
from gyrostand.config import load_config
from gyrostand.session.offline import simulated_frames

from .procs import Daemon, RemoteServer, send_paced, write_config

pytest.importorskip("can_remote")


def test_run_folder_deleted_mid_run_is_exit_1(tmp_path):
    srv = RemoteServer().start()
    cfg_path = write_config(tmp_path / "c.yaml", tmp_path / "runs",
                            {"interface": "remote", "channel": srv.url,
                             "preserve_timestamps": True},
                            sim={"duration": 200, "rates": {"drift": 20, "temperature": 10}})
    frames = list(simulated_frames(load_config(cfg_path)))
    daemon = Daemon(cfg_path)
    bus = None
    try:
        run_dir = daemon.run_dir(daemon.wait_for("ready: "))
        bus = can.Bus(interface="remote", channel=srv.url, preserve_timestamps=True)
        sender = threading.Thread(target=send_paced, args=(bus, frames, 40.0), daemon=True)
        sender.start()
        time.sleep(2.0)
        # as `rm -rf` would be, again while the daemon's next write lands between the
        # listing and the removal ("Directory not empty": seen once in CI)
        for _ in range(100):
            shutil.rmtree(run_dir, ignore_errors=True)
            if not run_dir.exists():
                break
            time.sleep(0.01)
        assert not run_dir.exists(), sorted(run_dir.rglob("*"))
        rc, err = daemon.finish(120)
        sender.join(10)
    finally:
        daemon.close()
        if bus is not None:
            bus.shutdown()
        srv.stop()
    assert rc == exitcodes.IOERR, err
    assert f"error: {run_dir}/az/samples.csv: " in err and "No such file" in err, err
    assert "Traceback" not in err
