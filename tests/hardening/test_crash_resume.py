"""Crash safety (issue 5, item 2): ``kill -9`` of ``gyrostand run`` mid-run, then
``gyrostand run --resume`` on the same run folder.

Real processes throughout: a python-can-remote server, the daemon as a subprocess, a stand
sending paced frames (40x real time) over its own ``remote`` client, an observer client
that records the daemon's heartbeats. At each crash:

* the raw log of the killed segment is readable (``read_log``) and holds every frame sent
  up to one second of frame time before the daemon's last heartbeat;
* every *acknowledged* 1-s sample (a complete row of ``samples.csv`` on disk) is
  reproduced exactly by replaying the raw segments recorded so far: samples lost = 0;
* torn last lines are then injected into ``samples.csv``, ``estimates.csv`` and
  ``ledger.jsonl`` (what a kill in the middle of an append leaves): ``diagnose`` and
  ``report`` on the crashed folder still work, and the resume cuts them.

A second daemon resuming the folder while the first writes it is refused (exit 73). After
the last resume the run stops on a stop command: one run folder, ``samples.csv``
starts with the acknowledged rows unchanged, the crash's bins are gaps (n = 0, never
invented), the raw log continues in ``raw-2.blf``, ..., the ledger is kept, the estimates
cover every bin, and replaying all segments reproduces every row outside the crash gaps.
"""

from __future__ import annotations

import json
import math
import threading
import time
from pathlib import Path

import can
import pytest

from gyrostand import exitcodes
from gyrostand.can.bus import FrameEncoder
from gyrostand.can.replay import read_log
from gyrostand.cli import main as cli_main
from gyrostand.config import load_config
from gyrostand.runfolder import raw_segments
from gyrostand.session.offline import run_replay, simulated_frames

from .procs import Daemon, Observer, RemoteServer, frame_key, send_paced, write_config

pytest.importorskip("can_remote")

SPEED = 40.0      # frames paced at 40x their timestamps
DOWN = 10.0       # s of frame time lost while the daemon is down
COUNTS: dict[str, int] = {"kills": 0, "torn_lines": 0, "acked_rows": 0, "lost": 0,
                          "frames_checked": 0}


def _rows(path: Path) -> list[str]:
    """Complete data rows of a samples.csv (a torn last line is left out)."""
    text = path.read_text()
    lines = text.split("\n")[1:-1]
    return [ln for ln in lines if ln]


def _by_t(rows: list[str]) -> dict[float, str]:
    return {float(r.split(",", 1)[0]): r for r in rows}


def _beats(cfg, frames: list[can.Message]) -> list[float]:
    ref = cfg.responses.status
    return [f.timestamp for f in frames if f.arbitration_id == ref.frame_id]


def _crash_and_resume(tmp_path: Path, kills: int, duration: float) -> None:
    srv = RemoteServer().start()
    runs = tmp_path / "runs"
    cfg_path = write_config(tmp_path / "crash.yaml", runs,
                            {"interface": "remote", "channel": srv.url,
                             "preserve_timestamps": True},
                            sim={"duration": duration,
                                 "rates": {"drift": 100, "temperature": 10}})
    cfg = load_config(cfg_path)
    frames = list(simulated_frames(cfg))
    stand = can.Bus(interface="remote", channel=srv.url, preserve_timestamps=True)
    observer = Observer(srv.url)
    run_dir: Path | None = None
    gaps: list[tuple[float, float]] = []  # (last acked t, first t of the resumed segment)
    idx = 0
    daemons: list[Daemon] = []
    try:
        for cycle in range(kills + 1):
            args = ["--out", str(runs)] + (["--resume"] if cycle else [])
            d = Daemon(cfg_path, *args)
            daemons.append(d)
            rd = d.run_dir(d.wait_for("ready: "))
            assert run_dir is None or rd == run_dir, "resume must continue the same folder"
            run_dir = rd
            if cycle == kills:
                break
            n_obs = len(observer.frames)
            stop = threading.Event()
            sent = [0]

            def sending(i: int = idx, ev: threading.Event = stop, out: list = sent) -> None:
                out[0] = send_paced(stand, frames[i:], SPEED, ev)

            sender = threading.Thread(target=sending)
            sender.start()
            samples = run_dir / "az" / "samples.csv"
            # (diagnose needs > 40 bins: on shorter records the core's cross-correlation
            # fails, a known defect outside this test)
            target = len(_rows(samples)) + 60
            deadline = time.monotonic() + 60
            while len(_rows(samples)) < target and time.monotonic() < deadline:
                time.sleep(0.02)
            d.kill9()  # mid-stream: the stand is still sending
            COUNTS["kills"] += 1
            stop.set()
            sender.join(10)
            last_sent = idx + sent[0]
            acked = _rows(samples)
            assert len(acked) >= target, "the daemon did not acknowledge bins in time"
            beats = _beats(cfg, observer.frames[n_obs:])
            assert beats, "no heartbeat from the killed daemon"
            # the raw log of the killed segment: readable, at most ~1 s of frame time lost
            seg = raw_segments(run_dir)[-1]
            got = {frame_key(f) for f in read_log(seg)}
            due = [f for f in frames[idx:last_sent] if f.timestamp <= beats[-1] - 1.0]
            assert due and all(frame_key(f) in got for f in due), \
                f"{sum(frame_key(f) not in got for f in due)} frames missing from {seg.name}"
            COUNTS["frames_checked"] += len(due)
            # every acknowledged row replays from the raw segments so far
            rep = run_replay(cfg, raw_segments(run_dir), out=tmp_path / f"replay-{cycle}")
            replayed = _by_t(_rows(rep.run_dir / "az" / "samples.csv"))
            lost = 0
            for row in acked:
                t = float(row.split(",", 1)[0])
                if any(a < t < b for a, b in gaps):  # a resumed daemon's gap bin
                    assert row.endswith(",0,0"), f"invented data in a crash gap: {row}"
                elif replayed.get(t) != row:
                    lost += 1
            COUNTS["acked_rows"] += len(acked)
            COUNTS["lost"] += lost
            assert lost == 0, f"{lost} acknowledged samples not reproduced by replay"
            # a torn last line (a kill in the middle of an append) must not break anything
            t_ack = float(acked[-1].split(",", 1)[0])
            nxt = replayed.get(t_ack + cfg.sampling.dt, f"{t_ack + 1!r},0.123456789,25.5,9,1")
            with samples.open("a") as fh:
                fh.write(nxt[: len(nxt) // 2])
            est = run_dir / "az" / "estimates.csv"
            last_est = est.read_text().split("\n")[-2]
            with est.open("a") as fh:
                fh.write(last_est[: len(last_est) // 3])
            COUNTS["torn_lines"] += 2
            assert cli_main(["diagnose", str(run_dir), "--json"]) == 0
            with (run_dir / "ledger.jsonl").open("a") as fh:
                fh.write('{"step": 99, "gyro": "az", "act')  # a torn ledger entry
            COUNTS["torn_lines"] += 1
            if cycle == 0:
                assert cli_main(["report", str(run_dir), "--out", str(tmp_path / "rep")]) == 0
            # the stand goes on; what it sends while no daemon listens is lost
            t_back = math.ceil(frames[last_sent - 1].timestamp + DOWN)
            idx = next(i for i, f in enumerate(frames) if f.timestamp >= t_back)
            gaps.append((t_ack, float(t_back)))
        # the last (resumed) daemon gets the rest and a stop command; a second daemon
        # resuming the same folder meanwhile is refused (the folder is locked)
        assert run_dir is not None
        other = Daemon(cfg_path, "--out", str(runs), "--resume")
        daemons.append(other)
        rc2, err2 = other.finish(timeout=60)
        assert rc2 == exitcodes.CANTCREAT and f"{run_dir}: in use by a running daemon (pid " \
            f"{daemons[-2].proc.pid})" in err2, err2
        ledger_before = (run_dir / "ledger.jsonl").read_text()
        send_paced(stand, frames[idx:], SPEED * 2)
        enc = FrameEncoder(cfg.db)
        stand.send(enc.command_frame(cfg.responses.command, "stop", 9, 1,
                                     timestamp=frames[-1].timestamp + 0.01))
        rc, err = daemons[-2].finish()
        assert rc == 0, err
    finally:
        for d in daemons:
            d.close()
        stand.shutdown()
        observer.close()
        srv.stop()

    final = _rows(run_dir / "az" / "samples.csv")
    ts = [float(r.split(",", 1)[0]) for r in final]
    assert all(b - a == cfg.sampling.dt for a, b in zip(ts, ts[1:], strict=False)), \
        "the resumed series is contiguous on the same grid"
    assert (run_dir / "ledger.jsonl").read_text() == ledger_before != ""
    assert [p.name for p in raw_segments(run_dir)] == \
        ["raw.blf"] + [f"raw-{i}.blf" for i in range(2, kills + 2)]
    est = (run_dir / "az" / "estimates.csv").read_text().splitlines()[1:]
    assert [float(r.split(",", 1)[0]) for r in est] == ts
    doc = json.loads((run_dir / "result.json").read_text())
    assert doc["state"] == "finished" and doc["stats"]["stop_reason"] == "stop command"
    assert doc["gyros"]["az"]["bins"] == len(final)
    assert "markov.beta" in doc["gyros"]["az"]["fits"]["ml"]["parameters"]
    # the counts of every segment, the killed ones as of their last acknowledgement
    segs = doc["stats"]["segments"]
    assert [x["raw"] for x in segs] == [p.name for p in raw_segments(run_dir)]
    assert [x["state"] for x in segs] == ["crashed"] * kills + ["finished"]
    assert segs[-1]["ended_by"] == "stop command"
    assert segs[-1]["decoder"] == doc["stats"]["decoder"]
    per_wall_s = len(frames) / (frames[-1].timestamp - frames[0].timestamp) * SPEED * 2
    for x, seg in zip(segs, raw_segments(run_dir), strict=True):
        recorded = sum(1 for _ in read_log(seg))
        assert abs(x["decoder"]["decoded"] - recorded) <= 1.5 * per_wall_s, (x, recorded)
    tot = doc["stats"]["run_totals"]
    assert tot["decoder"]["decoded"] == sum(x["decoder"]["decoded"] for x in segs)
    assert tot["binner"]["bins"] == sum(x["binner"]["bins"] for x in segs)
    assert tot["rows_written"] == sum(x["rows_written"] for x in segs)
    assert "whole run, " in (run_dir / "report.txt").read_text()
    # replaying every segment reproduces the run's rows outside the crash gaps
    rep = run_replay(cfg, raw_segments(run_dir), out=tmp_path / "replay-final")
    replayed = _by_t(_rows(rep.run_dir / "az" / "samples.csv"))
    mismatched = [r for r in final if not any(a < float(r.split(",", 1)[0]) < b
                                               for a, b in gaps)
                  and replayed.get(float(r.split(",", 1)[0])) != r]
    assert not mismatched, mismatched[:3]
    for a, b in gaps:
        inside = [r for r in final if a < float(r.split(",", 1)[0]) < b]
        assert inside and all(r.endswith(",0,0") for r in inside)


def test_kill9_then_resume_loses_no_acknowledged_sample(tmp_path):
    _crash_and_resume(tmp_path, kills=1, duration=200.0)
    print("crash counts:", COUNTS)


@pytest.mark.slow
def test_repeated_kill9_and_resume(tmp_path):
    _crash_and_resume(tmp_path, kills=4, duration=600.0)
    print("crash counts:", COUNTS)
