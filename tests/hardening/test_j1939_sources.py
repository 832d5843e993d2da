"""J1939 source addresses are part of the device (issue 28, finding 8), through
``gyrostand replay`` and ``run --check``:

- two FOGs sending one PGN from source addresses 0x80 and 0x81 on a `match: pgn` mapping:
  a warning at once naming the second address, its frames counted
  (``rejected.second_source``) and never merged into the first device's bins, and exit 65
  (before: every bin averaged both, n_drift 40, drift ≈ 5; only ``counter_jumps`` hinted);
- ``source_address:`` on each gyro's channel: two gyros, each with its own device's bins;
- one address mapped: the other device's frames are ignored and counted (``other_source``).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import can
import cantools
import numpy as np
import pytest
import yaml

from gyrostand import exitcodes
from gyrostand.cli import main as cli_main

DBC = Path(__file__).resolve().parents[1] / "data" / "fog2_j1939pg.dbc"
RATE, TEMP = 0x0CFF2180, 0x18FF2280  # FOG2_RATE / FOG2_TEMP as the DBC has them (SA 0x80)
LEVEL = {0x80: 0.5, 0x81: 10.0}  # deg/h of each device


@pytest.fixture(scope="module")
def stand(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("j1939")
    db = cantools.database.load_file(str(DBC))
    rate, temp = db.get_message_by_name("FOG2_RATE"), db.get_message_by_name("FOG2_TEMP")
    rng = np.random.default_rng(8)
    frames = []
    t0 = 1_700_000_000.0
    for k in range(300 * 20):
        t = t0 + k / 20
        for sa in (0x80, 0x81):
            v = {"AngularRate": LEVEL[sa] + 0.01 * rng.standard_normal(),
                 "RateCounter": k % 16}
            frames.append(can.Message(timestamp=t + 0.001 * (sa - 0x80),
                                      arbitration_id=(RATE & ~0xFF) | sa,
                                      is_extended_id=True, data=rate.encode(v)))
        if k % 2 == 0:
            frames.append(can.Message(timestamp=t + 0.005, arbitration_id=TEMP,
                                      is_extended_id=True,
                                      data=temp.encode({"FogTemp": 20 + k / 600})))
    log = tmp / "two-fogs.blf"
    with can.Logger(str(log)) as lg:
        for f in frames:
            lg.on_message_received(f)
    return tmp, log


def _session(tmp, name, gyros):
    d = {"session": {"name": name, "output": str(tmp / "runs")},
         "bus": {"interface": "virtual"}, "dbc": str(DBC), "gyros": gyros}
    p = tmp / f"{name}.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def _gyro(name, sa=None):
    drift = {"message": "FOG2_RATE", "signal": "AngularRate", "match": "pgn"}
    if sa is not None:
        drift["source_address"] = sa
    return {"name": name, "drift": drift, "model": ["markov", "temp", "bias"],
            "temperature": {"message": "FOG2_TEMP", "signal": "FogTemp", "match": "pgn"},
            "identifiers": ["lsq"]}


def _replay(cfg, log, out, capsys):
    rc = cli_main(["replay", str(cfg), str(log), "--out", str(out), "--json"])
    cap = capsys.readouterr()
    return rc, json.loads(cap.out), cap.err


def _drift(doc, gyro):
    with open(Path(doc["run_dir"]) / gyro / "samples.csv") as f:
        rows = list(csv.DictReader(f))
    return [float(r["drift"]) for r in rows if r["drift"]], \
        [int(r["n_drift"]) for r in rows]


def test_two_devices_on_one_pgn_mapping_are_never_merged(stand, tmp_path, capsys, caplog):
    tmp, log = stand
    cfg = _session(tmp, "merged", [_gyro("fog")])
    rc, doc, err = _replay(cfg, log, tmp_path, capsys)
    assert rc == exitcodes.DATAERR
    assert "second J1939 source address" in err and "source_address:" in err
    assert "J1939 PGN 0xFF21 from a second source address 0x81 (the first was 0x80)" \
        in caplog.text
    assert doc["stats"]["decoder"]["rejected"]["second_source"] == 6000
    drift, n = _drift(doc, "fog")
    assert max(abs(v - 0.5) for v in drift) < 0.05  # the first device only (not ≈ 5)
    assert max(n) <= 21
    assert doc["stats"]["decoder"]["counter_jumps"] == 0


def test_each_address_mapped_gives_each_gyro_its_device(stand, tmp_path, capsys):
    tmp, log = stand
    cfg = _session(tmp, "pinned", [_gyro("a", 0x80), _gyro("b", 0x81)])
    capsys.readouterr()
    assert cli_main(["run", str(cfg), "--check"]) == 0
    assert "from source address 0x81" in capsys.readouterr().out
    rc, doc, err = _replay(cfg, log, tmp_path, capsys)
    assert rc == 0, err
    for g in ("a", "b"):
        drift, n = _drift(doc, g)
        assert len(drift) >= 299
        assert max(abs(v - LEVEL[0x80 if g == "a" else 0x81]) for v in drift) < 0.05
    dec = doc["stats"]["decoder"]
    assert dec["rejected_total"] == 0 and dec["counter_jumps"] == 0


def test_one_address_mapped_ignores_and_counts_the_other(stand, tmp_path, capsys):
    tmp, log = stand
    cfg = _session(tmp, "one", [_gyro("a", 0x81)])
    rc, doc, err = _replay(cfg, log, tmp_path, capsys)
    assert rc == 0, err
    dec = doc["stats"]["decoder"]
    assert dec["other_source"] == 6000 and dec["rejected_total"] == 0
    drift, _ = _drift(doc, "a")
    assert max(abs(v - 10.0) for v in drift) < 0.05


def test_source_address_needs_match_pgn_and_one_owner(stand, tmp_path, capsys):
    tmp, _ = stand
    g = _gyro("a", 0x80)
    g["drift"]["match"] = "id"
    assert cli_main(["run", str(_session(tmp, "bad1", [g])), "--check"]) == exitcodes.CONFIG
    assert "gyros[0].drift.source_address: needs match: pgn" in capsys.readouterr().err
    cfg = _session(tmp, "bad2", [_gyro("a", 0x80), _gyro("b", 0x80)])
    assert cli_main(["run", str(cfg), "--check"]) == exitcodes.CONFIG
    assert "gyros[1].drift.signal: FOG2_RATE.AngularRate is already mapped by gyros[0]" \
        in capsys.readouterr().err
    cfg = _session(tmp, "bad3", [_gyro("a", 0x80), _gyro("b")])
    assert cli_main(["run", str(cfg), "--check"]) == exitcodes.CONFIG
    assert "FOG2_RATE is matched by pgn with source_address" in capsys.readouterr().err
