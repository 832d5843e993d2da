"""The payload packers (:mod:`gyrostand.can.pack`) give cantools' bytes for every message of
every DBC the project ships or tests with (multiplexed ones included) and of a DBC of
awkward layouts; a value outside the scheme is left to cantools; the encoder's frames
are cantools' frames."""

from __future__ import annotations

import random

import cantools
import pytest
from test_extract import AWKWARD, DBCS

from gyrostand.can.bus import FrameEncoder
from gyrostand.can.pack import draws, packer

MUXED = """VERSION ""
BO_ 768 RESULT: 8 GYROSTAND
 SG_ Kind M : 0|4@1+ (1,0) [0|1] "" STAND
 SG_ Identifier : 4|4@1+ (1,0) [0|2] "" STAND
 SG_ Value m0 : 16|32@1- (1,0) [-3.4E+038|3.4E+038] "" STAND
 SG_ Std m1 : 16|32@1- (1,0) [0|3.4E+038] "" STAND
 SG_ BeCount m1 : 55|9@0- (1,0) [-256|255] "" STAND
SIG_VALTYPE_ 768 Value : 1;
SIG_VALTYPE_ 768 Std : 1;
"""


def _databases():
    out = [(p.name, cantools.database.load_file(str(p))) for p in DBCS]
    out += [(p.name, cantools.database.load_file(str(p))) for p in
            sorted(DBCS[0].parents[1].glob("benchmarks/data/*.dbc"))]
    out.append(("awkward", cantools.database.load_string(AWKWARD)))
    out.append(("muxed", cantools.database.load_string(MUXED)))
    return out


@pytest.mark.parametrize("name,db", _databases(), ids=[n for n, _ in _databases()])
def test_every_message_packs_exactly_as_cantools(name, db):
    rng = random.Random(20261203)
    for message in db.messages:
        pack = packer(message)
        if message.is_container:
            assert pack is None
            continue
        assert pack is not None, f"{name}: {message.name} declined"
        packed = 0
        for values in draws(message, rng, 300):
            got = pack(values)
            if got is None:
                continue
            packed += 1
            assert got == bytes(message.encode(values, strict=False)), (
                name, message.name, values)
        assert packed >= 200, (name, message.name, packed)  # the packer, not cantools


def test_values_outside_the_scheme_are_left_to_cantools():
    db = cantools.database.load_string(MUXED)
    msg = db.get_message_by_name("RESULT")
    pack = packer(msg)
    assert pack is not None
    ok = {"Kind": 1.0, "Identifier": 2.0, "Std": 0.5, "BeCount": -3.0}
    assert pack(ok) == bytes(msg.encode(ok, strict=False))
    assert pack({**ok, "Identifier": 16.0}) is None  # beyond 4 bits: bitstruct raises
    assert pack({**ok, "BeCount": -257.0}) is None
    assert pack({**ok, "Std": 1e39}) is None  # beyond float32: bitstruct stores inf
    assert pack({**ok, "Kind": 3.0}) is None  # no branch: cantools refuses
    assert pack({"Kind": 0.0, "Identifier": 1.0}) is None  # a signal missing: cantools
    # ... while the encoder still gives cantools' frame, or cantools' refusal
    enc = FrameEncoder(db)
    frame = enc.encode("RESULT", {"Kind": 1, "Identifier": 2, "Std": 1e39, "BeCount": 7})
    assert bytes(frame.data) == bytes(msg.encode(
        enc.signal_values("RESULT", {"Kind": 1, "Identifier": 2, "Std": 1e39,
                                     "BeCount": 7})[1], strict=False))


@pytest.mark.parametrize("name,db", _databases(), ids=[n for n, _ in _databases()])
def test_the_encoder_gives_cantools_frames(name, db):
    """FrameEncoder.encode on random physical values (saturated and rounded by
    signal_values) packs what cantools packs from the same signal values."""
    rng = random.Random(7)
    enc = FrameEncoder(db)
    for message in db.messages:
        if message.is_container:
            continue
        for values in draws(message, rng, 50):
            noisy = {k: (v * rng.uniform(0.9, 1.1) if v == v else v)
                     for k, v in values.items()}
            try:
                msg, data = enc.signal_values(message.name, noisy)
            except Exception:  # noqa: BLE001 - e.g. NaN in an integer signal
                continue
            try:
                want = bytes(message.encode(data, strict=False))
            except Exception:  # noqa: BLE001
                with pytest.raises(Exception):  # noqa: B017, PT011
                    enc.encode(message.name, noisy)
                continue
            assert bytes(enc.encode(message.name, noisy).data) == want


def _reference_signal_values(msg, signals):
    """FrameEncoder.signal_values as it was written per frame (before it was compiled
    per message): the reference the compiled one is held to."""
    import math

    from gyrostand.errors import CanEdgeError

    by_name = {s.name: s for s in msg.signals}
    unknown = set(signals) - set(by_name)
    if unknown:
        raise CanEdgeError(f"message {msg.name} has no signal(s) {sorted(unknown)}")
    values: dict[str, float] = {}

    def value(sig) -> float:
        if sig.name in values:
            return values[sig.name]
        v = signals.get(sig.name)
        if v is None:
            v = sig.initial if sig.initial is not None else 0
        v = float(v)
        if not math.isnan(v):
            if sig.minimum is not None:
                v = max(v, float(sig.minimum))
            if sig.maximum is not None:
                v = min(v, float(sig.maximum))
        if not sig.is_float:
            if math.isnan(v):
                raise CanEdgeError(f"{msg.name}.{sig.name}: NaN in an integer signal")
            v = int(round((v - sig.offset) / sig.scale)) * sig.scale + sig.offset
        values[sig.name] = v
        return v

    def active(sig) -> bool:
        if not sig.multiplexer_ids:
            return True
        mux = by_name[sig.multiplexer_signal]
        return active(mux) and int(value(mux)) in sig.multiplexer_ids

    return {s.name: value(s) for s in msg.signals if active(s)}


@pytest.mark.parametrize("name,db", _databases(), ids=[n for n, _ in _databases()])
def test_signal_values_as_written_per_frame(name, db):
    """The compiled signal_values gives the per-frame reference's dict (keys, order, values,
    types) or its error, on random partial inputs: NaN, ±inf, out of range, ints, a
    multiplexer value selecting no branch, an unknown signal."""
    rng = random.Random(11)
    enc = FrameEncoder(db)
    specials = [float("nan"), float("inf"), -float("inf"), 0, -0.0, 1e300, -1e300, 3, 0.5]
    for message in db.messages:
        if message.is_container:
            continue
        names = [s.name for s in message.signals]
        for values in draws(message, rng, 60):
            given = {k: v for k, v in values.items() if rng.random() < 0.7}
            for k in list(given):
                r = rng.random()
                if r < 0.15:
                    given[k] = rng.choice(specials)
                elif r < 0.3:
                    given[k] = given[k] * rng.uniform(-3, 3) if given[k] == given[k] else 1.0
            if rng.random() < 0.1 and names:
                given[rng.choice(names)] = rng.randint(0, 20)  # maybe no branch
            if rng.random() < 0.03:
                given["NoSuchSignal"] = 1.0
            try:
                want: object = _reference_signal_values(message, given)
            except Exception as exc:  # noqa: BLE001
                want = (type(exc), str(exc))
            try:
                got: object = enc.signal_values(message.name, given)[1]
            except Exception as exc:  # noqa: BLE001
                got = (type(exc), str(exc))
            assert repr(got) == repr(want), (name, message.name, given)
            if isinstance(got, dict):
                assert [type(v) for v in got.values()] == \
                    [type(v) for v in want.values()]  # type: ignore[attr-defined]
