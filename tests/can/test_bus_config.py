"""python-can's whole configuration through the command line: ``--bus-kwargs``,
``--app-name``, ``bus: {}``, and python-can's own config (``~/.canrc``, ``CAN_*``) as the
fallback for every bus key, with ``run --check`` naming each key's source. HOME is a
temporary folder holding the ``.canrc``; the bus opened is python-can's real virtual bus."""

from __future__ import annotations

import os

import can
import pytest
import yaml
from canhelpers import DATA

from gyrostand import exitcodes
from gyrostand.cli import main
from gyrostand.config import load_config

SIM = {"seed": 3, "start": 0.0, "duration": 20, "rates": {"drift": 10, "temperature": 10},
       "temperature": [[0, 20], [20, 30]],
       "gyros": {g: {"model": ["markov", "temp"],
                     "params": {"markov.beta": 0.03, "markov.sigma": 0.01,
                                "temp.gamma": 0.001}} for g in ("x", "y")}}


@pytest.fixture
def home(python_can_home):
    return python_can_home


def _session(tmp_path, bus: dict, simulate: bool = False):
    d = yaml.safe_load((DATA / "foreign.yaml").read_text())
    d["bus"] = bus
    d["dbc"] = str(DATA / "foreign.dbc")
    d["session"]["output"] = str(tmp_path / "runs")
    if simulate:
        d["simulate"] = SIM
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


def _canrc(home, channel: str, **more: str) -> None:
    lines = ["[default]", "interface = virtual", f"channel = {channel}", "bitrate = 500000"]
    lines += [f"{k} = {v}" for k, v in more.items()]
    (home / ".canrc").write_text("\n".join(lines) + "\n")


def test_run_check_names_the_source_of_every_bus_key(tmp_path, home, monkeypatch, capsys):
    _canrc(home, "from-canrc", receive_own_messages="true")
    monkeypatch.setenv("CAN_CHANNEL", "from-env")
    path = _session(tmp_path, {"bitrate": 250000})
    assert main(["run", str(path), "--check", "--bus-kwargs", "serial=1234",
                 "receive_own_messages=false", "rx_queue_size=3.5", "--app-name", "MyApp"]) == 0
    out = capsys.readouterr().out
    lines = out[out.index("  bus (not opened"):out.index("  dbc:")].splitlines()
    assert lines == [
        "  bus (not opened; after each key, where it came from):",
        "    interface            = 'virtual'  (python-can config ~/.canrc)",
        "    channel              = 'from-env'  (env CAN_CHANNEL)",
        "    bitrate              = 250000  (session file)",
        "    serial               = 1234  (command line)",
        "    receive_own_messages = False  (command line)",
        "    rx_queue_size        = 3.5  (command line)",
        "    app_name             = 'MyApp'  (command line)",
    ]


def test_bus_may_be_empty_and_an_interface_found_nowhere_is_bad_input(tmp_path, home,
                                                                      capsys):
    path = _session(tmp_path, {})
    cfg = load_config(path)  # `bus: {}` is accepted
    assert dict(cfg.bus) == {}
    assert main(["run", str(path), "--check"]) == exitcodes.CONFIG
    err = capsys.readouterr().err
    assert err.startswith(f"error: {path}: bus.interface: not given: set it in the session "
                          f"file's bus:, with -i/--interface, or in python-can's config")
    # -i alone fills it; CAN_INTERFACE alone fills it
    assert main(["run", str(path), "--check", "-i", "virtual"]) == 0
    assert "    interface = 'virtual'  (command line)\n" in capsys.readouterr().out
    os.environ["CAN_INTERFACE"] = "virtual"
    try:
        assert main(["run", str(path), "--check"]) == 0
    finally:
        del os.environ["CAN_INTERFACE"]
    assert "    interface = 'virtual'  (env CAN_INTERFACE)\n" in capsys.readouterr().out


def test_bad_bus_arguments_are_usage_errors(tmp_path, home, capsys):
    _canrc(home, "c")
    path = _session(tmp_path, {})
    with pytest.raises(SystemExit) as exc:
        main(["run", str(path), "--check", "--bus-kwargs", "no-equals-sign"])
    assert exc.value.code == exitcodes.USAGE
    assert ("argument --bus-kwargs: expected KEY=VALUE (a python-can bus argument), got "
            "'no-equals-sign'") in capsys.readouterr().err
    assert main(["run", str(path), "--check", "-c", "a", "--bus-kwargs", "channel=b"]) == \
        exitcodes.USAGE
    assert "error: --bus-kwargs: channel is also given by its own option (--channel)" in \
        capsys.readouterr().err
    bad = _session(tmp_path, [])
    assert main(["run", str(bad), "--check"]) == exitcodes.CONFIG
    assert "bus: expected a mapping of can.Bus arguments, got list" in capsys.readouterr().err


def _received(bus: can.BusABC) -> list[can.Message]:
    out = []
    while (m := bus.recv(timeout=0.2)) is not None:
        out.append(m)
    return out


def test_simulate_opens_the_bus_canrc_names_with_typed_bus_kwargs(tmp_path, home, capsys):
    """The frames arrive on the virtual channel named only in ~/.canrc; its
    ``preserve_timestamps = true`` reaches can.Bus as True (the simulator's frame times
    arrive), and ``--bus-kwargs preserve_timestamps=False`` as False (a string 'False'
    would be true): the receiver then sees wall-clock times."""
    from gyrostand.session.offline import simulated_frames

    channel = f"canrc-{os.getpid()}"
    _canrc(home, channel, preserve_timestamps="true")
    path = _session(tmp_path, {}, simulate=True)
    sent = list(simulated_frames(load_config(path)))
    with can.Bus(interface="virtual", channel=channel) as rx:
        assert main(["simulate", str(path)]) == 0
        got = _received(rx)
    assert capsys.readouterr().out == f"sent {len(sent)} frames on virtual:{channel}\n"
    assert [m.timestamp for m in got] == [m.timestamp for m in sent]
    assert [bytes(m.data) for m in got] == [bytes(m.data) for m in sent]
    with can.Bus(interface="virtual", channel=channel) as rx:
        assert main(["simulate", str(path), "--bus-kwargs", "preserve_timestamps=False"]) == 0
        got = _received(rx)
    assert len(got) == len(sent)
    assert all(g.timestamp > s.timestamp + 1e6 for g, s in zip(got, sent, strict=True))
