"""Configs and files (issue 5, item 6): every invalid session file, an unwritable output
folder and a full disk make ``gyrostand run`` (a real process) exit non-zero with a
message naming the key or the path; YAML is loaded safely.

The full disk is a 256 KiB tmpfs mounted for the test (root only; skipped otherwise): the
daemon, fed over python-can-remote until the disk fills, must stop by itself in state
``fault`` naming the file it could not write, and what it had acknowledged stays
readable: ``samples.csv`` rows, the raw log up to the failure (replaying to those rows),
``diagnose`` on the folder.
"""

from __future__ import annotations

import copy
import os
import resource
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import pytest
import yaml

from gyrostand import exitcodes
from gyrostand.can.replay import read_log
from gyrostand.cli import main as cli_main
from gyrostand.config import load_config
from gyrostand.errors import ConfigError
from gyrostand.runfolder import read_samples_csv
from gyrostand.session.offline import run_replay, simulated_frames

from .procs import DBC, DEMO, ROOT, Daemon, RemoteServer, write_config

PWNED = Path(f"/tmp/hard_pwned_{os.getpid()}")


def _demo(tmp: Path) -> dict:
    d = yaml.safe_load(DEMO.read_text())
    d["session"]["output"] = str(tmp / "runs")
    d["dbc"] = str(DBC)
    d["bus"] = {"interface": "virtual", "channel": f"hard-cfg-{os.getpid()}"}
    return d


def _set(d: dict, path: str, value) -> dict:
    d = copy.deepcopy(d)
    keys = path.split(".")
    node = d
    for k in keys[:-1]:
        node = node[int(k)] if isinstance(node, list) else node[k]
    if value is KeyError:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value
    return d


#: (case, change to the demo session, text the error must contain)
BAD = [
    ("wrong type", ("sampling.dt", "fast"), "sampling.dt: expected a number"),
    ("wrong type int", ("sampling.buffer", 1.5), "sampling.buffer: expected an integer"),
    ("wrong type list", ("gyros.0.model", 3), "gyros[0].model: expected a non-empty list"),
    ("unknown key", ("sampling.dtt", 1.0), "sampling.dtt: unknown key"),
    ("unknown top key", ("extra", {}), "extra: unknown key"),
    ("missing key", ("gyros.0.drift", KeyError), "gyros[0].drift: missing required key"),
    ("missing DBC", ("dbc", "/nonexistent/gyro.dbc"), "/nonexistent/gyro.dbc"),
    ("signal not in DBC", ("gyros.0.drift.signal", "Drft"), "gyros[0].drift.signal: 'Drft'"),
    ("message not in DBC", ("gyros.0.temperature.message", "GYRO_TEMP_9"),
     "gyros[0].temperature.message"),
    ("bad command rate", ("responses.command_rate", -1), "responses.command_rate: must be >"),
    ("bad reconnect", ("reconnect", {"max_time": "long"}), "reconnect.max_time"),
    ("negative at_start", ("reconnect", {"at_start": -1}), "reconnect.at_start: must be >="),
    ("unwritable output", ("session.output", "__FILE__/runs"), "__FILE__"),
]


def _write(tmp: Path, name: str, d: dict | str) -> Path:
    p = tmp / f"{name.replace(' ', '_')}.yaml"
    p.write_text(d if isinstance(d, str) else yaml.safe_dump(d))
    return p


def test_every_invalid_config_exits_nonzero_naming_the_key(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    demo = _demo(tmp_path)
    cases = []
    for name, (key, value), expect in BAD:
        if isinstance(value, str) and "__FILE__" in value:
            value, expect = value.replace("__FILE__", str(blocker)), str(blocker)
        cases.append((name, _write(tmp_path, name, _set(demo, key, value)), expect))
    # YAML is loaded safely: a python tag is refused, never executed
    evil = DEMO.read_text() + (f"\nextra: !!python/object/apply:os.system "
                               f"['touch {PWNED}']\n")
    cases.append(("python tag", _write(tmp_path, "python tag", evil),
                  "could not determine a constructor"))
    cases.append(("not yaml", _write(tmp_path, "not yaml", "session: [unclosed"),
                  "invalid YAML"))
    cases.append(("no file", tmp_path / "missing.yaml", "cannot read config"))
    # three cases as real processes (exit status and stderr of `gyrostand run`), all of
    # them through the same entry point in this process (2 s less start-up each)
    as_process = {"wrong type", "python tag", "unwritable output"}
    procs = {name: subprocess.Popen(
        [sys.executable, "-m", "gyrostand", "run", str(path), "--duration", "1"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
        for name, path, _ in cases if name in as_process}
    failures = []
    for name, path, expect in cases:
        capsys.readouterr()
        rc = cli_main(["run", str(path), "--duration", "1"])
        err = capsys.readouterr().err
        if name in procs:
            _, perr = procs[name].communicate(timeout=120)
            if procs[name].returncode != rc or expect not in perr \
                    or perr.split(": ")[1:] != err.split(": ")[1:] and name != "unwritable output":
                failures.append((name, "process differs", procs[name].returncode, perr))
        if rc == 0 or expect not in err or not err.startswith("error: ") \
                or "Traceback" in err:
            failures.append((name, rc, err[-400:]))
        elif name != "unwritable output" and str(path) not in err:
            failures.append((name, "message does not name the file", err[-300:]))
    assert not failures, failures
    assert len(cases) == len(BAD) + 3
    assert not PWNED.exists(), "a YAML tag executed code"
    with pytest.raises(ConfigError, match="could not determine a constructor"):
        load_config(tmp_path / "python_tag.yaml")


# -- a read-only and a full file system -----------------------------------------------------

def _mount(where: Path, opts: str) -> bool:
    where.mkdir(parents=True, exist_ok=True)
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(where)],
                       capture_output=True)
    return r.returncode == 0


def _umount(where: Path) -> None:
    subprocess.run(["umount", "-l", str(where)], capture_output=True)


@pytest.fixture
def mounts(tmp_path):
    made: list[Path] = []

    def mount(name: str, opts: str, required: bool = True) -> Path | None:
        p = Path(f"/tmp/hard_mnt_{os.getpid()}_{name}")
        if os.geteuid() != 0 or not _mount(p, opts):
            if required:
                pytest.skip("cannot mount a tmpfs here (needs root)")
            return None
        made.append(p)
        return p

    yield mount
    for p in made:
        _umount(p)
        try:
            p.rmdir()
        except OSError:
            pass


def test_read_only_output_folder_names_the_path(tmp_path, mounts):
    ro = mounts("ro", "size=64k,ro")
    cfg = _write(tmp_path, "ro", _set(_demo(tmp_path), "session.output", str(ro / "runs")))
    r = subprocess.run([sys.executable, "-m", "gyrostand", "run", str(cfg), "--duration",
                        "1"], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == exitcodes.CANTCREAT and r.stderr.startswith("error: "), r.stderr
    assert str(ro / "runs") in r.stderr and "Read-only file system" in r.stderr


def _limit_file_size() -> None:  # in the daemon's process, before exec
    resource.setrlimit(resource.RLIMIT_FSIZE, (256 * 1024, 256 * 1024))


def test_full_disk_stops_cleanly_naming_the_file_and_keeps_what_was_written(tmp_path,
                                                                         mounts):
    """A 256 KiB tmpfs as the output folder; where no tmpfs can be mounted (not root), a
    256 KiB file-size limit (RLIMIT_FSIZE) on the daemon's process instead (Python
    ignores SIGXFSZ, so a write past it fails with EFBIG like a full disk)."""
    disk = mounts("full", "size=256k", required=False)
    expect = "No space left on device" if disk else "File too large"
    disk = disk or tmp_path
    srv = RemoteServer().start()
    cfg_path = write_config(tmp_path / "full.yaml", disk / "runs",
                            {"interface": "remote", "channel": srv.url,
                             "preserve_timestamps": True},
                            sim={"duration": 3000.0, "rates": {"drift": 100,
                                                                "temperature": 10}})
    cfg = load_config(cfg_path)
    daemon = Daemon(cfg_path, preexec_fn=None if disk != tmp_path else _limit_file_size)
    stand = None
    sent = [0]
    try:
        run_dir = daemon.run_dir(daemon.wait_for("ready: "))
        stand = can.Bus(interface="remote", channel=srv.url, preserve_timestamps=True)

        def flood() -> None:  # ~4,400 frames/s (the disk fills in a few seconds)
            t0, w0 = None, time.monotonic()
            for f in simulated_frames(cfg):
                if daemon.proc.poll() is not None:
                    return
                t0 = f.timestamp if t0 is None else t0
                delay = w0 + (f.timestamp - t0) / 40.0 - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                try:
                    stand.send(f)
                except Exception:
                    return
                sent[0] += 1

        th = threading.Thread(target=flood, daemon=True)
        th.start()
        rc, err = daemon.finish(timeout=120)
        th.join(10)
    finally:
        daemon.close()
        if stand is not None:
            stand.shutdown()
        srv.stop()
    assert rc == exitcodes.IOERR, (rc, err, daemon.out)
    stopped = next(ln for ln in daemon.out if ln.startswith("stopped: "))
    assert expect in stopped and "state fault" in stopped, stopped
    assert str(run_dir) in stopped  # the message names the file that failed
    assert sent[0] > 5000
    # what was written is intact: samples readable, raw log readable and replaying to them
    cols = read_samples_csv(run_dir / "az" / "samples.csv")
    assert len(cols["t"]) >= 10
    frames = sum(1 for _ in read_log(run_dir / "raw.blf"))
    assert frames > 1000
    free = tmp_path / "replay"
    rep = run_replay(cfg, run_dir / "raw.blf", out=free)
    rows = (run_dir / "az" / "samples.csv").read_text().split("\n")[1:-1]
    replayed = set((rep.run_dir / "az" / "samples.csv").read_text().split("\n")[1:-1])
    lost = [r for r in rows if r not in replayed]
    assert not lost, lost[:3]
    assert (run_dir / "result.json").is_file()  # provisional or final, never half
    r = subprocess.run([sys.executable, "-m", "gyrostand", "diagnose", str(run_dir)],
                       capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert "Traceback" not in r.stderr, r.stderr[-600:]
