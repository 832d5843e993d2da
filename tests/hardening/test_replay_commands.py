"""Replay = live, for commands too (issue 28, finding 9): ``gyrostand run`` over
python-can-remote receives a stand's frames with 41 ``reset`` commands among them (acked),
then ``gyrostand replay`` of its run folder gives the same samples.csv *and* the same
estimates.csv, byte for byte (before: samples equal, estimates.csv differed in 198 of 364
rows, the online LSQ at stop 0.10669 live vs 0.10782 replayed): a reset at frame time t
restarts the online identifiers before the bin that contains t, however the bins are
batched."""

from __future__ import annotations

import json

import can
import pytest

from gyrostand.can.bus import FrameEncoder
from gyrostand.cli import main as cli_main
from gyrostand.config import load_config
from gyrostand.session.offline import simulated_frames

from .procs import Daemon, RemoteServer, send_paced, write_config

pytest.importorskip("can_remote")


def test_resets_apply_at_the_same_bins_live_and_replayed(tmp_path, capsys):
    srv = RemoteServer().start()
    cfg_path = write_config(tmp_path / "live.yaml", tmp_path / "runs",
                            {"interface": "remote", "channel": srv.url,
                             "preserve_timestamps": True},
                            sim={"duration": 130, "rates": {"drift": 20, "temperature": 10}})
    cfg = load_config(cfg_path)
    enc = FrameEncoder(cfg.db)
    frames = list(simulated_frames(cfg))
    t0 = frames[0].timestamp
    resets = [enc.command_frame(cfg.responses.command, "reset", i + 1, 255,
                                timestamp=t0 + 3.3 + 3.0 * i) for i in range(41)]
    stop = enc.command_frame(cfg.responses.command, "stop", 99, 255,
                             timestamp=frames[-1].timestamp + 0.01)
    stream = sorted(frames + resets, key=lambda f: f.timestamp) + [stop]
    daemon = Daemon(cfg_path, "--out", str(tmp_path / "runs"))
    stand = None
    try:
        run_dir = daemon.run_dir(daemon.wait_for("ready: "))
        stand = can.Bus(interface="remote", channel=srv.url, preserve_timestamps=True)
        assert send_paced(stand, stream, speed=80.0) == len(stream)
        rc, err = daemon.finish()
    finally:
        daemon.close()
        if stand is not None:
            stand.shutdown()
        srv.stop()
    assert rc == 0, err
    live = json.loads((run_dir / "result.json").read_text())
    assert live["stats"]["commands"]["acked"] == 42  # 41 resets and the stop
    out = tmp_path / "replayed"
    assert cli_main(["replay", str(cfg_path), str(run_dir), "--out", str(out)]) == 0, \
        capsys.readouterr().err
    (rep,) = [p for p in out.iterdir() if p.is_dir()]
    for name in ("samples.csv", "estimates.csv"):
        a, b = (run_dir / "az" / name).read_bytes(), (rep / "az" / name).read_bytes()
        assert a.count(b"\n") > 120, name
        assert a == b, name
