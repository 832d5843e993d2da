"""Property-based fuzzing of the receive path (issue 5, item 1).

Arbitrary frames — ids (ours, other DBC messages, unknown, standard and extended), DLCs,
payloads (random bytes or valid DBC encodings), flags (error, remote, FD) and timestamps
(forward, equal, backwards, huge jumps, NaN, ±inf) — go through the real
:class:`DecodingListener` and :class:`Binner`. Whatever arrives:

* nothing escapes the listener and nothing inside it fails (``listener_errors == 0``);
* every frame is accounted for: received = decoded + ignored + rejected (by reason);
* every decoded sample ends in exactly one bin or is counted late / refused as a jump;
* each gyro's 1-s series is contiguous and monotonic (k = 0, 1, 2, ...), means lie in the
  DBC's range and an empty channel is NaN, never invented.
"""

import math
from pathlib import Path

import can
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gyrostand.can.binning import Binner
from gyrostand.can.receive.listener import DecodingListener
from gyrostand.can.routes import ChannelMap
from gyrostand.config import load_config

ROOT = Path(__file__).resolve().parents[2]
CFG = load_config(ROOT / "configs" / "three-gyros.yaml")
CMAP = ChannelMap.from_config(CFG)
DB = CFG.db
MAPPED = [(s.message.frame_id, DB.get_message_by_name(s.message.name))
          for pair in CMAP.signals for s in pair]
OTHERS = [(m.frame_id, m) for m in DB.messages]
#: examples and frames tried, counted for benchmarks/fuzz_counts.py (which prints them)
EXAMPLES = {"n": 0, "frames": 0}


def valid_payload(message, draw):
    """A payload cantools encodes from in-range values (reaches the deep checks)."""
    values = {}
    for sig in message.signals:
        lo = sig.minimum if sig.minimum is not None else 0
        hi = sig.maximum if sig.maximum is not None else 0
        values[sig.name] = draw(st.floats(min_value=float(lo), max_value=float(hi),
                                          allow_nan=False))
    if message.is_multiplexed():
        for sig in message.signals:
            if sig.is_multiplexer:
                values[sig.name] = draw(st.sampled_from(
                    sorted({v for s in message.signals for v in (s.multiplexer_ids or [0])})))
    try:
        return bytes(message.encode(values, strict=False, padding=True))
    except Exception:  # a combination cantools will not encode: random bytes instead
        return bytes(draw(st.binary(min_size=message.length, max_size=message.length)))


@st.composite
def frames(draw):
    out = []
    t = 1_700_000_000.0
    for _ in range(draw(st.integers(1, 120))):
        kind = draw(st.sampled_from(["mapped", "mapped", "mapped", "other", "random"]))
        if kind == "random":
            ext = draw(st.booleans())
            fid = draw(st.integers(0, 0x1FFFFFFF if ext else 0x7FF))
            data = draw(st.binary(max_size=8))
        else:
            fid, message = draw(st.sampled_from(MAPPED if kind == "mapped" else OTHERS))
            ext = bool(message.is_extended_frame)
            if draw(st.integers(0, 9)) == 0:
                data = draw(st.binary(max_size=64))  # wrong length / garbage
            else:
                data = valid_payload(message, draw)
        step = draw(st.sampled_from(["small", "small", "small", "zero", "back", "jump",
                                     "nan", "inf"]))
        if step == "small":
            t += draw(st.floats(0.0, 0.7))
        elif step == "back":
            t -= draw(st.floats(0.0, 5.0))
        elif step == "jump":
            t += draw(st.sampled_from([100.0, 5000.0, 1e7]))
        ts = {"nan": math.nan, "inf": math.inf}.get(step, t)
        flags = draw(st.sampled_from(["", "", "", "", "error", "remote", "fd"]))
        try:
            msg = can.Message(timestamp=ts, arbitration_id=fid, is_extended_id=ext,
                              data=data if flags != "remote" else None,
                              dlc=len(data) if flags != "remote" else draw(st.integers(0, 8)),
                              is_error_frame=flags == "error", is_remote_frame=flags == "remote",
                              is_fd=flags == "fd" or len(data) > 8, check=False)
        except Exception:  # python-can refuses this combination itself: not a frame
            continue
        out.append(msg)
    return out


def bounds(sig):
    return (sig.minimum if sig.minimum is not None else -np.inf,
            sig.maximum if sig.maximum is not None else np.inf)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(frames())
def test_nothing_escapes_and_every_frame_is_accounted_for(msgs):
    check(msgs)


@pytest.mark.slow
@settings(max_examples=5000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(frames())
def test_fuzz_long(msgs):
    check(msgs)


def check(msgs):
    listener = DecodingListener(DB, CMAP, capacity=200, max_gap=3600.0)
    binner = Binner(CMAP.gyros, dt=1.0, max_gap=3600.0)
    bins = []
    n_samples = 0
    for i, msg in enumerate(msgs):
        listener.on_message_received(msg)
        if i % 17 == 0:
            drained = listener.drain()
            n_samples += len(drained)
            bins += binner.add_many(drained)
    drained = listener.drain()
    n_samples += len(drained)
    bins += binner.add_many(drained)
    s = listener.stats()
    EXAMPLES["n"] += 1
    EXAMPLES["frames"] += len(msgs)
    assert s.listener_errors == 0
    assert s.received == len(msgs)
    assert s.received == s.decoded + s.ignored + s.rejected_total + s.held, s
    listener.settle()  # end of the frames: what is held is accepted or rejected
    drained = listener.drain()
    n_samples += len(drained)
    bins += binner.add_many(drained)
    s = listener.stats()
    assert s.held == 0 and s.received == s.decoded + s.ignored + s.rejected_total, s
    bins += binner.flush()
    assert s.samples == n_samples
    b = binner.stats()
    assert sum(x.n_drift + x.n_temp for x in bins) + b.late + b.jumps == n_samples
    for g, name in enumerate(CMAP.gyros):
        series = [x for x in bins if x.gyro == name]
        ks = [x.k for x in series]
        if ks:
            assert ks == list(range(ks[0], ks[0] + len(ks))), "1-s series not contiguous"
        lo_d, hi_d = bounds(CMAP.signals[g][0])
        lo_t, hi_t = bounds(CMAP.signals[g][1])
        for x in series:
            assert x.t == binner.t0 + x.k * binner.dt
            assert (x.n_drift == 0) == np.isnan(x.drift)
            assert (x.n_temp == 0) == np.isnan(x.temp)
            if x.n_drift:
                assert lo_d - 1e-9 <= x.drift <= hi_d + 1e-9
            if x.n_temp:
                assert lo_t - 1e-9 <= x.temp <= hi_t + 1e-9


def test_fuzz_counts_for_the_note():
    """Runs after the property test in this module: how much was tried (printed with -s)."""
    print(f"\nfuzz: {EXAMPLES['n']} examples, {EXAMPLES['frames']} frames")
