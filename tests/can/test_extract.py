"""The precompiled extractors (:mod:`gyrostand.can.receive.extract`) give cantools' values, to
the bit and of the same type, for every signal of every DBC the project ships or tests
with, and for a DBC of deliberately awkward layouts; the listener uses them."""

from __future__ import annotations

import random
from pathlib import Path

import can
import cantools
import pytest

from gyrostand.can.dbc import find_signal, load_dbc
from gyrostand.can.receive.extract import extractor
from gyrostand.can.receive.listener import DecodingListener
from gyrostand.can.routes import ChannelMap

ROOT = Path(__file__).resolve().parents[2]
DBCS = sorted([*ROOT.glob("dbc/*.dbc"), *ROOT.glob("tests/data/*.dbc")])

# big-endian signals of odd widths crossing bytes, signed and unsigned, scaled and
# offset; a 64-bit little-endian counter; float32/float64 in both byte orders; 1-bit
# flags at either end of the payload; a 12-byte (CAN FD) payload
AWKWARD = """VERSION ""
BO_ 2566869505 ODD_BE: 8 IMU
 SG_ RateBE13 : 5|13@0- (0.0125,-3.5) [-60|60] "deg/s" X
 SG_ TempBE11 : 20|11@0+ (0.25,-40) [-40|471.75] "degC" X
 SG_ Flag0 : 39|1@0+ (1,0) [0|1] "" X
 SG_ Odd17 : 38|17@0- (3e-05,0) [-2|2] "" X
 SG_ Last1 : 56|1@0+ (1,0) [0|1] "" X
BO_ 513 ODD_LE: 8 IMU
 SG_ Wide64 : 0|64@1+ (1,0) [0|0] "" X
BO_ 514 MIXED: 8 IMU
 SG_ LeOdd : 3|19@1- (0.001,0.5) [-300|300] "" X
 SG_ BeOdd : 39|7@0+ (2,1) [1|255] "" X
 SG_ BeSigned : 47|9@0- (1,0) [-256|255] "" X
BO_ 515 FLOATS: 12 IMU
 SG_ F32le : 0|32@1- (1,0) [0|0] "" X
 SG_ F64be : 39|64@0- (0.5,1) [0|0] "" X
BO_ 516 CHOICE: 2 IMU
 SG_ State : 0|4@1+ (1,0) [0|15] "" X
 SG_ Scaled : 8|8@1+ (0.5,0) [0|127.5] "" X
SIG_VALTYPE_ 515 F32le : 1;
SIG_VALTYPE_ 515 F64be : 2;
VAL_ 516 State 0 "off" 1 "on" 5 "fault" ;
"""


def _databases():
    out = [(p.name, cantools.database.load_file(str(p))) for p in DBCS]
    out.append(("awkward", cantools.database.load_string(AWKWARD)))
    return out


def _plain_signals(message):
    return [s.name for s in message.signals
            if not s.multiplexer_ids and not s.is_multiplexer]


@pytest.mark.parametrize("name,db", _databases(), ids=[n for n, _ in _databases()])
def test_every_plain_signal_extracts_exactly_as_cantools(name, db):
    rng = random.Random(20261201)
    checked = 0
    for message in db.messages:
        if message.is_container or message.is_multiplexed():
            continue
        names = _plain_signals(message)
        if not names:
            continue
        for subset in [names, *([n] for n in names)]:  # the whole message and each alone
            decode = extractor(message, subset)
            assert decode is not None, f"{name}: {message.name} {subset} declined"
            for _ in range(500):
                data = bytes(rng.getrandbits(8) for _ in range(message.length))
                want = message.decode_simple(data, False)
                got = decode(data)
                for sig in subset:
                    a, b = got[sig], want[sig]
                    assert type(a) is type(b), (name, message.name, sig, a, b)
                    assert a == b or (a != a and b != b), (name, message.name, sig, data.hex())
                    checked += 1
    assert checked > 0


def test_multiplexed_messages_are_left_to_cantools():
    """cantools rejects a frame whose multiplexer value the DBC does not define, even for
    a plain signal beside it: such messages keep cantools' decode (and its rejections)."""
    db = cantools.database.load_file(str(ROOT / "tests/data/foreign.dbc"))
    muxed = [m for m in db.messages if m.is_multiplexed()]
    assert muxed, "foreign.dbc has a multiplexed message"
    for m in muxed:
        for sig in m.signals:
            assert extractor(m, [sig.name]) is None


def test_the_listener_decodes_an_awkward_layout_like_cantools(tmp_path):
    """Big-endian 13- and 11-bit signals on an extended id, through the real listener on
    the virtual bus path: every sample equals cantools' decode of its frame."""
    path = tmp_path / "awkward.dbc"
    path.write_text(AWKWARD)
    db = load_dbc(path)
    cdb = cantools.database.load_file(str(path), strict=False)
    msg = cdb.get_message_by_name("ODD_BE")
    drift = find_signal(db, "ODD_BE", "RateBE13")
    temp = find_signal(db, "ODD_BE", "TempBE11")
    listener = DecodingListener(db, ChannelMap(gyros=("g",), signals=((drift, temp),)))
    route = next(iter(listener._routes.values()))
    assert "extractor" in (route.decode.__code__.co_filename or "")
    rng = random.Random(7)
    want = []
    for k in range(2000):
        data = bytes(rng.getrandbits(8) for _ in range(8))
        d = msg.decode_simple(data, False)
        if not (-60 <= d["RateBE13"] <= 60):
            data = bytes([data[0] & 0xF0 | 0x0A, 0x80]) + data[2:]  # back into range
            d = msg.decode_simple(data, False)
        listener.on_message_received(can.Message(
            timestamp=1000.0 + 0.01 * k, arbitration_id=msg.frame_id,
            is_extended_id=True, data=data))
        want += [float(d["RateBE13"]), float(d["TempBE11"])]
    got = [s[3] for s in listener.drain()]
    assert got == want
