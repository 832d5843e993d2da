"""The frame catalogue: loads, round-trips every message, matches its generator."""

from __future__ import annotations

import importlib.util
import math

import cantools
import pytest
from canhelpers import DATA, ROOT

from gyrostand.can.bus import MODEL_TERM_BITS
from gyrostand.can.dbc import find_message, find_signal, load_dbc
from gyrostand.config import MODEL_TERMS
from gyrostand.errors import CanEdgeError

DBC = ROOT / "dbc" / "gyrostand.dbc"


def _sample_values(msg, mux_value=None):
    """A value for every signal active under ``mux_value``: mid-range, on the raw grid."""
    out = {}
    for s in msg.signals:
        if s.multiplexer_ids and mux_value not in s.multiplexer_ids:
            continue
        if s.is_multiplexer:
            out[s.name] = mux_value
        elif s.is_float:
            out[s.name] = 1.5
        else:
            lo = s.minimum if s.minimum is not None else 0
            hi = s.maximum if s.maximum is not None else 1
            raw = round(((lo + hi) / 2 - s.offset) / s.scale)
            out[s.name] = raw * s.scale + s.offset
    return out


@pytest.mark.parametrize("path", [DBC, DATA / "foreign.dbc"], ids=["ours", "foreign"])
def test_every_message_round_trips(path):
    db = cantools.database.load_file(str(path))
    n = 0
    for msg in db.messages:
        mux = next((s for s in msg.signals if s.is_multiplexer), None)
        mux_values = sorted({i for s in msg.signals for i in (s.multiplexer_ids or ())}) \
            if mux else [None]
        for mv in mux_values:
            values = _sample_values(msg, mv)
            decoded = msg.decode(msg.encode(values), decode_choices=False)
            assert decoded.keys() == values.keys()
            for k, v in values.items():
                assert math.isclose(decoded[k], v, rel_tol=1e-12, abs_tol=1e-12), (msg.name, k)
            n += 1
    assert n >= 4


def test_catalogue_shape():
    db = load_dbc(DBC)
    names = {m.name for m in db.messages}
    for g in (1, 2, 3):
        assert {f"GYRO_DRIFT_{g}", f"GYRO_TEMP_{g}", f"GS_RESULT_{g}",
                f"GS_SUMMARY_{g}"} <= names
    assert {"GS_STATUS", "GS_COMMAND", "GS_ACK"} <= names
    ids = [m.frame_id for m in db.messages]
    assert len(ids) == len(set(ids))
    drift = find_signal(db, "GYRO_DRIFT_1", "Drift")
    assert (drift.unit, drift.resolution, drift.minimum, drift.maximum) == \
        ("deg/h", 1e-5, -1000.0, 1000.0)
    temp = find_signal(db, "GYRO_TEMP_1", "Temperature")
    assert (temp.unit, temp.resolution) == ("degC", 0.01)
    value = find_signal(db, "GS_RESULT_1", "Value")
    assert (value.multiplexer, value.multiplexer_ids) == ("Kind", (0,))
    assert db.get_message_by_name("GS_RESULT_1").get_signal_by_name("Std").is_float
    # the command outranks every data frame in arbitration
    cmd = find_message(db, "GS_COMMAND")[0].frame_id
    assert cmd < min(m.frame_id for m in db.messages if m.name != "GS_COMMAND")


def test_generator_reproduces_committed_file():
    spec = importlib.util.spec_from_file_location("dbc_generate", ROOT / "dbc" / "generate.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.render() == DBC.read_text()


def test_model_term_bits_are_the_vocabulary():
    assert MODEL_TERM_BITS == MODEL_TERMS


def test_lookup_errors_name_what_exists(tmp_path):
    db = load_dbc(DATA / "foreign.dbc")
    with pytest.raises(CanEdgeError, match=r"both a standard and an extended"):
        find_message(db, 0x321)
    assert find_message(db, 0x321, extended=True)[0].name == "OTHER_EXT_321"
    assert find_message(db, 0x321, extended=False)[0].name == "IMU_Y_TEMP"
    with pytest.raises(CanEdgeError, match=r"'YTmp' is not a signal of message IMU_Y_TEMP .*"
                                           r"\(known: YStat, YTemp\)"):
        find_signal(db, "IMU_Y_TEMP", "YTmp")
    bad = tmp_path / "bad.dbc"
    bad.write_text("BO_ this is not a dbc")
    with pytest.raises(CanEdgeError, match=r"bad\.dbc: cannot load DBC"):
        load_dbc(bad)
