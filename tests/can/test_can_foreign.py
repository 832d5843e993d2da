"""A foreign DBC end to end: extended ids, Motorola signals with scale and offset, and one
gyro's drift and temperature multiplexed in one frame. Nothing may assume our layout."""

from __future__ import annotations

import numpy as np
from canhelpers import make_ingest, smooth_truth

from gyrostand.can.bus import FrameEncoder
from gyrostand.can.framesim import BadFrameInjector, FrameSimOptions, generate_frames
from gyrostand.can.routes import ChannelMap


def test_foreign_dbc_live_end_to_end(foreign_cfg, rig_factory):
    cm = ChannelMap.from_config(foreign_cfg)
    n = 30
    truths = [smooth_truth(n, 0), smooth_truth(n, 1)]
    opts = FrameSimOptions(drift_rate=100, temperature_rate=20, jitter=0.001, seed=11)
    frames = list(generate_frames(foreign_cfg.db, cm, truths, opts))
    # gyro x's two streams share the extended id 0x18FF5001, told apart by MuxSel
    ids = {(f.arbitration_id, f.is_extended_id) for f in frames}
    assert ids == {(0x18FF5001, True), (0x18FF5102, True), (0x321, False)}
    enc = FrameEncoder(foreign_cfg.db)
    diag = enc.encode("IMU_X_MUX", {"MuxSel": 3, "Diag": 7}, timestamp=frames[5].timestamp)
    frames.insert(6, diag)  # a multiplexer value that maps to no channel: ignored

    ingest = make_ingest(foreign_cfg)
    rig = rig_factory([ingest.listener])
    rig.wait(ingest.listener, rig.send_all(frames))
    bins = ingest.finish()
    st = ingest.listener.stats()
    assert st.rejected_total == 0 and st.ignored == 1 and st.counter_jumps == 0
    # half the resolution (DBC scale) of each signal: the encoder rounds to the grid
    tol = {("x", 0): 0.5e-4, ("x", 1): 0.5e-2, ("y", 0): 0.5e-6, ("y", 1): 0.25e-1}
    for g, truth in zip(("x", "y"), truths, strict=True):
        series = [b for b in bins if b.gyro == g]
        assert [b.k for b in series] == list(range(n))
        assert all((b.n_drift, b.n_temp) == (100, 20) for b in series)
        drift = np.array([b.drift for b in series])
        temp = np.array([b.temp for b in series])
        assert np.max(np.abs(drift - truth.drift)) <= tol[(g, 0)] + 1e-9
        assert np.max(np.abs(temp - truth.temp)) <= tol[(g, 1)] + 1e-9


def test_foreign_bad_multiplexer_is_undecodable(foreign_cfg):
    cm = ChannelMap.from_config(foreign_cfg)
    frames = generate_frames(foreign_cfg.db, cm, [smooth_truth(5, 0), smooth_truth(5, 1)],
                             FrameSimOptions(drift_rate=20, temperature_rate=10))
    inj = BadFrameInjector(foreign_cfg.db, cm, every=3, kinds=("bad_mux", "out_of_range"))
    ingest = make_ingest(foreign_cfg)
    for f in inj(frames):
        ingest.listener.on_message_received(f)
    st = ingest.listener.stats()
    assert inj.expected["undecodable"] > 0 and inj.expected["out_of_range"] > 0
    assert {k: v for k, v in st.rejected.items() if v} == dict(inj.expected)
    bins = ingest.finish()
    assert all(b.n_drift == 20 and b.n_temp == 10 for b in bins) and len(bins) == 10
