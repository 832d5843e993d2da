"""A DBC's value tables and validity signals are honoured (issue 28, finding 7), through
``gyrostand replay`` (array and per-frame paths) and ``init``:

- a raw value named in a ``VAL_`` table ``"NotAvailable"`` / ``"Error"`` is counted
  (``rejected.not_available``, ``decoder.not_available``) and never binned (before: samples
  at 1774.97 °C and 1759 °C, fits without a warning);
- a frame whose validity signal says ``invalid`` (``Rate_Status = 2``) is counted
  (``rejected.invalid``) and its drift dropped (before: a drift bin of 204.99);
- ``valid: {signal, accept}`` in the session drops every other value;
- ``init`` maps the validity signal and names the codes."""

from __future__ import annotations

import json

import can
import cantools
import pytest
import yaml

from gyrostand import exitcodes
from gyrostand.cli import main as cli_main

from .procs import DBC, simulated_session

TEMP = ' SG_ Temperature : 0|16@1- (0.01,0) [-60|150] "degC" GYROSTAND'
WIDE = ' SG_ Temperature : 0|16@1- (0.01,0) [-60|400] "degC" GYROSTAND'
COUNTER = ' SG_ Counter : 32|8@1+ (1,0) [0|255] "" GYROSTAND'
STATUS = COUNTER + '\n SG_ Rate_Status : 40|4@1+ (1,0) [0|15] "" GYROSTAND'
VALS = ('VAL_ 272 Temperature 32767 "NotAvailable" 32000 "Error" ;\n'
        'VAL_ 256 Rate_Status 0 "valid" 1 "degraded" 2 "invalid" ;\n')


@pytest.fixture(scope="module")
def stand(tmp_path_factory):
    """The demo session on a DBC with temperature codes and a drift status signal, and a
    log where every 7th temperature frame carries a code and every 11th drift frame is
    marked invalid with a drift of 204.99, every 13th (other) one degraded."""
    tmp = tmp_path_factory.mktemp("codes")
    cfg_path, frames = simulated_session(tmp, duration=300)
    text = DBC.read_text(encoding="cp1252")
    text = text.replace(TEMP, WIDE).replace(COUNTER, STATUS, 1)
    text = text.replace("BA_DEF_ ", VALS + "BA_DEF_ ", 1) if "BA_DEF_ " in text else text + VALS
    dbc = tmp / "codes.dbc"
    dbc.write_text(text)
    db = cantools.database.load_file(str(dbc))
    d = yaml.safe_load(cfg_path.read_text())
    d["dbc"] = str(dbc)
    cfg = tmp / "codes.yaml"
    cfg.write_text(yaml.safe_dump(d))
    out, k_t, k_d = [], 0, 0
    n = {"code": 0, "invalid": 0, "degraded": 0}
    for f in frames:
        f = can.Message(timestamp=f.timestamp, arbitration_id=f.arbitration_id,
                        is_extended_id=f.is_extended_id, data=bytes(f.data))
        if f.arbitration_id == 0x110:
            k_t += 1
            if k_t % 7 == 0:
                v = db.decode_message(0x110, f.data, decode_choices=False)
                v["Temperature"] = 327.67 if k_t % 14 == 0 else 320.0  # raw 32767 / 32000
                f.data = bytearray(db.encode_message(0x110, v))
                n["code"] += 1
        elif f.arbitration_id == 0x100:
            k_d += 1
            v = db.decode_message(0x100, f.data, decode_choices=False)
            if k_d % 11 == 0:
                v["Drift"], v["Rate_Status"] = 204.99, 2
                n["invalid"] += 1
            elif k_d % 13 == 0:
                v["Rate_Status"] = 1
                n["degraded"] += 1
            f.data = bytearray(db.encode_message(0x100, v))
        out.append(f)
    log = tmp / "codes.blf"
    with can.Logger(str(log)) as lg:
        for f in out:
            lg.on_message_received(f)
    return tmp, cfg, log, n, len(out)


def _replay(cfg, log, out, capsys, *extra):
    rc = cli_main(["replay", str(cfg), str(log), "--out", str(out), "--json", *extra])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    doc = json.loads(cap.out)
    from pathlib import Path

    run = Path(doc["run_dir"])
    return doc, (run / "az" / "samples.csv").read_bytes()


def _columns(samples: bytes) -> dict[str, list[float]]:
    lines = samples.decode().splitlines()
    head = lines[0].split(",")
    rows = [ln.split(",") for ln in lines[1:]]
    return {k: [float(r[i]) for r in rows if r[i]] for i, k in enumerate(head)}


@pytest.mark.parametrize("path", [[], ["--per-frame"]])
def test_codes_and_invalid_frames_are_counted_never_binned(stand, tmp_path, capsys, path):
    tmp, cfg, log, n, total = stand
    doc, samples = _replay(cfg, log, tmp_path, capsys, *path)
    dec = doc["stats"]["decoder"]
    assert dec["rejected"]["not_available"] == n["code"] > 100
    assert dec["not_available"] == n["code"]
    assert dec["rejected"]["invalid"] == n["invalid"] > 300
    assert dec["received"] == total
    cols = _columns(samples)
    assert max(cols["temp"]) < 50 and max(cols["drift"]) < 10  # no 320/327.67, no 204.99
    # degraded (1) is not named invalid: kept without a valid: key
    assert dec["samples"] == total - n["code"] - n["invalid"]


def test_the_array_and_per_frame_paths_agree(stand, tmp_path, capsys):
    tmp, cfg, log, n, total = stand
    a, sa = _replay(cfg, log, tmp_path / "a", capsys)
    b, sb = _replay(cfg, log, tmp_path / "b", capsys, "--per-frame")
    assert sa == sb
    assert a["stats"]["decoder"] == b["stats"]["decoder"]


def test_valid_accept_in_the_session_drops_every_other_value(stand, tmp_path, capsys):
    tmp, cfg, log, n, total = stand
    d = yaml.safe_load(cfg.read_text())
    d["gyros"][0]["drift"]["valid"] = {"signal": "Rate_Status", "accept": [0]}
    strict = tmp_path / "strict.yaml"
    strict.write_text(yaml.safe_dump(d))
    doc, _ = _replay(strict, log, tmp_path, capsys)
    assert doc["stats"]["decoder"]["rejected"]["invalid"] == n["invalid"] + n["degraded"]
    d["gyros"][0]["drift"]["valid"] = {"signal": "Nope", "accept": [0]}
    strict.write_text(yaml.safe_dump(d))
    assert cli_main(["run", str(strict), "--check"]) == exitcodes.CONFIG
    assert "gyros[0].drift.valid.signal: GYRO_DRIFT_1 has no signal 'Nope'" in \
        capsys.readouterr().err


def test_init_maps_the_validity_signal_and_names_the_codes(stand, tmp_path, capsys):
    tmp, cfg, log, n, total = stand
    out = tmp_path / "i.yaml"
    assert cli_main(["init", str(tmp / "codes.dbc"), "-o", str(out), "--listen-only"]) == 0
    text = out.read_text()
    assert "valid: {signal: Rate_Status, accept: [0, 1]}" in text
    assert ("# CHECK: GYRO_TEMP_1.Temperature codes 32000 Error, 32767 NotAvailable: "
            "counted (not_available), never binned") in text
    capsys.readouterr()
    assert cli_main(["run", str(out), "--check"]) == 0
    assert "frames dropped unless Rate_Status in {0, 1}" in capsys.readouterr().out
