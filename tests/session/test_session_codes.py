"""Code numbers come from the DBC's value tables: a DBC with another numbering is encoded
(and its commands obeyed) with its own numbers; a missing entry or a mask wider than its
signal is refused at load, naming the message, the signal and the entry."""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path

import cantools
import pytest
from sessionhelpers import DEMO, demo_dict, make_cfg, run_virtual

from gyrostand.can.bus import (
    ACK_REASONS,
    COMMANDS,
    IDENTIFIER_CODES,
    STATE_CODES,
    STATUS_CODES,
    FrameEncoder,
)
from gyrostand.can.codes import SIGNAL_NAMES
from gyrostand.config import parse_config
from gyrostand.core.registry import names
from gyrostand.errors import CanEdgeError, ConfigError
from gyrostand.session.offline import simulated_frames

ROOT = Path(__file__).resolve().parents[2]
DBC = ROOT / "dbc" / "gyrostand.dbc"
CODED = ("Identifier", "Status", "State", "Command", "Result", "Reason")
_VAL = re.compile(r"^VAL_ (\d+) (\w+) (.*) ;$")


def _rewrite_tables(text: str, change) -> str:
    """``text`` with each value table of a coded signal replaced by ``change(signal,
    [(number, name), ...])``; everything else (every frame layout) byte for byte."""
    out = []
    for line in text.splitlines(keepends=True):
        m = _VAL.match(line.rstrip("\n"))
        if m and m.group(2) in CODED:
            pairs = [(int(n), s) for n, s in re.findall(r'(\d+) "([^"]*)"', m.group(3))]
            new = change(m.group(2), pairs)
            body = " ".join(f'{n} "{s}"' for n, s in new)
            line = f"VAL_ {m.group(1)} {m.group(2)} {body} ;\n"
        out.append(line)
    return "".join(out)


def _rotated(signal: str, pairs: list[tuple[int, str]]) -> list[tuple[int, str]]:
    """Every name moves to the next name's number (none keeps its own)."""
    numbers = [n for n, _ in pairs]
    return [(numbers[(i + 1) % len(pairs)], s) for i, (_, s) in enumerate(pairs)]


@pytest.fixture(scope="module")
def permuted(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("permuted") / "permuted.dbc"
    p.write_text(_rewrite_tables(DBC.read_text(), _rotated))
    return p


def _tables(db, names_of=lambda c: {str(v): int(k) for k, v in c.items()}):
    return {(m.name, s.name): names_of(s.choices) for m in db.messages for s in m.signals
            if s.name in CODED and s.choices}


def test_the_project_dbc_carries_every_table_and_the_module_constants_are_its_numbers():
    db = cantools.database.load_file(str(DBC))
    t = _tables(db)
    assert t[("GS_RESULT_1", "Identifier")] == t[("GS_SUMMARY_3", "Identifier")] == \
        IDENTIFIER_CODES
    assert list(IDENTIFIER_CODES) == list(names())  # the registry's identifiers, in order
    assert t[("GS_SUMMARY_1", "Status")] == STATUS_CODES
    assert t[("GS_STATUS", "State")] == STATE_CODES
    assert t[("GS_ACK", "Reason")] == ACK_REASONS
    assert t[("GS_ACK", "Result")] == {"ack": 0, "nack": 1}
    assert {v: k for k, v in t[("GS_COMMAND", "Command")].items()} == COMMANDS
    for role, signals in SIGNAL_NAMES.items():  # every name the daemon needs is there
        msg = {"result": "GS_RESULT_2", "summary": "GS_SUMMARY_2", "status": "GS_STATUS",
               "command": "GS_COMMAND", "ack": "GS_ACK"}[role]
        for sig, need in signals.items():
            need = need() if callable(need) else need
            assert set(need) <= set(t[(msg, sig)]), (msg, sig)


def test_a_permuted_dbc_changes_only_the_value_tables(permuted):
    a = cantools.database.load_file(str(DBC))
    b = cantools.database.load_file(str(permuted))
    for ma in a.messages:
        mb = b.get_message_by_name(ma.name)
        assert (ma.frame_id, ma.length) == (mb.frame_id, mb.length)
        for sa in ma.signals:
            sb = mb.get_signal_by_name(sa.name)
            assert (sa.start, sa.length, sa.byte_order, sa.is_signed, sa.scale, sa.offset,
                    sa.minimum, sa.maximum, sa.multiplexer_ids) == \
                (sb.start, sb.length, sb.byte_order, sb.is_signed, sb.scale, sb.offset,
                 sb.minimum, sb.maximum, sb.multiplexer_ids), (ma.name, sa.name)
    ta, tb = _tables(a), _tables(b)
    assert ta.keys() == tb.keys()
    for key in ta:  # same names, every one on another number
        assert set(ta[key]) == set(tb[key])
        assert all(ta[key][n] != tb[key][n] for n in ta[key]), key


def test_frames_carry_the_numbers_of_the_dbc_they_are_encoded_with(permuted):
    db = cantools.database.load_file(str(permuted))
    enc = FrameEncoder(db)

    def named(f, msg):
        return db.get_message_by_name(msg).decode(f.data, decode_choices=True)

    for ident in names():
        for f in enc.result_frames("GS_RESULT_1", ident, [0.03, -0.01], [0.001, 0.002], 7):
            assert str(named(f, "GS_RESULT_1")["Identifier"]) == ident
        for status in STATUS_CODES:
            d = named(enc.summary_frame("GS_SUMMARY_1", ident, status, ["markov", "temp"],
                                        100, 0.01), "GS_SUMMARY_1")
            assert (str(d["Identifier"]), str(d["Status"])) == (ident, status)
            assert d["ModelTerms"] == 0b11
    for state in STATE_CODES:
        page0 = enc.status_frames("GS_STATUS", state, 3, bins=1, gaps=0, decoded=1,
                                  rejected=0, bus_errors=0, late=0)[0]
        assert str(named(page0, "GS_STATUS")["State"]) == state
    for reason in ACK_REASONS:
        d = named(enc.ack_frame("GS_ACK", 2, 5, reason == "ok", reason), "GS_ACK")
        assert (str(d["Reason"]), str(d["Result"])) == \
            (reason, "ack" if reason == "ok" else "nack")
    for code, command in COMMANDS.items():
        f = enc.command_frame("GS_COMMAND", command, 1)
        raw = db.get_message_by_name("GS_COMMAND").decode(f.data, decode_choices=False)
        assert str(named(f, "GS_COMMAND")["Command"]) == command
        assert raw["Command"] != code  # the permuted number, not the project's
        assert enc.command_name("GS_COMMAND", raw["Command"]) == command
    assert enc.command_name("GS_COMMAND", 200) is None


def test_a_daemon_on_a_permuted_dbc_obeys_its_commands_and_labels_its_frames(tmp_path,
                                                                           permuted):
    cfg = make_cfg(tmp_path, duration=240.0, rate=10.0, period=10.0, lkf={"warmup": 60},
                   dbc=str(permuted))
    frames = list(simulated_frames(cfg))
    half = next(i for i, f in enumerate(frames) if f.timestamp - frames[0].timestamp >= 20.0)
    start = FrameEncoder(cfg.db).command_frame(cfg.responses.command, "start", 9, 1,
                                               timestamp=frames[half - 1].timestamp)
    outcome, seen_frames, _ = run_virtual(cfg, frames[:half] + [start] + frames[half:],
                                          start_idle=True)
    # "start" then the stand's "stop", both understood in the permuted numbering
    assert outcome.stop_reason == "stop command"
    db = cfg.db

    def seen(name):
        m = db.get_message_by_name(name)
        return [m.decode(f.data, decode_choices=True) for f in seen_frames
                if f.arbitration_id == m.frame_id and not f.is_extended_id]

    acks = {a["Sequence"]: str(a["Result"]) for a in seen("GS_ACK")}
    assert acks == {9: "ack", 1: "ack"}
    states = [str(d["State"]) for d in seen("GS_STATUS") if d["Page"] == 0]
    # (whether a beat falls in the idle part depends on how the frames were batched)
    assert "running" in states and set(states) <= set(STATE_CODES)
    summaries = seen("GS_SUMMARY_1")
    labels = {str(d["Identifier"]) for d in summaries}
    assert labels == {"lkf", "lsq", "ml"}  # ml: the final fit's round
    doc = json.loads(outcome.result_json.read_text())
    online = doc["gyros"]["az"]["online"]
    last = {str(d["Identifier"]): str(d["Status"]) for d in summaries}
    assert last["lkf"] == online["lkf"]["status"] and last["lsq"] == online["lsq"]["status"]


def _cfg_with(tmp_path, text: str, **gyro):
    p = tmp_path / "mine.dbc"
    p.write_text(text)
    d = copy.deepcopy(demo_dict())
    d["dbc"] = str(p)
    d["gyros"][0].update(gyro)
    return lambda: parse_config(d, source="t.yaml", base_dir=DEMO.parent)


def test_a_value_table_lacking_a_name_is_refused_at_load_naming_it(tmp_path):
    def drop(name):
        return lambda sig, pairs: [(n, s) for n, s in pairs if s != name]

    load = _cfg_with(tmp_path, _rewrite_tables(DBC.read_text(), drop("ml")))
    with pytest.raises(ConfigError, match=r"t\.yaml: gyros\[0\]\.result\.message: .*message "
                       r"GS_RESULT_1 signal Identifier: its value table \(VAL_\) lacks ml "
                       r"\(it has: 0 'lkf', 1 'lsq'\)"):
        load()
    load = _cfg_with(tmp_path, _rewrite_tables(DBC.read_text(), drop("rate_limited")))
    with pytest.raises(ConfigError, match=r"responses\.ack: .*message GS_ACK signal Reason: "
                       r"its value table \(VAL_\) lacks rate_limited"):
        load()
    load = _cfg_with(tmp_path, _rewrite_tables(DBC.read_text(), drop("snapshot")))
    with pytest.raises(ConfigError, match=r"responses\.command: .*GS_COMMAND signal Command: "
                       r"its value table \(VAL_\) lacks snapshot"):
        load()


def test_a_code_outside_its_signal_s_range_is_refused_at_load(tmp_path):
    def far(sig, pairs):
        return [(7 if s == "ml" else n, s) for n, s in pairs] if sig == "Identifier" else pairs

    load = _cfg_with(tmp_path, _rewrite_tables(DBC.read_text(), far))
    with pytest.raises(ConfigError, match=r"GS_RESULT_1 signal Identifier: value\(s\) ml = 7 "
                       r"outside the signal's range \[0, 2\]"):
        load()


def test_a_model_terms_mask_wider_than_its_signal_is_refused_at_load_and_never_saturated(
        tmp_path):
    narrow = DBC.read_text().replace(
        'SG_ ModelTerms : 8|16@1+ (1,0) [0|65535] "" STAND',
        'SG_ ModelTerms : 8|8@1+ (1,0) [0|255] "" STAND')
    # trend is bit 8: one past an 8-bit signal
    load = _cfg_with(tmp_path, narrow, model=["markov", "temp", "trend"], identifiers=["ml"])
    with pytest.raises(ConfigError, match=r"gyros\[0\]\.result\.summary: .*GS_SUMMARY_1 "
                       r"signal ModelTerms \(8 bits, max 255\) cannot carry the model markov, "
                       r"temp, trend \(mask 0x103 needs 9 bits\)"):
        load()
    assert _cfg_with(tmp_path, narrow, model=["markov", "temp", "hysteresis"],
                     identifiers=["lkf", "ml"])()  # bit 7 fits
    enc = FrameEncoder(cantools.database.load_string(narrow))
    with pytest.raises(CanEdgeError, match="cannot carry the model markov, trend"):
        enc.summary_frame("GS_SUMMARY_1", "ml", "ok", ["markov", "trend"], 10, 0.1)


def test_a_gyro_s_identifier_options_come_from_the_registry_and_its_lkf_section():
    from gyrostand.core.options import LkfOptions, LsqOptions, MlOptions

    d = copy.deepcopy(demo_dict())
    d["gyros"][0]["lkf"] = {"beta0": 0.02, "variant": "paper"}
    g = parse_config(d, source="t.yaml", base_dir=DEMO.parent).gyros[0]
    assert g.options("lkf") is g.lkf and g.lkf == LkfOptions(beta0=0.02, variant="paper")
    assert g.options("lsq") == LsqOptions() and g.options("ml") == MlOptions()
    with pytest.raises(Exception, match="unknown identifier 'kf'"):
        g.options("kf")
