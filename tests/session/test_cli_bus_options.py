"""python-can's command-line conventions on run/simulate/demo: -i/-c/-b/--fd/--data-bitrate
override the session's bus: and reach can.Bus (virtual in-process, python-can-remote on
127.0.0.1 across processes); global options after the subcommand; simulate --log (--out
deprecated)."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import pytest
from sessionhelpers import DEMO, decode, write_cfg_yaml

from gyrostand import exitcodes
from gyrostand.can.bus import FrameEncoder
from gyrostand.cli import build_parser, main
from gyrostand.cli.common import with_bus_overrides
from gyrostand.config import load_config
from gyrostand.session.offline import simulated_frames


def _cfg(tmp_path: Path, bus: dict, duration: float = 20.0) -> Path:
    return write_cfg_yaml(tmp_path / "s.yaml", tmp_path / "runs", bus, duration=duration,
                          rates={"drift": 10, "temperature": 10})


def _drain(bus: can.BusABC) -> list[can.Message]:
    got = []
    while (f := bus.recv(0.05)) is not None:
        got.append(f)
    return got


def test_options_override_only_the_keys_given():
    cfg = load_config(DEMO)
    args = build_parser().parse_args(["demo", "-c", "stand-b", "-b", "250000", "--fd",
                                      "--data-bitrate", "2000000"])
    bus = dict(with_bus_overrides(cfg, args).bus)
    assert bus == {**cfg.bus, "channel": "stand-b", "bitrate": 250000, "fd": True,
                   "data_bitrate": 2000000}
    args = build_parser().parse_args(["run", "x.yaml", "--interface", "socketcan"])
    assert dict(with_bus_overrides(cfg, args).bus) == {**cfg.bus, "interface": "socketcan"}
    same = with_bus_overrides(cfg, build_parser().parse_args(["run", "x.yaml"]))
    assert same.bus == cfg.bus and set(same.bus_sources.values()) == {"session file"}


def test_global_options_work_after_the_subcommand(tmp_path, capsys):
    missing = str(tmp_path / "missing.csv")
    assert main(["identify", missing]) == exitcodes.NOINPUT
    assert "error:" in capsys.readouterr().err
    with pytest.raises(Exception, match="missing.csv"):  # --debug: the traceback
        main(["identify", missing, "--debug"])
    with pytest.raises(Exception, match="missing.csv"):
        main(["--debug", "identify", missing])
    from gyrostand.cli import _gather_globals
    for argv, verbose in ((["-v", "identify", "x"], 1), (["identify", "x", "-vv"], 2),
                          (["-v", "identify", "x", "-v"], 2), (["identify", "x"], 0)):
        args = build_parser().parse_args(argv)
        _gather_globals(args)
        assert (args.verbose, args.debug) == (verbose, False), argv


def test_help_lists_the_valid_terms(capsys):
    for argv in (["fit", "--help"], ["identify", "--help"]):
        with pytest.raises(SystemExit):
            main(argv)
        out = " ".join(capsys.readouterr().out.split())
        assert "temp_rate, hysteresis, trend, warmup, random_walk, markov2" in out, argv


def test_simulate_channel_override_reaches_the_virtual_bus(tmp_path, capsys):
    cfg_path = _cfg(tmp_path, {"interface": "virtual", "channel": "cli-opt-config"})
    n_frames = sum(1 for _ in simulated_frames(load_config(cfg_path)))
    wanted = can.Bus(interface="virtual", channel="cli-opt-override")
    configured = can.Bus(interface="virtual", channel="cli-opt-config")
    try:
        assert main(["simulate", str(cfg_path), "-c", "cli-opt-override", "--fast"]) == 0
        assert capsys.readouterr().out.strip() == \
            f"sent {n_frames} frames on virtual:cli-opt-override"
        assert len(_drain(wanted)) == n_frames > 400
        assert _drain(configured) == []
    finally:
        wanted.shutdown()
        configured.shutdown()


def test_simulate_log_and_its_deprecated_spelling(tmp_path, capsys, caplog):
    cfg_path = _cfg(tmp_path, {"interface": "virtual", "channel": "cli-opt-log"})
    assert main(["simulate", str(cfg_path), "--log", str(tmp_path / "a.blf")]) == 0
    with caplog.at_level(logging.WARNING):
        assert main(["simulate", str(cfg_path), "--out", str(tmp_path / "b.blf")]) == 0
    assert "deprecated: use --log" in caplog.text
    assert (tmp_path / "a.blf").read_bytes() == (tmp_path / "b.blf").read_bytes()
    capsys.readouterr()
    assert main(["simulate", str(cfg_path), "--log", "x.blf", "--out", "y.blf"]) == exitcodes.USAGE
    assert "not both" in capsys.readouterr().err


def test_run_interface_and_channel_override_the_session_bus(tmp_path, capsys):
    """The session names a remote server nobody runs; -i virtual -c CH runs the daemon on
    an in-process virtual channel instead, which the test feeds."""
    cfg_path = _cfg(tmp_path, {"interface": "remote", "channel": "ws://127.0.0.1:9/",
                               "preserve_timestamps": True}, duration=30.0)
    cfg = load_config(cfg_path)
    out = tmp_path / "runs"
    rc: list[int] = []
    t = threading.Thread(target=lambda: rc.append(main(
        ["run", str(cfg_path), "-i", "virtual", "-c", "cli-opt-run", "--duration", "25",
         "--out", str(out)])))
    stand = can.Bus(interface="virtual", channel="cli-opt-run", preserve_timestamps=True)
    t.start()
    try:
        deadline = time.monotonic() + 30
        while not (out.is_dir() and any(out.iterdir())) and time.monotonic() < deadline:
            time.sleep(0.02)  # the run folder exists once the bus is open
        frames = list(simulated_frames(cfg))
        for f in frames:
            stand.send(f)
        t.join(60)
    finally:
        stand.shutdown()
    assert rc == [0]
    printed = capsys.readouterr().out
    result = next(line.split(None, 1)[1] for line in printed.splitlines()
                  if line.startswith("result:"))
    doc = json.loads(Path(result).read_text())
    assert "cli-opt-run" in doc["stats"]["bus"]["channel"]
    assert doc["stats"]["decoder"]["decoded"] >= 0.99 * 26 * 20


pytest.importorskip("can_remote")

from tests.hardening.procs import Daemon, free_port, wait_port  # noqa: E402


def test_run_remote_options_reach_the_server_bus(tmp_path):
    """-i remote -c ws://127.0.0.1:PORT/ -b --fd --data-bitrate: the daemon (another
    process) opens the remote bus with them; the server's log shows the can.Bus
    arguments it received; frames flow and a stop command is acknowledged."""
    port = free_port()
    url = f"ws://127.0.0.1:{port}/"
    server_log = tmp_path / "server.log"
    with server_log.open("w") as fh:
        server = subprocess.Popen(
            [sys.executable, "-m", "can_remote", "--interface", "virtual", "--channel",
             f"cli-opt-remote-{port}", "--host", "127.0.0.1", "--port", str(port)],
            stdout=subprocess.DEVNULL, stderr=fh)
    try:
        wait_port(port)
        cfg_path = _cfg(tmp_path, {"interface": "virtual", "channel": "nobody-sends-here",
                                   "preserve_timestamps": True}, duration=20.0)
        cfg = load_config(cfg_path)
        daemon = Daemon(cfg_path, "-i", "remote", "-c", url, "-b", "250000", "--fd",
                        "--data-bitrate", "2000000", "--out", str(tmp_path / "runs"))
        try:
            ready = daemon.wait_for("ready: ")
            client = can.Bus(interface="remote", channel=url, preserve_timestamps=True)
            try:
                frames = list(simulated_frames(cfg))
                for f in frames:
                    client.send(f)
                client.send(FrameEncoder(cfg.db).command_frame(
                    cfg.responses.command, "stop", 5, 1, timestamp=frames[-1].timestamp))
                got, deadline = [], time.monotonic() + 30
                while time.monotonic() < deadline and not decode(cfg, got, "GS_ACK"):
                    if (f := client.recv(0.2)) is not None:
                        got.append(f)
            finally:
                client.shutdown()
            rc, err = daemon.finish()
        finally:
            daemon.close()
    finally:
        server.terminate()
        server.wait(10)
    assert rc == 0, err
    assert decode(cfg, got, "GS_ACK")[-1]["Result"] == 0
    doc = json.loads((daemon.run_dir(ready) / "result.json").read_text())
    assert url in doc["stats"]["bus"]["channel"]
    assert doc["stats"]["decoder"]["decoded"] == len(frames) + 1  # and the stop command
    received = [line for line in server_log.read_text().splitlines()
                if "Config received" in line]
    assert received, server_log.read_text()[-2000:]
    assert "'bitrate': 250000" in received[0] and "'fd': True" in received[0]
    assert "'data_bitrate': 2000000" in received[0]
