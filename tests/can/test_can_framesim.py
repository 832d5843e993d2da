"""The frame simulator: rates, ordering, jitter bounds, drops, quantization, determinism."""

from __future__ import annotations

import numpy as np
import pytest
from canhelpers import make_ingest, smooth_truth

from gyrostand.can.framesim import FrameSimOptions, Truth, generate_frames, send_frames
from gyrostand.can.replay import replay
from gyrostand.can.routes import ChannelMap

T0 = 1_700_000_000.0


def _run(cfg, truths, **kw):
    cm = ChannelMap.from_config(cfg)
    frames = list(generate_frames(cfg.db, cm, truths, FrameSimOptions(**kw)))
    ingest = make_ingest(cfg)
    bins = [b for batch in replay(frames, ingest) for b in batch]
    return frames, bins, ingest


def test_rates_order_and_hold_means(demo_cfg):
    truth = smooth_truth(10)
    frames, bins, ingest = _run(demo_cfg, [truth], drift_rate=1000, temperature_rate=10,
                                jitter=0.0004, seed=1)
    ts = np.array([f.timestamp for f in frames])
    assert np.all(np.diff(ts) >= 0)  # merged in timestamp order
    assert len(frames) == 10 * (1000 + 10)
    assert ts.min() >= T0 and ts.max() < T0 + 10
    # held truth: every bin mean is the truth point rounded to the DBC resolution
    assert [b.n_drift for b in bins] == [1000] * 10
    assert np.max(np.abs(np.array([b.drift for b in bins]) - truth.drift)) <= 0.5e-5 + 1e-12
    assert np.max(np.abs(np.array([b.temp for b in bins]) - truth.temp)) <= 0.005 + 1e-12
    assert ingest.listener.stats().counter_jumps == 0


def test_linear_interpolation_quantization_and_drops(demo_cfg):
    t = np.arange(20.0)
    truth = Truth(t, 0.01 * t, 20 + 0.1 * t)  # linear: a bin's mean is its centre value
    frames, bins, ingest = _run(demo_cfg, [truth], drift_rate=100, temperature_rate=10,
                                interpolation="linear", drift_quantization=0.001,
                                drop=0.1, seed=2)
    dm = demo_cfg.db.get_message_by_name("GYRO_DRIFT_1")
    vals = [dm.decode(f.data)["Drift"] for f in frames if f.arbitration_id == dm.frame_id]
    assert np.allclose(np.round(np.array(vals) / 0.001) * 0.001, vals, atol=1e-9)
    n = sum(b.n_drift for b in bins)
    assert 0.85 * 2000 < n < 0.95 * 2000  # ~10 % dropped
    assert ingest.listener.stats().counter_jumps > 50  # the counter shows the losses
    inner = bins[:-1]
    centre = 0.01 * (np.array([b.k for b in inner]) + 0.5)
    assert np.max(np.abs(np.array([b.drift for b in inner]) - centre)) < 0.002


def test_seeded_and_validated(demo_cfg):
    cm = ChannelMap.from_config(demo_cfg)
    tr = [smooth_truth(5)]
    opts = FrameSimOptions(jitter=0.001, drop=0.05, seed=9)
    a = [(f.timestamp, bytes(f.data)) for f in generate_frames(demo_cfg.db, cm, tr, opts)]
    b = [(f.timestamp, bytes(f.data)) for f in generate_frames(demo_cfg.db, cm, tr, opts)]
    assert a == b
    with pytest.raises(ValueError, match="jitter"):
        FrameSimOptions(drift_rate=1000, jitter=0.001)
    with pytest.raises(ValueError, match="truths"):
        list(generate_frames(demo_cfg.db, cm, tr * 2, opts))
    assert FrameSimOptions.from_config(demo_cfg.simulate).seed == 42


def test_send_frames_on_virtual_bus(demo_cfg, rig_factory):
    ingest = make_ingest(demo_cfg)
    rig = rig_factory([ingest.listener])
    cm = ChannelMap.from_config(demo_cfg)
    n = send_frames(rig.tx, generate_frames(demo_cfg.db, cm, [smooth_truth(3)],
                                            FrameSimOptions(drift_rate=20)))
    rig.wait(ingest.listener, n)
    assert [b.n_drift for b in ingest.finish()] == [20, 20, 20]
