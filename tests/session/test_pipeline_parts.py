"""The parts the daemon's pipeline is made of (issue 12, item 5): the command protocol's
state machine, no I/O before ``open()``, the backoff of bus (re)opening, signals as a stop
request, and the listener's named counters."""

from __future__ import annotations

import os
import signal
import threading
from dataclasses import asdict, fields

import pytest
from sessionhelpers import make_cfg

from gyrostand.can.bus import ACK_REASONS, COMMANDS, STATE_CODES
from gyrostand.can.receive.counts import REASONS, Counts, DecodeStats, Rejections
from gyrostand.errors import OutputError
from gyrostand.session.commands import (
    END_OF_RUN,
    FAULT,
    IDLE,
    RUNNING,
    STATES,
    STOPPED,
    STOPPING,
    TRANSITIONS,
    Ack,
    CommandProtocol,
)
from gyrostand.session.live import Backoff, StopSignals
from gyrostand.session.pipeline import NullSink, Pipeline

CODE = {name: code for code, name in COMMANDS.items()}


def _cmd(name: str, seq: int, **extra: float) -> dict[str, float]:
    return {"Command": float(CODE[name]), "Sequence": float(seq), **extra}


def _protocol_in(state: str, calls: list[str]) -> CommandProtocol:
    """A protocol driven into ``state`` by commands (the table's own paths)."""
    p = CommandProtocol(1, 1000.0, start_idle=state == IDLE,
                        actions={"reset": lambda t: calls.append("reset"),
                                 "snapshot": lambda t: calls.append("snapshot")})
    if state == STOPPING:
        assert p.handle(0.0, _cmd("stop", 0)).ok
    assert p.state == state
    return p


def test_names_are_those_the_frames_carry():
    assert set(STATES) == set(STATE_CODES)
    assert {c for _, c in TRANSITIONS} == set(COMMANDS.values())
    assert set(TRANSITIONS.values()) | set(END_OF_RUN.values()) <= set(STATES)


@pytest.mark.parametrize("state", [IDLE, RUNNING, STOPPING])
@pytest.mark.parametrize("command", ["start", "stop", "reset", "snapshot"])
def test_every_command_in_every_state_follows_the_table(state, command):
    calls: list[str] = []
    p = _protocol_in(state, calls)
    ack = p.handle(1.0, _cmd(command, 7))
    assert (ack.command, ack.sequence) == (CODE[command], 7)
    nxt = TRANSITIONS.get((state, command))
    if nxt is None:
        assert (ack.ok, ack.reason, p.state) == (False, "wrong_state", state)
        assert calls == []
    else:
        assert (ack.ok, ack.reason, p.state) == (True, "ok", nxt)
        assert calls == ([command] if command in ("reset", "snapshot") else [])
    assert ack.reason in ACK_REASONS
    assert p.identifying == (p.state in (RUNNING, STOPPING))
    assert (p.stop_requested is not None) == (p.state == STOPPING)


def test_refusals_before_the_table_and_their_counts():
    p = CommandProtocol(3, 2.0)  # 2 commands/s, bursts of 2
    assert p.handle(0.0, _cmd("start", 1, Target=9.0)) is None  # another node's: no token
    assert p.handle(0.0, _cmd("reset", 2, Target=3.0)).ok  # this node's
    assert p.handle(0.5, {"Command": 9.0, "Sequence": 3.0}).reason == "unknown_command"
    assert p.handle(1.0, {"Command": 2.0}).reason == "malformed"  # no Sequence
    assert p.handle(1.0, _cmd("snapshot", 4)).ok  # the bucket's last token
    # no token left at the same frame time: refused (the refusals' own bucket holds 2),
    # then only counted
    assert [p.handle(1.0, _cmd("stop", 5 + i)) for i in range(3)] == [
        Ack(CODE["stop"], 5, False, "rate_limited"), Ack(CODE["stop"], 6, False,
                                                         "rate_limited"), None]
    assert p.state == RUNNING and p.stop_requested is None
    assert p.counts == {"received": 8, "acked": 2, "nacked": 4, "ignored": 1,
                        "malformed": 1, "unknown": 1, "rate_limited": 3,
                        "nacks_suppressed": 1}


def test_a_failing_action_is_not_acknowledged():
    def fail(t: float) -> None:
        raise OutputError("snapshot.json: cannot write: No space left on device")

    p = CommandProtocol(1, 10.0, actions={"snapshot": fail})
    with pytest.raises(OutputError, match="No space left"):
        p.handle(0.0, _cmd("snapshot", 1))
    assert (p.counts["received"], p.counts["acked"], p.counts["nacked"]) == (1, 0, 0)
    assert p.state == RUNNING


def test_the_end_of_run_follows_its_table():
    p = CommandProtocol(1, 10.0, start_idle=True)
    assert (p.end("end"), p.end("done")) == (STOPPING, STOPPED)
    with pytest.raises(ValueError, match="from state 'stopped'"):
        p.end("end")
    q = CommandProtocol(1, 10.0)
    assert (q.end("fail"), q.end("fail")) == (FAULT, FAULT)
    with pytest.raises(ValueError, match="'done' from state 'fault'"):
        q.end("done")


def test_the_constructor_writes_nothing_open_writes_the_run_files(tmp_path):
    cfg = make_cfg(tmp_path / "runs")
    run = tmp_path / "runs" / "r"
    pipe = Pipeline(cfg, run, NullSink(), source="test")
    assert not run.exists()
    with pytest.raises(OutputError, match="not open"):
        _ = pipe.samples
    run.mkdir(parents=True)
    with pipe as p:
        assert p is pipe
        names = sorted(str(f.relative_to(run)) for f in run.rglob("*") if f.is_file())
        assert names == ["az/estimates.csv", "az/samples.csv", "result.json"]
        assert (run / "az" / "samples.csv").read_text() == "t,drift,temp,n_drift,n_temp\n"
    assert pipe.files.closed  # a run left without finish() still closes its files


def test_backoff_doubles_up_to_the_cap_and_never_past_the_limit():
    b = Backoff(0.25, 1.0, 3.0, start=100.0)
    now, waits = 100.0, []
    while not b.expired(now):
        w = b.next_wait(now)
        waits.append(w)
        now += w
    assert waits == [0.25, 0.5, 1.0, 1.0, 0.25]  # 0.25+0.5+1+1 = 2.75: 0.25 s left
    assert now == 103.0


def test_a_signal_is_a_stop_request_and_the_old_handler_comes_back():
    before = signal.getsignal(signal.SIGTERM)
    ev = threading.Event()
    with StopSignals(ev) as stop:
        assert not stop.is_set()
        os.kill(os.getpid(), signal.SIGTERM)
        stop.wait(5.0)
        assert stop.is_set() and ev.is_set()  # the event set outside the handler
        assert stop.reason("none") == "SIGTERM"
    assert signal.getsignal(signal.SIGTERM) is before


def test_the_listener_counters_are_the_snapshot_fields():
    counted = {f.name for f in fields(Counts)}
    snap = {f.name for f in fields(DecodeStats)} - {"rejected", "clock_steps", "held"}
    assert counted == snap
    # the reasons' order is the JSON key order of stats.decoder.rejected
    assert REASONS == ("unknown_id", "wrong_dlc", "undecodable", "out_of_range",
                       "bad_timestamp", "non_monotonic", "time_jump", "error_frame",
                       "remote_frame", "overflow", "not_available", "invalid",
                       "second_source", "command_overflow")
    assert list(asdict(Rejections())) == list(REASONS)


def test_command_codes_are_named_by_the_given_table():
    """A DBC with other numbering: the protocol asks ``command_name``, not a fixed table."""
    p = CommandProtocol(1, 10.0, start_idle=True, command_name={7: "start"}.get)
    assert p.handle(0.0, {"Command": 1.0, "Sequence": 1.0}).reason == "unknown_command"
    ack = p.handle(0.5, {"Command": 7.0, "Sequence": 2.0})
    assert ack.ok and ack.command == 7 and p.state == RUNNING
