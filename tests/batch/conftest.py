"""A small lab archive for the batch tests, made the way a lab's archive is made: session
files derived from configs/demo.yaml, CAN logs written by ``gyrostand simulate`` (frames
with jitter, drops, quantized sensors), a run folder written by ``gyrostand replay``, and a
manifest CSV of run attributes.

Runs (1200 s each, 10 Hz drift and temperature frames; the fitted model is the session's
``markov,temp``):

* ``u1-a``, ``u1-b``: unit U1 on two dates (seeds 1, 2), logs;
* ``u2``: unit U2, a run folder (replayed here from its log);
* ``u3-hidden``: unit U3 whose drift has a thermal-gradient term ``temp_rate`` (k = 10
  (deg/h)·s/°C) that its session's model lacks: the diagnosis must name it;
* ``u4-bad``: a corrupt log (garbage bytes in a .blf).
"""

from __future__ import annotations

import copy
import csv
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from gyrostand.cli import main

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "configs" / "demo.yaml"
DBC = ROOT / "dbc" / "gyrostand.dbc"
DURATION = 1200
TRUTH = {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.001}
HIDDEN_K = 10.0


def session_file(path: Path, seed: int, hidden: bool = False) -> Path:
    d = copy.deepcopy(yaml.safe_load(DEMO.read_text()))
    d["session"]["output"] = str(path.parent / "runs")
    d["dbc"] = str(DBC)
    d["gyros"][0]["identifiers"] = ["ml"]
    sim = d["simulate"]
    sim["seed"] = seed
    sim["duration"] = DURATION
    sim["rates"] = {"drift": 10, "temperature": 10}
    if hidden:
        sim["gyros"]["az"]["model"] = ["markov", "temp", "temp_rate", "white"]
        sim["gyros"]["az"]["params"]["temp_rate.k"] = HIDDEN_K
    path.write_text(yaml.safe_dump(d))
    return path


def _simulate(cfg: Path, log: Path) -> None:
    assert main(["-q", "simulate", str(cfg), "--log", str(log)]) == 0


@pytest.fixture(scope="session")
def archive(tmp_path_factory) -> dict[str, Path]:
    """The archive folder, its manifest and the run names."""
    root = tmp_path_factory.mktemp("archive")
    logs = root / "logs"
    logs.mkdir()
    rows = []
    for run, seed, serial, date, hidden in (("u1-a", 1, "U1", "2026-01-10", False),
                                            ("u1-b", 2, "U1", "2026-03-10", False),
                                            ("u3-hidden", 4, "U3", "2026-02-01", True)):
        cfg = session_file(root / f"{run}.yaml", seed, hidden)
        _simulate(cfg, logs / f"{run}.blf")
        rows.append({"run": run, "path": f"logs/{run}.blf", "config": f"{run}.yaml",
                     "serial": serial, "date": date, "type": "FOG-A"})
    # a run folder: the log replayed by `gyrostand replay`
    cfg = session_file(root / "u2.yaml", 3)
    _simulate(cfg, logs / "u2.blf")
    assert main(["-q", "replay", str(cfg), str(logs / "u2.blf"), "--out",
                 str(root / "folders")]) == 0
    (folder,) = (root / "folders").iterdir()
    folder = folder.rename(root / "folders" / "u2")
    (logs / "u2.blf").unlink()  # the folder keeps none of it but samples + result.json
    rows.append({"run": "u2", "path": "folders/u2", "config": "", "serial": "U2",
                 "date": "2026-02-15", "type": "FOG-A"})
    (logs / "u4-bad.blf").write_bytes(b"LOGG" + os.urandom(20000))
    rows.append({"run": "u4-bad", "path": "logs/u4-bad.blf", "config": "u1-a.yaml",
                 "serial": "U4", "date": "2026-02-20", "type": "FOG-A"})
    manifest = root / "manifest.csv"
    with manifest.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return {"root": root, "manifest": manifest}


RUNS = ("u1-a", "u1-b", "u3-hidden", "u2", "u4-bad")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_port(port: int, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    raise TimeoutError(f"nothing listens on 127.0.0.1:{port} after {timeout:g} s")


def stop(proc: subprocess.Popen, timeout: float = 10.0) -> None:
    """Terminate a process group we started, then kill it."""
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, 15)
            proc.wait(timeout)
        except (ProcessLookupError, subprocess.TimeoutExpired):
            try:
                os.killpg(proc.pid, 9)
            except ProcessLookupError:
                pass
            proc.wait(timeout)


@pytest.fixture
def dask_cluster(tmp_path):
    """``dask scheduler`` and one ``dask worker`` as separate processes on 127.0.0.1."""
    dask = Path(sys.executable).with_name("dask")
    port = free_port()
    addr = f"tcp://127.0.0.1:{port}"
    logs = tmp_path / "dask-logs"
    logs.mkdir()
    sched = subprocess.Popen([str(dask), "scheduler", "--host", "127.0.0.1", "--port",
                              str(port), "--no-dashboard"],
                             stdout=subprocess.DEVNULL,
                             stderr=(logs / "scheduler.err").open("w"),
                             start_new_session=True)
    procs = [sched]
    try:
        wait_port(port)
        worker = subprocess.Popen([str(dask), "worker", addr, "--nthreads", "1",
                                   "--nworkers", "1", "--host", "127.0.0.1",
                                   "--no-dashboard"],
                                  stdout=subprocess.DEVNULL,
                                  stderr=(logs / "worker.err").open("w"),
                                  start_new_session=True)
        procs.append(worker)
        yield addr
    finally:
        for p in reversed(procs):
            stop(p)
