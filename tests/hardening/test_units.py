"""Physical units are checked, not assumed (issue 28, finding 6), through ``gyrostand
replay`` / ``init`` / ``run --check``:

- the same frames with the temperature declared in K (offset 273.15), °F or mK, or the
  drift in rad/s, bin to the same °C / deg/h samples (to 1e-9) and the same fits (before:
  K used as °C gave beta 0.0062 / gamma -2.1e-5 instead of 0.054 / -1.6e-3);
- a session whose units already are degC / deg/h gives byte-identical samples.csv with
  and without an explicit ``session.drift_unit: deg/h``;
- a unit the project cannot convert is exit 78 (CONFIG) naming the key path, the signal and unit;
- ``init`` says which conversion it proposes."""

from __future__ import annotations

import csv
import json
import math

import pytest
import yaml

from gyrostand import exitcodes
from gyrostand.cli import main as cli_main

from .procs import DBC, simulated_session

DRIFT = ' SG_ Drift : 0|32@1- (1E-005,0) [-1000|1000] "deg/h" GYROSTAND'
TEMP = ' SG_ Temperature : 0|16@1- (0.01,0) [-60|150] "degC" GYROSTAND'
RAD = 1e-5 * math.pi / 180 / 3600
#: the same raw bits, declared in other units (physical = raw·scale + offset)
VARIANTS = {
    "K": (TEMP, ' SG_ Temperature : 0|16@1- (0.01,273.15) [213.15|423.15] "K" GYROSTAND'),
    "degK": (TEMP, ' SG_ Temperature : 0|16@1- (0.01,273.15) [213.15|423.15] "degK" X'),
    "°F": (TEMP, ' SG_ Temperature : 0|16@1- (0.018,32) [-76|302] "°F" GYROSTAND'),
    "mK": (TEMP, ' SG_ Temperature : 0|16@1- (10,273150) [213150|423150] "mK" GYROSTAND'),
    "rad/s": (DRIFT, f' SG_ Drift : 0|32@1- ({RAD!r},0) [-0.005|0.005] "rad/s" GYROSTAND'),
}


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("units")
    cfg_path, frames = simulated_session(tmp, duration=300)
    import can

    log = tmp / "stand.blf"
    with can.Logger(str(log)) as lg:
        for f in frames:
            lg.on_message_received(f)
    return tmp, cfg_path, log


def _variant(tmp, cfg_path, name, old, new, **session):
    text = DBC.read_text(encoding="cp1252")
    assert old in text
    dbc = tmp / f"{name.replace('/', '_').replace('°', 'deg')}.dbc"
    dbc.write_text(text.replace(old, new.replace(" X", " GYROSTAND")), encoding="utf-8")
    d = yaml.safe_load(cfg_path.read_text())
    d["dbc"] = str(dbc)
    d["session"].update(session)
    out = dbc.with_suffix(".yaml")
    out.write_text(yaml.safe_dump(d, allow_unicode=True), encoding="utf-8")
    return out


def _replay(cfg, log, out, capsys):
    rc = cli_main(["replay", str(cfg), str(log), "--out", str(out), "--json"])
    cap = capsys.readouterr()
    return rc, (json.loads(cap.out) if rc == 0 else None), cap.err


def _samples(doc):
    from pathlib import Path

    run = Path(doc["run_dir"])
    with open(run / "az" / "samples.csv") as f:
        return list(csv.DictReader(f)), (run / "az" / "samples.csv").read_bytes(), run


def test_units_are_converted_to_degc_and_the_drift_unit(session, tmp_path, capsys):
    tmp, cfg_path, log = session
    rc, base, err = _replay(cfg_path, log, tmp_path / "base", capsys)
    assert rc == 0, err
    want, want_bytes, run = _samples(base)
    ml = json.loads((run / "result.json").read_text())["gyros"]["az"]["fits"]["ml"]
    for name, (old, new) in VARIANTS.items():
        cfg = _variant(tmp, cfg_path, name, old, new, drift_unit="deg/h")
        rc, doc, err = _replay(cfg, log, tmp_path / name.replace("/", "_"), capsys)
        assert rc == 0, (name, err)
        got, _, grun = _samples(doc)
        assert len(got) == len(want) == 301
        for a, b in zip(got, want, strict=True):
            for k in ("drift", "temp"):
                assert float(a[k]) == pytest.approx(float(b[k]), abs=1e-9), (name, k)
        gml = json.loads((grun / "result.json").read_text())["gyros"]["az"]["fits"]["ml"]
        for p in ("markov.beta", "temp.gamma"):
            assert gml["parameters"][p]["value"] == pytest.approx(
                ml["parameters"][p]["value"], rel=1e-3), (name, p)  # ml optimum tol
        assert doc["stats"]["decoder"]["rejected_total"] == 0


def test_same_units_give_byte_identical_samples(session, tmp_path, capsys):
    tmp, cfg_path, log = session
    rc, a, err = _replay(cfg_path, log, tmp_path / "a", capsys)
    assert rc == 0, err
    explicit = _variant(tmp, cfg_path, "same", TEMP, TEMP, drift_unit="deg/h")
    rc, b, err = _replay(explicit, log, tmp_path / "b", capsys)
    assert rc == 0, err
    assert _samples(a)[1] == _samples(b)[1]


@pytest.mark.parametrize("signal, unit, path", [
    (TEMP, "V", "gyros[0].temperature.signal"),
    (TEMP, "deg/h", "gyros[0].temperature.signal"),
    (DRIFT, "degC", "gyros[0].drift.signal"),
    (DRIFT, "km/h", "gyros[0].drift.signal"),
])
def test_a_unit_that_cannot_be_converted_is_exit_78_naming_the_key(session, tmp_path,
                                                                  capsys, signal, unit, path):
    tmp, cfg_path, log = session
    cfg = _variant(tmp, cfg_path, f"bad-{unit}", signal,
                   signal.replace(signal.rsplit('"', 2)[1], unit))
    rc, _, err = _replay(cfg, log, tmp_path, capsys)
    assert rc == exitcodes.CONFIG
    assert f"{path}: " in err and f"unit {unit!r}" in err, err
    assert "Temperature" in err or "Drift" in err
    rc = cli_main(["run", str(cfg), "--check"])
    assert rc == exitcodes.CONFIG and f"{path}: " in capsys.readouterr().err


def test_an_unknown_drift_unit_is_refused(session, tmp_path, capsys):
    tmp, cfg_path, log = session
    cfg = _variant(tmp, cfg_path, "bad-session-unit", TEMP, TEMP, drift_unit="furlong")
    assert cli_main(["run", str(cfg), "--check"]) == exitcodes.CONFIG
    assert "session.drift_unit: drift unit 'furlong'" in capsys.readouterr().err


def test_init_and_check_say_the_conversion(session, tmp_path, capsys):
    tmp, cfg_path, log = session
    old, new = VARIANTS["K"]
    dbc = tmp_path / "k.dbc"
    dbc.write_text(DBC.read_text(encoding="cp1252").replace(old, new), encoding="utf-8")
    out = tmp_path / "k.yaml"
    assert cli_main(["init", str(dbc), "-o", str(out), "--listen-only"]) == 0
    text = out.read_text()
    assert ("# CHECK: temperature GYRO_TEMP_1.Temperature is converted at decode time: "
            "K -> degC (v - 273.15)") in text
    assert 'drift_unit: "deg/h"' in text
    capsys.readouterr()
    assert cli_main(["run", str(out), "--check"]) == 0
    assert "converted K -> degC (v - 273.15)" in capsys.readouterr().out
