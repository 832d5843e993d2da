"""Run modes of the live daemon: --duration (frame time) and --idle + a start command."""

from __future__ import annotations

import threading

from sessionhelpers import decode, make_cfg

from gyrostand.can.bus import FrameEncoder
from gyrostand.session.live import run_live
from gyrostand.session.offline import simulated_frames
from gyrostand.session.stand import SimulatedStand


def _run(cfg, frames, **kw):
    ready, stop = threading.Event(), threading.Event()
    stand = SimulatedStand(cfg, frames, ready, stop, send_stop=kw.pop("send_stop", True),
                           window=10**9)
    stand.start()
    outcome = run_live(cfg, on_ready=lambda _d: ready.set(), stop_event=stop,
                       handle_signals=False, **kw)
    stand.join(10)
    assert stand.error is None
    return outcome, stand


def test_duration_counts_frame_time(tmp_path):
    cfg = make_cfg(tmp_path, duration=200.0, rate=10.0)
    frames = list(simulated_frames(cfg))
    outcome, _ = _run(cfg, frames, duration=50.0, send_stop=False)
    assert outcome.ok and outcome.stop_reason == "duration 50 s of frame time"
    # frames already received when the duration passed are binned and recorded alike
    st = outcome.stats
    assert st["binner"]["bins"] >= 51 and st["recorder"]["frames"] == st["decoder"]["received"]


def test_idle_until_a_start_command(tmp_path):
    cfg = make_cfg(tmp_path, duration=100.0, rate=10.0)
    frames = list(simulated_frames(cfg))
    half = next(i for i, f in enumerate(frames) if f.timestamp - frames[0].timestamp >= 50.0)
    start = FrameEncoder(cfg.db).command_frame(cfg.responses.command, "start", 9, 1,
                                               timestamp=frames[half - 1].timestamp)
    outcome, stand = _run(cfg, frames[:half] + [start] + frames[half:], start_idle=True)
    assert outcome.stop_reason == "stop command"
    rows = (outcome.run_dir / "az" / "estimates.csv").read_text().splitlines()[1:]
    assert len(rows) == 101
    lsq_status = [r.rsplit(",", 1)[1] for r in rows]
    assert set(lsq_status[:45]) == {"insufficient_data"}  # idle: nothing identified
    assert lsq_status[-1] in ("ok", "warning")            # identifying after start
    acks = {a["Sequence"]: a["Result"] for a in decode(cfg, stand.received, "GS_ACK")}
    assert acks == {9: 0, 1: 0}
