"""Frame timing (issue 11, item 1): a bad timestamp costs one frame, a clock step
re-anchors without losing or merging data, commands pass whatever their timestamps;
non-finite and absurd values of a signal without a DBC range (item 2); replay with a
small ``sampling.buffer`` never overflows (item 3).

Frames are the simulated stand's (jitter, 50 Hz drift, 10 Hz temperature); the property
tests draw where outliers and steps fall and how large they are (hypothesis)."""

from __future__ import annotations

import math
import struct

import can
import numpy as np
import pytest
from canhelpers import ROOT, make_ingest, smooth_truth
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gyrostand.can.bus import FrameEncoder
from gyrostand.can.framesim import FrameSimOptions, generate_frames
from gyrostand.can.receive.listener import DecodingListener
from gyrostand.can.routes import ChannelMap
from gyrostand.config import load_config, parse_config

CFG = load_config(ROOT / "configs" / "demo.yaml")
CMAP = ChannelMap.from_config(CFG)
OPTS = FrameSimOptions(drift_rate=50, temperature_rate=10, jitter=0.003, seed=11)
CLEAN = list(generate_frames(CFG.db, CMAP, [smooth_truth(120)], OPTS))
SETTINGS = settings(max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow,
                                           HealthCheck.function_scoped_fixture])


def _with_t(f: can.Message, t: float) -> can.Message:
    return can.Message(timestamp=t, arbitration_id=f.arbitration_id,
                       is_extended_id=f.is_extended_id, data=bytes(f.data))


def _run(frames, cfg=CFG):
    ing = make_ingest(cfg)
    out = []
    for i, f in enumerate(frames):
        ing.listener.on_message_received(f)
        if i % 97 == 0:
            out += ing.pump()
    out += ing.finish()
    return out, ing.listener.stats()


def _key(bins):
    return [(b.gyro, b.k, b.t, b.drift, b.temp, b.n_drift, b.n_temp) for b in bins]


CLEAN_BINS, CLEAN_STATS = _run(CLEAN)


# -- isolated outliers ------------------------------------------------------------------
@st.composite
def outliers(draw):
    """Indices of isolated frames (at least 2 good frames between two of them) and the
    wrong timestamp each gets: far ahead, far behind, or an absolute small value."""
    n = len(CLEAN)
    idx = sorted(set(draw(st.lists(st.integers(0, n - 1), min_size=1, max_size=8))))
    iso = []
    for i in idx:
        if i not in (1, 2) and (not iso or i - iso[-1] >= 3):
            iso.append(i)
    wrong = {}
    for i in iso:
        # the first frame has nothing to be compared with: a frame a little *behind* the
        # second is a pause before it as far as anyone can tell; far behind is not
        kind = draw(st.sampled_from(["ahead", "absolute"] if i == 0 else
                                    ["ahead", "behind", "absolute"]))
        if kind == "absolute":
            wrong[i] = draw(st.sampled_from([0.0, 1.0, 1e6]))
        else:
            d = draw(st.floats(5.0, 1e7))
            wrong[i] = CLEAN[i].timestamp + (d if kind == "ahead" else -d)
    return wrong


@SETTINGS
@given(outliers())
def test_an_isolated_outlier_costs_its_own_frame_only(wrong):
    frames = [(_with_t(f, wrong[i]) if i in wrong else f) for i, f in enumerate(CLEAN)]
    bins, stats = _run(frames)
    want, _ = _run([f for i, f in enumerate(CLEAN) if i not in wrong])
    assert _key(bins) == _key(want)
    assert stats.rejected["time_jump"] + stats.rejected["non_monotonic"] == len(wrong)
    assert stats.clock_steps == 0 and stats.held == 0
    assert stats.decoded == CLEAN_STATS.decoded - len(wrong)


def test_the_issue_cases_stray_first_frame_and_one_frame_3000_s_ahead():
    stray = _with_t(CLEAN[0], 1.0)  # a stray first frame before the real ones
    bins, st1 = _run([stray] + CLEAN)
    assert _key(bins) == _key(CLEAN_BINS) and st1.rejected_total == 1
    assert st1.decoded == CLEAN_STATS.decoded
    i = len(CLEAN) // 2
    ahead = CLEAN[:i] + [_with_t(CLEAN[i], CLEAN[i].timestamp + 3000.0)] + CLEAN[i + 1:]
    bins, st2 = _run(ahead)
    assert st2.rejected["time_jump"] == 1 and st2.decoded == CLEAN_STATS.decoded - 1
    assert len(bins) == len(CLEAN_BINS) and max(b.k for b in bins) < 130  # no gap bins


# -- clock steps --------------------------------------------------------------------------
@SETTINGS
@given(st.integers(40, len(CLEAN) - 40),
       st.one_of(st.floats(-1e7, -5.0), st.floats(3601.0, 1e7)))
def test_a_clock_step_reanchors_nothing_lost_sides_kept_apart(at, delta):
    frames = CLEAN[:at] + [_with_t(f, f.timestamp + delta) for f in CLEAN[at:]]
    ing = make_ingest(CFG)
    samples = []
    for f in frames:
        ing.listener.on_message_received(f)
        samples += ing.listener.drain()
    ing.listener.settle()
    samples += ing.listener.drain()
    s = ing.listener.stats()
    assert s.clock_steps == 1 and s.rejected_total == 0 and s.decoded == CLEAN_STATS.decoded
    # the samples before the step keep their times; after it they are shifted by a whole
    # number of bins, to start in a bin after the old side's last one
    n_old = sum(1 for f in CLEAN[:at])  # one sample per frame (one signal per message)
    old, new = samples[:n_old], samples[n_old:]
    assert [x[2] for x in old] == [f.timestamp for f in CLEAN[:at]]
    shift = {round(x[2] - f.timestamp, 6) for x, f in zip(new, frames[at:], strict=True)}
    assert len(shift) == 1
    (sh,) = shift
    assert float(sh).is_integer()
    assert math.floor(new[0][2]) > math.floor(max(x[2] for x in old))
    assert math.floor(new[0][2]) - math.floor(max(x[2] for x in old)) <= 3  # no invented gap
    bins = ing.binner.add_many(samples) + ing.binner.flush()
    ks = [b.k for b in bins]
    assert ks == list(range(ks[0], ks[0] + len(ks)))
    assert sum(b.n_drift + b.n_temp for b in bins) == len(samples)


def test_a_300_s_step_back_of_the_host_clock_keeps_every_bin():
    at = len(CLEAN) // 2
    frames = CLEAN[:at] + [_with_t(f, f.timestamp - 300.0) for f in CLEAN[at:]]
    bins, s = _run(frames)
    assert s.clock_steps == 1 and s.rejected_total == 0
    # every clean bin is there, the one split by the step in two parts (kept apart);
    # at most one empty bin between the two sides
    full = [b for b in CLEAN_BINS if b.n_drift and b.n_temp]
    assert sum(b.n_drift for b in bins) == sum(b.n_drift for b in CLEAN_BINS)
    assert len([b for b in bins if b.n_drift and b.n_temp]) >= len(full) - 1
    assert len(bins) <= len(CLEAN_BINS) + 2


def test_a_pause_within_max_gap_is_gap_bins():
    at = len(CLEAN) // 2
    frames = CLEAN[:at] + [_with_t(f, f.timestamp + 50.0) for f in CLEAN[at:]]
    bins, s = _run(frames)
    assert s.clock_steps == 0 and s.rejected_total == 0
    assert len(bins) == len(CLEAN_BINS) + 50
    assert sum(1 for b in bins if b.n_drift == 0 and b.n_temp == 0) >= 49


@SETTINGS
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 0.3))
def test_jitter_alone_never_holds_or_rejects(seed, width):
    jit = np.random.default_rng(seed).uniform(-width, width, len(CLEAN))
    frames = sorted((_with_t(f, f.timestamp + j) for f, j in zip(CLEAN, jit, strict=True)),
                    key=lambda f: f.timestamp)
    _, s = _run(frames)
    assert s.rejected_total == 0 and s.clock_steps == 0 and s.decoded == len(CLEAN)


# -- commands ---------------------------------------------------------------------------
def test_commands_pass_whatever_the_data_channel_thinks_of_their_time():
    ing = make_ingest(CFG)
    lst = ing.listener
    enc = FrameEncoder(CFG.db)
    ref = CFG.responses.command
    t0 = CLEAN[0].timestamp
    lst.on_message_received(_with_t(CLEAN[0], 1.0))  # a stray first frame
    for f in CLEAN[:50]:
        lst.on_message_received(f)
    times = [t0 + 1.0, 1.0, t0 + 3000.0, math.nan, t0 - 1e6]
    for i, t in enumerate(times):
        lst.on_message_received(enc.encode(ref.name, {"Command": 2, "Sequence": i,
                                                      "Target": 255}, timestamp=t))
    got = lst.pop_commands()
    assert [int(v["Sequence"]) for _, v in got] == list(range(len(times)))
    assert math.isfinite(got[3][0])  # a NaN timestamp becomes the frame time


def test_rate_limit_survives_a_wild_command_timestamp():
    from gyrostand.session.pipeline import TokenBucket

    b = TokenBucket(2.0)
    assert b.take(100.0) and b.take(100.0) and not b.take(100.0)
    assert b.take(1e9)  # a stray future timestamp (refills once) ...
    assert b.take(101.0) and not b.take(101.0)  # ... and does not block later seconds
    assert b.take(102.0) and b.take(102.5)


# -- values: non-finite and absurd floats of a signal without a DBC range -----------------
FLOAT_DBC = """VERSION ""

NS_ :

BS_:

BU_: STAND

BO_ 256 DRIFT_F: 8 STAND
 SG_ Drift : 0|32@1- (1,0) [0|0] "deg/h" Vector__XXX
 SG_ Counter : 32|8@1+ (1,0) [0|255] "" Vector__XXX

BO_ 257 TEMP_F: 4 STAND
 SG_ Temp : 0|32@1- (1,0) [0|0] "degC" Vector__XXX

SIG_VALTYPE_ 256 Drift : 1;
SIG_VALTYPE_ 257 Temp : 1;
"""


@pytest.fixture(scope="module")
def float_cfg(tmp_path_factory):
    d = tmp_path_factory.mktemp("floatdbc")
    (d / "f.dbc").write_text(FLOAT_DBC)
    return parse_config({
        "session": {"name": "f", "output": str(d / "runs")},
        "bus": {"interface": "virtual", "channel": "float-stand"}, "dbc": "f.dbc",
        "sampling": {"dt": 1.0},
        "gyros": [{"name": "g", "drift": {"message": "DRIFT_F", "signal": "Drift"},
                   "temperature": {"message": "TEMP_F", "signal": "Temp"},
                   "model": ["markov", "temp"], "identifiers": ["lsq"]}]},
        source="float.yaml", base_dir=d)


def _float_frame(fid: int, value: float, t: float) -> can.Message:
    data = struct.pack("<f", value) + (b"\0\0\0\0" if fid == 256 else b"")
    return can.Message(timestamp=t, arbitration_id=fid, is_extended_id=False, data=data)


@settings(max_examples=200, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.sampled_from([256, 257]),
                          st.one_of(st.floats(width=32, allow_nan=True),
                                    st.sampled_from([math.inf, -math.inf, math.nan,
                                                     3e38, -3e38, 1e13]))),
                min_size=1, max_size=60))
def test_non_finite_and_absurd_values_are_out_of_range(float_cfg, payloads):
    ing = make_ingest(float_cfg)
    t = 1_700_000_000.0
    for i, (fid, v) in enumerate(payloads):
        ing.listener.on_message_received(_float_frame(fid, v, t + 0.01 * i))
    ing.listener.settle()
    samples = ing.listener.drain()
    s = ing.listener.stats()
    v32 = [struct.unpack("<f", struct.pack("<f", v))[0] for _, v in payloads]
    bad = sum(1 for v in v32 if not (math.isfinite(v) and abs(v) <= 1e12))
    assert s.rejected["out_of_range"] == bad
    assert len(samples) == len(payloads) - bad
    assert all(math.isfinite(x[3]) and abs(x[3]) <= 1e12 for x in samples)


# -- replay back-pressure ------------------------------------------------------------------
def test_replay_with_a_tiny_buffer_drops_nothing():
    from gyrostand.can.binning import Binner
    from gyrostand.can.ingest import Ingest
    from gyrostand.can.replay import replay

    def run(buffer):
        lst = DecodingListener(CFG.db, CMAP, capacity=buffer, max_gap=3600.0)
        ing = Ingest(lst, Binner(CMAP.gyros, 1.0))
        bins = [b for batch in replay(iter(CLEAN), ing, parallel=False) for b in batch]
        return bins, lst.stats()

    small, s_small = run(16)
    big, _ = run(65536)
    assert s_small.rejected["overflow"] == 0
    assert _key(small) == _key(big) == _key(CLEAN_BINS)

