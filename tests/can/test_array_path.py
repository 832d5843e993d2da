"""The array path of replay (issue 13's vectorized path) gives what the per-frame path
gives: array extractors equal to cantools on every mapped-able signal of every DBC in the
tests; DecodingListener.receive_arrays equal to receive_frames (bins to the bit, every
counter and rejection, held frames, clock steps, rolling counters, commands) on streams
with jitter, drops, bad frames of every kind, outliers, clock steps, NaN timestamps, a
tiny FIFO and J1939 PGN matching; and whole replays (run folders) with byte-identical
samples.csv and estimates.csv and the same stats, in this process and through the
reader process, on our DBC, the foreign layout and damaged logs."""

from __future__ import annotations

import filecmp
import math
import random
import struct
from pathlib import Path

import can
import cantools
import numpy as np
import pytest
from canhelpers import ROOT, make_ingest, smooth_truth
from test_extract import AWKWARD, DBCS, _plain_signals

from gyrostand.can.framesim import BadFrameInjector, FrameSimOptions, generate_frames, write_log
from gyrostand.can.logs.blfarray import FrameArrays
from gyrostand.can.logs.frames import frame_fields
from gyrostand.can.receive.extract import array_extractor
from gyrostand.can.recorder import Recorder
from gyrostand.can.routes import ChannelMap
from gyrostand.config import load_config, parse_config
from gyrostand.session.offline import run_replay

BENCH_DBC = ROOT / "benchmarks" / "data" / "foreign_triad.dbc"


# -- array extractors -----------------------------------------------------------------

def _all_databases():
    out = [(p.name, cantools.database.load_file(str(p))) for p in [*DBCS, BENCH_DBC]]
    out.append(("awkward", cantools.database.load_string(AWKWARD)))
    return out


@pytest.mark.parametrize("name,db", _all_databases(), ids=[n for n, _ in _all_databases()])
def test_array_extractors_equal_cantools(name, db):
    rng = random.Random(name)
    built = 0
    for msg in db.messages:
        if msg.is_multiplexed() or msg.length > 8:
            continue
        n = int(msg.length)
        payloads = [bytes(rng.getrandbits(8) for _ in range(n)) for _ in range(300)]
        payloads += [bytes(n), b"\xff" * n]
        arr = np.frombuffer(b"".join(p.ljust(8, b"\0") for p in payloads),
                            np.uint8).reshape(len(payloads), 8)
        want = [msg.decode_simple(p, False) for p in payloads]
        for sig in _plain_signals(msg):
            integer = type(msg.get_signal_by_name(sig).conversion).__name__ in (
                "IdentityConversion", "LinearIntegerConversion") and not \
                msg.get_signal_by_name(sig).is_float
            dec = array_extractor(msg, [sig])
            if msg.get_signal_by_name(sig).length == 64 and not \
                    msg.get_signal_by_name(sig).is_signed:
                assert dec is None  # uint64 beyond int64: declined, the scalar path decodes
                continue
            assert dec is not None, (msg.name, sig)
            got = dec(arr)[sig]
            assert got.dtype == np.float64
            assert [struct.pack("<d", x) for x in got.tolist()] == \
                [struct.pack("<d", float(w[sig])) for w in want], (msg.name, sig)
            if integer:
                deci = array_extractor(msg, [sig], ints=[sig])
                assert deci is not None
                assert deci(arr)[sig].tolist() == [int(w[sig]) for w in want]
            built += 1
    assert built >= 1


# -- the listener: receive_arrays == receive_frames ------------------------------------

TRIAD = load_config(ROOT / "configs" / "three-gyros.yaml")
DEMO = load_config(ROOT / "configs" / "demo.yaml")


def _frames(cfg, n=90, seed=1, drop=0.0, jitter=0.002, rate=50):
    cm = ChannelMap.from_config(cfg)
    return list(generate_frames(cfg.db, cm, [smooth_truth(n, k) for k in range(len(cm.gyros))],
                                FrameSimOptions(drift_rate=rate, temperature_rate=10,
                                                jitter=jitter, drop=drop, seed=seed)))


def _retime(f, t):
    return can.Message(timestamp=t, arbitration_id=f.arbitration_id,
                       is_extended_id=f.is_extended_id, data=bytes(f.data),
                       is_error_frame=f.is_error_frame, is_remote_frame=f.is_remote_frame,
                       dlc=f.dlc)


def _bits(bins):
    return [(b.gyro, b.k, struct.pack("<dddii", b.t, b.drift, b.temp, b.n_drift, b.n_temp))
            for b in bins]


def _feed(cfg, frames, batch, arrays, capacity=None, listener=None):
    ing = make_ingest(cfg, capacity)
    if listener is not None:
        ing.listener = listener
    batch = max(1, min(batch, ing.listener.frames_that_fit()))
    tuples = [frame_fields(f) for f in frames]
    took = [0]
    inner = ing.listener._receive_arrays

    def spy(fa):  # how many frames the array path decided (not the per-frame code)
        n = inner(fa)
        took[0] += n
        return n

    ing.listener._receive_arrays = spy  # type: ignore[method-assign]
    bins = []
    for i in range(0, len(tuples), batch):
        part = tuples[i:i + batch]
        if arrays:
            ing.listener.receive_arrays(FrameArrays.from_frames(part))
        else:
            ing.listener.receive_frames(part)
        bins += ing.pump()
    bins += ing.finish()
    lst = ing.listener
    _feed.took = took[0]  # type: ignore[attr-defined]
    return (_bits(bins), lst.stats(), dict(lst._last_counter), lst.last_timestamp,
            [(t, sorted(v.items())) for t, v in lst.pop_commands()])


def _same(cfg, frames, batch=256, capacity=None, make=None):
    a = _feed(cfg, frames, batch, False, capacity, make() if make else None)
    b = _feed(cfg, frames, batch, True, capacity, make() if make else None)
    # the array path decides most frames (the first of a log waits for a second one)
    assert _feed.took >= 0.5 * len(frames) - 2 * batch, (_feed.took, len(frames))  # type: ignore[attr-defined]
    assert b[1] == a[1]
    assert b[0] == a[0]
    assert b[2:] == a[2:]
    return a


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("batch", [1, 7, 256, 5000])
def test_clean_and_dropped_frames(seed, batch):
    frames = _frames(TRIAD, seed=seed, drop=0.02)
    bins, stats, *_ = _same(TRIAD, frames, batch)
    assert stats.samples > 0.95 * len(frames) and len(bins) >= 3 * 85
    assert stats.counter_jumps > 0  # the drops show in the rolling counters


@pytest.mark.parametrize("every", [7, 31])
def test_bad_frames_of_every_kind(every):
    inject = BadFrameInjector(TRIAD.db, ChannelMap.from_config(TRIAD), every=every)
    frames = list(inject(_frames(TRIAD, seed=4)))
    _, stats, *_ = _same(TRIAD, frames, 300)
    for reason, k in inject.expected.items():
        assert stats.rejected[reason] >= k, reason


def _mutate(frames, rng, kind):
    out = list(frames)
    n = len(out)
    if kind == "outliers":
        for i in rng.sample(range(10, n), 12):
            out[i] = _retime(out[i], out[i].timestamp + rng.choice([-1e5, 5e3, 50.0, -30.0]))
    elif kind in ("step", "step_back"):
        at = rng.randrange(n // 4, 3 * n // 4)
        delta = -300.0 if kind == "step_back" else rng.choice([-300.0, 7200.0, 12.5])
        out = out[:at] + [_retime(f, f.timestamp + delta) for f in out[at:]]
    elif kind == "nan":
        for i in rng.sample(range(n), 9):
            out[i] = _retime(out[i], rng.choice([math.nan, math.inf, -math.inf]))
    elif kind == "swaps":  # frames of one id out of order
        for i in rng.sample(range(n - 20), 15):
            j = next((j for j in range(i + 1, n) if out[j].arbitration_id ==
                      out[i].arbitration_id), None)
            if j is not None:
                out[i], out[j] = out[j], out[i]
    elif kind == "errors":
        for i in sorted(rng.sample(range(n), 40), reverse=True):
            f = out[i]
            out.insert(i, can.Message(timestamp=f.timestamp, is_error_frame=True,
                                      arbitration_id=f.arbitration_id, dlc=8,
                                      data=bytes(8)))
    elif kind == "commands":  # the daemon's command frames, some malformed
        cmd = TRIAD.db.get_message_by_name("GS_COMMAND")
        for i in sorted(rng.sample(range(n), 10), reverse=True):
            data = bytes(rng.getrandbits(8) for _ in range(cmd.length))
            if rng.random() < 0.3:
                data = data[:2]
            out.insert(i, can.Message(timestamp=out[i].timestamp,
                                      arbitration_id=cmd.frame_id, data=data))
    return out


@pytest.mark.parametrize("kind", ["outliers", "step", "nan", "swaps", "errors", "commands"])
@pytest.mark.parametrize("seed", range(3))
def test_timing_and_odd_frames(kind, seed):
    rng = random.Random(f"{kind}{seed}")
    frames = _mutate(_frames(TRIAD, n=60, seed=seed), rng, kind)
    _same(TRIAD, frames, rng.choice([64, 500, 2000]))


def test_a_tiny_fifo():
    frames = _frames(DEMO, n=40, seed=2)
    _, stats, *_ = _same(DEMO, frames, 1000, capacity=50)
    assert stats.rejected["overflow"] == 0


def test_foreign_layout():
    cfg = load_config(ROOT / "tests" / "data" / "foreign.yaml")
    inject = BadFrameInjector(cfg.db, ChannelMap.from_config(cfg), every=23)
    _same(cfg, list(inject(_frames(cfg, n=50, seed=3))), 400)


def test_j1939_pgn_match_and_hint():
    fog = ROOT / "tests" / "data" / "fog1a_j1939.dbc"
    for match in ("pgn", None):
        d = {"session": {"name": "fog"}, "bus": {"interface": "virtual"}, "dbc": str(fog),
             "gyros": [{"name": "fog",
                        "drift": {"message": "FOG_RATE", "signal": "Angular_Rate",
                                  "counter": "Rolling_Counter"},
                        "temperature": {"message": "FOG_HOUSEKEEPING",
                                        "signal": "Sensor_Temperature"},
                        "model": ["markov", "temp"]}]}
        if match:
            d["match"] = match
        cfg = parse_config(d, source="fog.yaml", base_dir=fog.parent)
        frames = _frames(cfg, n=30, seed=5)
        moved = [_retime(f, f.timestamp) for f in frames]
        for f in moved[::3]:  # another source address and priority
            f.arbitration_id = (f.arbitration_id & ~0xFF & ~(7 << 26)) | 0x42 | (6 << 26)
        _, stats, *_ = _same(cfg, moved, 200)
        if match:
            assert stats.rejected["unknown_id"] == 0 and stats.samples > 0
        else:
            assert stats.rejected["unknown_id"] > 0


# -- whole replays: run folders byte for byte ------------------------------------------

def _replay(cfg, path, tmp_path, monkeypatch, per_frame, parallel=None):
    monkeypatch.setenv("GYROSTAND_PER_FRAME", "1" if per_frame else "0")
    out = tmp_path / ("pf" if per_frame else "ar") / str(parallel)
    outcome = run_replay(cfg, path, out=out, parallel=parallel)
    return outcome


def _compare(a, b):
    for name in ("samples.csv", "estimates.csv"):
        fa, fb = a.run_dir / name, b.run_dir / name
        assert fa.is_file() == fb.is_file(), name
        if fa.is_file():
            assert filecmp.cmp(fa, fb, shallow=False), name
    for k in ("decoder", "binner", "log"):
        assert a.stats.get(k) == b.stats.get(k), k
    assert (a.stop_reason, a.state) == (b.stop_reason, b.state)


def _log(cfg, path, frames, container=None):
    if container is None:
        write_log(path, frames)
    else:
        with Recorder(path, max_container_size=container) as rec:
            for f in frames:
                rec.on_message_received(f)
    return path


@pytest.mark.parametrize("parallel", [None, True])
def test_replay_of_our_layout_with_bad_frames_and_a_step(tmp_path, monkeypatch, parallel):
    rng = random.Random(9)
    inject = BadFrameInjector(TRIAD.db, ChannelMap.from_config(TRIAD), every=41)
    frames = _mutate(list(inject(_frames(TRIAD, n=150, seed=6, drop=0.01))), rng,
                     "step_back")
    frames = _mutate(frames, rng, "errors")
    cfg = parse_config({**_raw(TRIAD), "session": {"name": "t", "output": str(tmp_path)}},
                       source=str(TRIAD.path), base_dir=TRIAD.path.parent)
    path = _log(cfg, tmp_path / "t.blf", frames, container=4096)
    a = _replay(cfg, path, tmp_path, monkeypatch, True, parallel)
    b = _replay(cfg, path, tmp_path, monkeypatch, False, parallel)
    _compare(a, b)
    assert a.stats["decoder"]["clock_steps"] == 1


def _raw(cfg):
    import yaml

    return yaml.safe_load(cfg.path.read_text())


def test_replay_of_the_foreign_layout_and_a_damaged_log(tmp_path, monkeypatch):
    cfg = load_config(ROOT / "tests" / "data" / "foreign.yaml")
    path = _log(cfg, tmp_path / "f.blf", _frames(cfg, n=120, seed=8, drop=0.01),
                container=2048)
    raw = bytearray(path.read_bytes())
    raw[len(raw) // 2:len(raw) // 2 + 40] = bytes(40)  # a damaged container mid-file
    bad = tmp_path / "bad.blf"
    bad.write_bytes(bytes(raw[:-100]))  # and cut short
    for p in (path, bad):
        for parallel in (None, True):
            a = _replay(cfg, p, tmp_path / p.stem, monkeypatch, True, parallel)
            b = _replay(cfg, p, tmp_path / p.stem, monkeypatch, False, parallel)
            _compare(a, b)
            if p is bad:
                assert a.stats["log"]["containers_skipped"] + a.stats["log"]["truncated"] >= 1


def test_replay_of_an_asc_log_and_several_files(tmp_path, monkeypatch):
    frames = _frames(DEMO, n=40, seed=3)
    asc = tmp_path / "d.asc"
    with can.ASCWriter(asc) as w:
        for f in frames[:len(frames) // 2]:
            w.on_message_received(f)
    blf = _log(DEMO, tmp_path / "d.blf", frames[len(frames) // 2:], container=1000)
    for parallel in (None, True):
        a = _replay(DEMO, [asc, blf], tmp_path, monkeypatch, True, parallel)
        b = _replay(DEMO, [asc, blf], tmp_path, monkeypatch, False, parallel)
        _compare(a, b)


def test_cli_replay_per_frame_gives_the_same_run(tmp_path, monkeypatch, capsys):
    import json
    import os

    from gyrostand.cli import main

    monkeypatch.delenv("GYROSTAND_PER_FRAME", raising=False)
    log = _log(TRIAD, tmp_path / "t.blf", _frames(TRIAD, n=60, seed=12, drop=0.01))
    results = []
    for extra in ([], ["--per-frame"]):
        assert main(["replay", str(TRIAD.path), str(log), "--out",
                     str(tmp_path / f"r{len(extra)}"), *extra]) == 0
        out = capsys.readouterr().out
        results.append(Path(next(line.split(None, 1)[1] for line in out.splitlines()
                                 if line.startswith("result:"))))
    assert os.environ.get("GYROSTAND_PER_FRAME") == "1"  # set by --per-frame
    monkeypatch.delenv("GYROSTAND_PER_FRAME")
    a, b = (json.loads(p.read_text()) for p in results)
    assert a["stats"]["decoder"] == b["stats"]["decoder"]
    for g in ("x", "y", "z"):
        assert (results[0].parent / g / "samples.csv").read_bytes() == \
            (results[1].parent / g / "samples.csv").read_bytes()


def test_reader_process_sends_the_same_frames_as_arrays(tmp_path):
    from gyrostand.can.logs.reader import ReaderProcess
    from gyrostand.errors import CanEdgeError

    path = _log(TRIAD, tmp_path / "r.blf", _frames(TRIAD, n=40, seed=13), container=3000)
    raw = bytearray(path.read_bytes())
    raw[len(raw) // 3:len(raw) // 3 + 60] = bytes(60)
    bad = tmp_path / "bad.blf"
    bad.write_bytes(bytes(raw[:-50]))
    for p in (path, bad):
        tuples = ReaderProcess([p], batch=333)
        want = [(struct.pack("<d", t), k, f, bytes(d)) for b in tuples for t, k, f, d in b]
        arrays = ReaderProcess([p], batch=333, arrays=True)
        batches = list(arrays)
        assert all(isinstance(b, FrameArrays) for b in batches)
        assert [len(b) for b in batches[:-1]] == [333] * (len(batches) - 1)
        got = [(struct.pack("<d", t), k, f, d) for b in batches for t, k, f, d in b.frames()]
        assert got == want and len(got) > 1000
        assert arrays.damage.as_dict() == tuples.damage.as_dict()
        assert arrays.frames == tuples.frames == len(want)
        assert (tuples.damage.total > 0) == (p is bad)
    with pytest.raises(CanEdgeError, match=r"nope\.blf: log file not found"):
        list(ReaderProcess([tmp_path / "nope.blf"], arrays=True))
