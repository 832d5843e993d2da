"""Commands (issue 5, item 5): honoured only from the configured id, rate-limited
(``responses.command_rate``), malformed and unknown ones counted and nacked.

1. ``gyrostand run`` as a process over python-can-remote, driven command by command from
   another client: look-alikes on other ids are not honoured, a wrong-DLC command is
   nacked ``malformed`` (echoing what can be read), an unknown code ``unknown_command``,
   another node's command is ignored, a flood is cut to the configured rate
   (``rate_limited`` nacks, themselves limited), then a stop is still honoured.
2. Property-based (hypothesis): arbitrary payloads, lengths, targets and timestamps on
   the command id through the real listener and pipeline: every command is answered
   exactly once (ack, nack with a reason, ignored, or a counted suppressed nack), never
   more than ``command_rate`` per second of frame time are executed, nothing raises.
"""

from __future__ import annotations

import json
import math
import time

import can
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gyrostand.can.bus import ACK_REASONS, FrameEncoder
from gyrostand.config import load_config
from gyrostand.session.pipeline import NullSink, Pipeline

from .procs import Daemon, Observer, RemoteServer, write_config

pytest.importorskip("can_remote")

T = 1_700_000_000.0
RATE = 5
REASON = {v: k for k, v in ACK_REASONS.items()}
#: examples and command frames tried, counted for benchmarks/fuzz_counts.py (which
#: prints them)
COUNTS = {"examples": 0, "command_frames": 0}


def _acks(cfg, frames):
    msg = cfg.db.get_message_by_name("GS_ACK")
    return [dict(msg.decode(f.data, decode_choices=False)) for f in frames
            if f.arbitration_id == msg.frame_id and not f.is_extended_id]


def _cmd(enc, cfg, name, seq, t, target=255):
    return enc.command_frame(cfg.responses.command, name, seq, target, timestamp=t)


def test_commands_over_remote_id_rate_malformed_unknown(tmp_path):
    srv = RemoteServer().start()
    cfg_path = write_config(tmp_path / "cmd.yaml", tmp_path / "runs",
                            {"interface": "remote", "channel": srv.url,
                             "preserve_timestamps": True},
                            responses={"command_rate": RATE})
    cfg = load_config(cfg_path)
    enc = FrameEncoder(cfg.db)
    daemon = Daemon(cfg_path, "--out", str(tmp_path / "runs"))
    obs = stand = None
    try:
        run_dir = daemon.run_dir(daemon.wait_for("ready: "))
        obs = Observer(srv.url)
        stand = can.Bus(interface="remote", channel=srv.url, preserve_timestamps=True)

        def exchange(frames, n_acks, wait=3.0):
            """Send frames, return the acks that follow (until n_acks or a quiet wait)."""
            start = len(obs.frames)
            mine = {(f.arbitration_id, bytes(f.data)) for f in frames}

            def acks():  # the daemon's, not our own frames echoed by the bus
                return _acks(cfg, [f for f in obs.frames[start:]
                                   if (f.arbitration_id, bytes(f.data)) not in mine])

            for f in frames:
                stand.send(f)
            deadline = time.monotonic() + wait
            while time.monotonic() < deadline:
                if n_acks and len(acks()) >= n_acks:
                    time.sleep(0.2)  # and nothing more
                    break
                time.sleep(0.02)
            return acks()

        stop = _cmd(enc, cfg, "stop", 1, T)
        # 1. a stop-looking payload on other ids: GS_ACK's id, an unknown id, and the
        #    command id as an extended frame: none is a command
        fakes = [can.Message(arbitration_id=i, is_extended_id=x, data=stop.data,
                             timestamp=T + 0.1 * k)
                 for k, (i, x) in enumerate([(0x0F1, False), (0x0F2, False), (0x0F0, True)])]
        assert exchange(fakes, 0, wait=1.0) == []
        # 2. wrong DLC on the command id: nack malformed, Command/Sequence echoed
        short = can.Message(arbitration_id=0x0F0, is_extended_id=False, data=stop.data[:2],
                            timestamp=T + 1)
        assert exchange([short], 1) == [{"Command": 2, "Sequence": 1, "Result": 1,
                                         "Reason": ACK_REASONS["malformed"], "Node": 1}]
        # 3. unknown code; 4. another node's command: ignored
        cmd = cfg.db.get_message_by_name("GS_COMMAND")  # code 9: outside the DBC range
        unknown = can.Message(arbitration_id=cmd.frame_id, is_extended_id=False,
                              data=cmd.encode({"Command": 9, "Sequence": 2, "Target": 1},
                                              strict=False), timestamp=T + 2)
        assert [a["Reason"] for a in exchange([unknown], 1)] == \
            [ACK_REASONS["unknown_command"]]
        assert exchange([_cmd(enc, cfg, "reset", 3, T + 3, target=7)], 0, wait=1.0) == []
        # 5. a flood of 50 resets within 5 ms of frame time: RATE executed, RATE nacked
        #    rate_limited, the rest only counted
        flood = [_cmd(enc, cfg, "reset", 10 + i, T + 5 + 1e-4 * i) for i in range(50)]
        got = exchange(flood, 2 * RATE)
        assert [(a["Sequence"], a["Result"]) for a in got if a["Result"] == 0] == \
            [(10 + i, 0) for i in range(RATE)]
        assert [REASON[a["Reason"]] for a in got if a["Result"] == 1] == \
            ["rate_limited"] * RATE
        # 6. a second later the bucket has refilled: the stop is honoured
        got = exchange([_cmd(enc, cfg, "stop", 99, T + 7)], 1)
        assert got == [{"Command": 2, "Sequence": 99, "Result": 0, "Reason": 0, "Node": 1}]
        rc, err = daemon.finish()
    finally:
        daemon.close()
        for b in (obs, ):
            if b is not None:
                b.close()
        if stand is not None:
            stand.shutdown()
        srv.stop()
    assert rc == 0, err
    doc = json.loads((run_dir / "result.json").read_text())
    assert doc["stats"]["stop_reason"] == "stop command"
    assert doc["stats"]["commands"] == {
        "received": 1 + 1 + 1 + 50 + 1, "acked": RATE + 1, "nacked": 2 + RATE,
        "ignored": 1, "malformed": 1, "unknown": 1, "rate_limited": 50 - RATE,
        "nacks_suppressed": 50 - 2 * RATE}
    rej = doc["stats"]["decoder"]["rejected"]
    assert rej["unknown_id"] == 2 and rej["wrong_dlc"] == 1
    assert doc["stats"]["decoder"]["ignored"] == 1  # GS_ACK's id: a known, unmapped message
    log = (run_dir / "run.log").read_text()
    assert "malformed command" in log and "commands over responses.command_rate" in log


# -- property: every command frame is answered once, the rate holds -----------------------

CFG = None


def _cfg(tmp_dir):
    global CFG
    if CFG is None:
        CFG = load_config(write_config(tmp_dir / "prop.yaml", tmp_dir / "runs",
                                       {"interface": "virtual", "channel": "unused"},
                                       responses={"command_rate": 3}))
    return CFG


class _Sink(NullSink):
    def __init__(self) -> None:
        super().__init__()
        self.frames: list[can.Message] = []

    def send(self, frames) -> None:
        super().send(frames)
        self.frames += list(frames)


frame_st = st.tuples(
    st.sampled_from([0, 1, 2, 3, 4, 5, 7, 8, 9, 12]),        # DLC (the DBC says 8)
    st.binary(min_size=12, max_size=12),                      # bytes to take them from
    st.sampled_from([1, 2, 3, 4, 9, 0, 255]),                 # Command (when DLC >= 1)
    st.sampled_from([255, 1, 7]),                             # Target (when DLC >= 3)
    st.floats(0.0, 0.6),                                      # frame-time step, s
)


@settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.lists(frame_st, min_size=1, max_size=60))
def test_every_command_frame_is_answered_once_and_the_rate_holds(tmp_path_factory, spec):
    cfg = _cfg(tmp_path_factory.mktemp("prop") if CFG is None else None)
    sink = _Sink()
    run_dir = tmp_path_factory.mktemp("run")
    pipe = Pipeline(cfg, run_dir, sink, source="test").open()
    t = T
    executed: list[float] = []
    for dlc, raw, code, target, dt in spec:
        t += dt
        data = bytearray(raw[:dlc])
        if dlc >= 1:
            data[0] = code
        if dlc >= 3:
            data[2] = target
        pipe.listener.on_message_received(
            can.Message(arbitration_id=0x0F0, is_extended_id=False, data=bytes(data),
                        timestamp=t))
        before = dict(pipe.commands)
        pipe.step([])
        after = pipe.commands
        if after["received"] > before["received"] and after["ignored"] == before["ignored"] \
                and after["rate_limited"] == before["rate_limited"]:
            executed.append(t)  # handled: acked or nacked for what it is
        COUNTS["command_frames"] += 1
    pipe.samples.close()
    for w in pipe.estimates.values():
        w.close()
    c = pipe.commands
    assert pipe.listener.stats().listener_errors == 0
    assert c["received"] == len(spec)
    answered = c["acked"] + c["nacked"] + c["ignored"] + c["nacks_suppressed"]
    assert answered == c["received"]
    acks = _acks(cfg, sink.frames)
    assert len(acks) == c["acked"] + c["nacked"]
    assert sum(a["Reason"] == ACK_REASONS["malformed"] for a in acks) == c["malformed"]
    assert sum(a["Reason"] == ACK_REASONS["unknown_command"] for a in acks) == c["unknown"]
    # token bucket: in any 1-s window at most capacity + rate * 1 s commands handled
    rate = cfg.responses.command_rate
    for i, a in enumerate(executed):
        n = sum(1 for b in executed[i:] if b - a <= 1.0)
        assert n <= max(1.0, rate) + rate * 1.0 + 1e-9
    assert all(math.isfinite(x) for x in executed)
    COUNTS["examples"] += 1

