"""Record every raw frame live, replay the log through the same path: identical bins.
The BLF on disk is readable up to the last flush while the recorder is still open."""

from __future__ import annotations

import math

import can
import pytest
from canhelpers import make_ingest, smooth_truth

from gyrostand.can.bus import FrameEncoder
from gyrostand.can.framesim import (
    BAD_KINDS,
    BadFrameInjector,
    FrameSimOptions,
    generate_frames,
    write_log,
)
from gyrostand.can.logs.read import LogDamage
from gyrostand.can.recorder import Recorder
from gyrostand.can.replay import FILE_PUMP, PUMP, paced, read_log, replay
from gyrostand.can.routes import ChannelMap
from gyrostand.errors import CanEdgeError
from gyrostand.runfolder import SamplesWriter, read_samples_csv

T0 = 1_700_000_000.0


def _key(bins):
    return [(b.gyro, b.k, b.t, None if math.isnan(b.drift) else b.drift,
             None if math.isnan(b.temp) else b.temp, b.n_drift, b.n_temp) for b in bins]


def _sim(cfg, n=40, **kw):
    cm = ChannelMap.from_config(cfg)
    opts = FrameSimOptions(**{"drift_rate": 50, "temperature_rate": 10, "jitter": 0.002,
                              "drop": 0.02, "seed": 5, **kw})
    truths = [smooth_truth(n, k) for k in range(len(cm.gyros))]
    kinds = [k for k in BAD_KINDS if k != "bad_timestamp"]  # no log format stores NaN time
    inj = BadFrameInjector(cfg.db, cm, every=13, kinds=kinds)
    return list(inj(generate_frames(cfg.db, cm, truths, opts)))


def test_blf_record_then_replay_gives_identical_bins(triad_cfg, rig_factory, tmp_path):
    frames = _sim(triad_cfg)
    live = make_ingest(triad_cfg)
    rec = Recorder(tmp_path / "raw.blf")
    rig = rig_factory([live.listener, rec])
    rig.wait(live.listener, rig.send_all(frames))
    live_bins = live.finish()
    rec.stop()
    assert rec.frames == len(frames) and rec.errors == 0

    replayed = make_ingest(triad_cfg)
    bins = [b for batch in replay(tmp_path / "raw.blf", replayed, pump_every=100) for b in batch]
    assert _key(bins) == _key(live_bins)
    assert replayed.listener.stats() == live.listener.stats()
    assert any(b.is_gap for b in bins) or live.listener.stats().rejected_total > 0

    # and the samples.csv of both paths are byte-identical
    for name, got in (("live", live_bins), ("replay", bins)):
        with SamplesWriter(tmp_path / name, [g.name for g in triad_cfg.gyros]) as w:
            w.write(got)
    for g in ("x", "y", "z"):
        a = (tmp_path / "live" / g / "samples.csv").read_bytes()
        assert a == (tmp_path / "replay" / g / "samples.csv").read_bytes()
        cols = read_samples_csv(tmp_path / "live" / g / "samples.csv")
        ref = [b for b in live_bins if b.gyro == g]
        assert cols["t"] == [b.t for b in ref]
        assert cols["n_drift"] == [b.n_drift for b in ref]
        assert [x for x in cols["drift"] if not math.isnan(x)] == \
            [b.drift for b in ref if not math.isnan(b.drift)]


@pytest.mark.parametrize("suffix", [".asc", ".log", ".csv", ".blf"])
def test_every_log_format_replays_to_the_same_bins(demo_cfg, tmp_path, suffix):
    # python-can 4.6's ASC writer prints the trigger-block time's milliseconds without
    # zero padding (12 ms is read back as 120 ms): start where the first frame's ms field
    # has three digits, so ASC keeps absolute time to within 1 ms like the other formats
    frames = _sim(demo_cfg, n=20, start=T0 + 0.25)
    direct = make_ingest(demo_cfg)
    ref = [b for batch in replay(frames, direct) for b in batch]
    path = tmp_path / f"sim{suffix}"
    assert write_log(path, frames) == len(frames)
    got = [b for batch in replay(path, make_ingest(demo_cfg)) for b in batch]
    assert _key(got) == _key(ref)


def test_blf_readable_up_to_last_flush(demo_cfg, tmp_path):
    enc = FrameEncoder(demo_cfg.db)
    path = tmp_path / "live.blf"
    rec = Recorder(path, flush_interval=1.0)

    def frame(i, t):
        return enc.encode("GYRO_DRIFT_1", {"Drift": i * 0.5, "Counter": i % 256},
                          timestamp=T0 + t)

    for i in range(50):  # 0.00 .. 0.49 s of frame time: no automatic flush yet
        rec.on_message_received(frame(i, i * 0.01))
    assert rec.flushes == 0
    rec.flush()  # what the daemon's 1-Hz tick does
    for i in range(50, 60):  # still < 1 s after the first frame: buffered only
        rec.on_message_received(frame(i, i * 0.01))
    on_disk = list(can.LogReader(path))
    assert len(on_disk) == 50
    assert [m.timestamp for m in on_disk] == pytest.approx([T0 + i * 0.01 for i in range(50)],
                                                           abs=1e-6)
    assert [bytes(m.data) for m in on_disk] == [bytes(frame(i, 0).data) for i in range(50)]
    rec.on_message_received(frame(60, 1.5))  # 1.5 s after the last flush: flushes itself
    assert rec.flushes == 2 and len(list(can.LogReader(path))) == 61
    rec.on_message_received(frame(61, math.nan))  # unstorable: counted, file unharmed
    rec.stop()
    assert rec.unrecordable == 1 and rec.errors == 0
    assert len(list(can.LogReader(path))) == 61


def test_replay_errors_and_pacing(tmp_path):
    with pytest.raises(CanEdgeError, match=r"nothing\.blf: log file not found"):
        list(read_log(tmp_path / "nothing.blf"))
    bad = tmp_path / "bad.blf"
    bad.write_bytes(b"not a blf at all" * 20)
    with pytest.raises(CanEdgeError, match=r"bad\.blf"):
        list(read_log(bad))
    # pacing follows frame time through injected clock/sleep: no wall clock in the data
    now = [100.0]
    slept = []

    def sleep(s):
        slept.append(s)
        now[0] += s

    msgs = [can.Message(timestamp=T0 + t) for t in (0.0, 0.5, 2.0)]
    out = list(paced(msgs, speed=2.0, clock=lambda: now[0], sleep=sleep))
    assert out == msgs and slept == pytest.approx([0.25, 0.75])


# -- the reader process (replay of large logs parses them beside the decoding) -----------

def _batches(source, ingest, **kw):
    return [_key(batch) for batch in replay(source, ingest, pump_every=100, **kw)]


def test_reader_process_replay_equals_the_in_process_replay(triad_cfg, tmp_path):
    frames = _sim(triad_cfg, n=30)  # bad frames of every kind mixed in
    a, b = tmp_path / "a.blf", tmp_path / "b.blf"
    write_log(a, frames[:1500])
    write_log(b, frames[1500:])
    serial, parallel = make_ingest(triad_cfg), make_ingest(triad_cfg)
    want = _batches([a, b], serial, parallel=False)
    got = _batches([a, b], parallel, parallel=True)
    assert got == want  # the same bins, closed in the same batches
    assert parallel.listener.stats() == serial.listener.stats()
    st = serial.listener.stats()
    assert st.received == len(frames) and st.rejected_total > 50 and st.counter_jumps > 0
    assert sum(len(x) for x in want) > 3 * 25


def test_a_log_file_is_pumped_every_file_pump_frames_to_the_same_bins(triad_cfg, tmp_path):
    """Log files replayed as fast as possible pump every FILE_PUMP frames (the array
    path's cost is per batch); the bins and counts are those of pumps every PUMP frames,
    on the array path and the per-frame path alike."""
    frames = _sim(triad_cfg, n=110)
    path = tmp_path / "a.blf"
    write_log(path, frames)
    assert len(frames) > 2 * FILE_PUMP >= 16 * PUMP
    big, small, per_frame = (make_ingest(triad_cfg) for _ in range(3))
    got = [_key(batch) for batch in replay(path, big)]
    want = [_key(batch) for batch in replay(path, small, pump_every=PUMP)]
    assert len(got) == len(frames) // FILE_PUMP + 1  # the full batches, then the flush
    assert len(want) >= len(frames) // PUMP
    assert sum(got, []) == sum(want, [])
    assert sum(got, []) == sum((_key(b) for b in replay(path, per_frame, arrays=False)), [])
    assert big.listener.stats() == small.listener.stats() == per_frame.listener.stats()
    assert big.binner.stats() == small.binner.stats()


def test_reader_process_stops_when_the_consumer_does(demo_cfg, tmp_path):
    from gyrostand.can.logs.reader import ReaderProcess

    path = tmp_path / "sim.blf"
    n = write_log(path, _sim(demo_cfg, n=60, drift_rate=200))
    reader = ReaderProcess([path], batch=64)
    it = iter(reader)
    first = next(it)
    assert len(first) == 64 and reader.returncode is None
    it.close()  # e.g. the replay loop raised
    assert reader.returncode is not None
    full = ReaderProcess([path], batch=1000)
    sizes = [len(b) for b in full]
    assert sum(sizes) == n == full.frames and full.returncode == 0
    assert all(s == 1000 for s in sizes[:-1])


def test_reader_process_reports_errors_with_the_file(demo_cfg, tmp_path, caplog):
    from gyrostand.can.logs.reader import ReaderProcess

    with pytest.raises(CanEdgeError, match="nope.blf: log file not found"):
        list(ReaderProcess([tmp_path / "nope.blf"]))
    path = tmp_path / "sim.blf"
    frames = _sim(demo_cfg, n=30)
    with Recorder(path, max_container_size=2048) as rec:  # many objects, as a long run has
        for f in frames:
            rec.on_message_received(f)
    whole = path.read_bytes()
    path.write_bytes(whole[:-750])  # torn inside the last object: read up to it, warned
    caplog.clear()
    damage = LogDamage()
    want = [m.timestamp for m in read_log(path, damage)]
    assert damage.truncated == 1 and "cut short inside" in caplog.text
    caplog.clear()
    reader = ReaderProcess([path], batch=50)
    got = [f for b in reader for f in b]
    assert 0 < len(got) < len(frames)
    assert [f[0] for f in got] == want
    assert "cut short inside" in caplog.text  # logged here, by the reader
    assert reader.damage.truncated == 1
    bad = bytearray(whole)
    bad[len(bad) // 2: len(bad) // 2 + 64] = b"X" * 64  # damage inside: skipped, counted
    path.write_bytes(bytes(bad))
    damage = LogDamage()
    inline = [m.timestamp for m in read_log(path, damage)]
    assert damage.containers >= 1 and 0 < len(inline) < len(frames)
    reader = ReaderProcess([path], batch=50)
    got = [f[0] for b in reader for f in b]
    assert got == inline and reader.damage.containers == damage.containers
    assert set(inline) <= {f.timestamp for f in frames}


@pytest.mark.parametrize("cores,size_limit,expect", [
    (2, 0, True), (1, 0, False), (2, 1 << 40, False)])
def test_replay_auto_uses_a_reader_process_for_large_logs_with_two_cores(
        demo_cfg, tmp_path, monkeypatch, caplog, cores, size_limit, expect):
    import logging

    from gyrostand.can import replay as replay_mod

    path = tmp_path / "sim.blf"
    write_log(path, _sim(demo_cfg, n=5))
    monkeypatch.setattr(replay_mod, "_cores", lambda: cores)
    monkeypatch.setattr(replay_mod, "PARALLEL_MIN_BYTES", size_limit)
    with caplog.at_level(logging.INFO, logger="gyrostand.can.replay"):
        bins = [b for batch in replay(path, make_ingest(demo_cfg), arrays=False)
                for b in batch]
    assert len(bins) >= 5
    assert ("log parsed in a reader process" in caplog.text) == expect
    # a BLF read as arrays is parsed here whatever its size (cheaper than a process)
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="gyrostand.can.replay"):
        again = [b for batch in replay(path, make_ingest(demo_cfg), arrays=True)
                 for b in batch]
    assert again == bins
    assert "log parsed in a reader process" not in caplog.text
    assert "read as arrays" in caplog.text
