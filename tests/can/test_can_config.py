"""Session config: the shipped configs load; every error names the file and key path."""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import pytest
import yaml
from canhelpers import DATA, ROOT

from gyrostand.config import load_config, parse_config
from gyrostand.errors import ConfigError

DEMO = ROOT / "configs" / "demo.yaml"


def test_demo_config(demo_cfg):
    cfg = demo_cfg
    assert cfg.name == "demo"
    assert cfg.dbc_path == (ROOT / "dbc" / "gyrostand.dbc").resolve()
    assert cfg.output == (ROOT / "runs").resolve()
    assert dict(cfg.bus) == {"interface": "virtual", "channel": "gyrostand-demo",
                             "preserve_timestamps": True}
    (g,) = cfg.gyros
    assert (g.name, g.model, g.identifiers) == ("az", ("markov", "temp"), ("lkf", "lsq", "ml"))
    assert (g.drift.signal.message.frame_id, g.drift.signal.name) == (0x100, "Drift")
    assert g.drift.counter.name == "Counter"
    assert g.result.values.name == "GS_RESULT_1" and g.result.summary.name == "GS_SUMMARY_1"
    assert cfg.responses.command.frame_id == 0x0F0 and cfg.responses.period == 10.0
    sim = cfg.simulate
    assert sim.temperature == ((0, 20), (500, 45), (1000, 45), (2000, 35))
    assert dict(sim.gyros["az"].params)["markov.beta"] == 0.0333
    assert (sim.drift_rate, sim.temperature_rate, sim.seed) == (100.0, 10.0, 42)
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.name = "x"
    with pytest.raises(TypeError):
        cfg.bus["channel"] = "other"


def test_three_gyros_and_ids(triad_cfg):
    assert [g.name for g in triad_cfg.gyros] == ["x", "y", "z"]
    y = triad_cfg.gyro("y")
    assert y.drift.signal.message.name == "GYRO_DRIFT_2"  # given as 0x101


def test_foreign_config(foreign_cfg):
    x, y = foreign_cfg.gyros
    assert x.drift.signal.message.is_extended and x.drift.signal.message.frame_id == 0x18FF5001
    assert (x.drift.signal.multiplexer, x.drift.signal.multiplexer_ids) == ("MuxSel", (1,))
    assert x.temperature.signal.multiplexer_ids == (2,)
    assert y.temperature.signal.message.name == "IMU_Y_TEMP"
    assert foreign_cfg.dbc_path == (DATA / "foreign.dbc").resolve()
    assert foreign_cfg.simulate is None


class _NoAliases(yaml.SafeDumper):
    def ignore_aliases(self, data):
        return True


def _demo() -> dict:
    return yaml.safe_load(DEMO.read_text())


def _check(tmp_path: Path, mutate, match: str) -> None:
    data = copy.deepcopy(_demo())
    mutate(data)
    path = tmp_path / "configs" / "bad.yaml"
    path.parent.mkdir(exist_ok=True)
    (tmp_path / "dbc").mkdir(exist_ok=True)
    (tmp_path / "dbc" / "gyrostand.dbc").write_text((ROOT / "dbc" / "gyrostand.dbc").read_text())
    path.write_text(yaml.dump(data, Dumper=_NoAliases))  # session files refuse aliases
    with pytest.raises(ConfigError, match=match):
        load_config(path)


def _second_gyro(d):
    g = copy.deepcopy(d["gyros"][0])
    g["name"] = "el"
    g["drift"] = {"message": "GYRO_DRIFT_2", "signal": "Drft"}
    g["temperature"] = {"message": "GYRO_TEMP_2", "signal": "Temperature"}
    d["gyros"].append(g)


CASES = {
    "signal name": (_second_gyro,
                    r"bad\.yaml: gyros\[1\]\.drift\.signal: 'Drft' is not a signal of message "
                    r"GYRO_DRIFT_2 in \.\./dbc/gyrostand\.dbc \(known: Drift, Counter\)"),
    "message name": (lambda d: d["gyros"][0]["temperature"].update(message="GYRO_TMP"),
                     r"gyros\[0\]\.temperature\.message: 'GYRO_TMP' is not a message in "
                     r"\.\./dbc/gyrostand\.dbc \(known: .*GYRO_TEMP_1"),
    "frame id": (lambda d: d["gyros"][0]["drift"].update(message=0x7AB),
                 r"gyros\[0\]\.drift\.message: no message with frame id 0x7AB"),
    "unknown top key": (lambda d: d.update(sampeling={"dt": 1}),
                        r"bad\.yaml: sampeling: unknown key \(allowed here: session, bus"),
    "unknown nested key": (lambda d: d["sampling"].update(dT=2),
                           r"sampling\.dT: unknown key \(allowed here: dt, epoch"),
    "model term": (lambda d: d["gyros"][0].update(model=["markov", "tmp"]),
                   r"gyros\[0\]\.model\[1\]: 'tmp' is not one of: markov, temp, white"),
    "identifier": (lambda d: d["gyros"][0].update(identifiers=["lkf", "ekf"]),
                   r"gyros\[0\]\.identifiers\[1\]: 'ekf' is not one of: lkf, lsq, ml"),
    "dt": (lambda d: d["sampling"].update(dt=0),
           r"sampling\.dt: must be >= 0.01, got 0"),
    "dt type": (lambda d: d["sampling"].update(dt="fast"),
                r"sampling\.dt: expected a number, got str 'fast'"),
    "missing key": (lambda d: d["gyros"][0].pop("drift"),
                    r"gyros\[0\]\.drift: missing required key"),
    "dbc missing": (lambda d: d.update(dbc="nowhere.dbc"),
                    r"dbc: .*nowhere\.dbc: DBC file not found"),
    "duplicate gyro": (lambda d: d["gyros"].append(copy.deepcopy(d["gyros"][0])),
                       r"gyros\[1\]\.name: 'az' repeats gyros\[0\]"),
    "result signals": (lambda d: d["gyros"][0]["result"].update(message="GS_STATUS"),
                       r"gyros\[0\]\.result\.message: message GS_STATUS lacks signal\(s\) "
                       r"Kind, Identifier, Param"),
    "counter": (lambda d: d["gyros"][0]["drift"].update(counter="Cnt"),
                r"gyros\[0\]\.drift\.counter: 'Cnt' is not a signal of message GYRO_DRIFT_1"),
    "bus not a mapping": (lambda d: d.update(bus=["virtual"]),
                          r"bus: expected a mapping of can\.Bus arguments, got list"),
    "bus interface": (lambda d: d["bus"].update(interface=5),
                      r"bus\.interface: expected a non-empty string, got int 5"),
    "bus key": (lambda d: d["bus"].update({"rx queue": 5}),
                r"bus\.rx queue: not a can\.Bus argument name \(expected an identifier\)"),
    "node": (lambda d: d["responses"].update(node=300),
             r"responses\.node: must be in \[0, 254\], got 300"),
    "sim rate": (lambda d: d["simulate"]["rates"].update(drift=5000),
                 r"simulate\.rates\.drift: must be <= 1000, got 5000"),
    "sim jitter": (lambda d: d["simulate"].update(jitter=0.02),
                   r"simulate\.jitter: 0\.02 s must stay below half the shortest frame period"),
    "sim profile": (lambda d: d["simulate"]["temperature"].append([1500, 30]),
                    r"simulate\.temperature\[4\]: times must increase, 1500 after 2000"),
    "sim gyro": (lambda d: d["simulate"]["gyros"].update(el=d["simulate"]["gyros"]["az"]),
                 r"simulate\.gyros\.el: unknown key \(allowed here: az\)"),
    "sim param": (lambda d: d["simulate"]["gyros"]["az"]["params"].update({"bias.b": 1.0}),
                  r"simulate\.gyros\.az\.params\.bias\.b: term 'bias' is not in "
                  r"simulate\.gyros\.az\.model"),
    "sim param form": (lambda d: d["simulate"]["gyros"]["az"]["params"].update(beta=1.0),
                       r"simulate\.gyros\.az\.params\.beta: expected '<term>\.<param>'"),
    "clash": (lambda d: d["gyros"].append({**copy.deepcopy(d["gyros"][0]), "name": "el"}),
              r"gyros\[1\]\.drift\.signal: GYRO_DRIFT_1\.Drift is already mapped by "
              r"gyros\[0\]\.drift\.signal"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_errors_name_the_key_path(tmp_path, case):
    mutate, match = CASES[case]
    _check(tmp_path, mutate, match)


def test_yaml_and_file_errors(tmp_path):
    p = tmp_path / "broken.yaml"
    p.write_text("session: {name: [unclosed\n")
    with pytest.raises(ConfigError, match=r"broken\.yaml: invalid YAML"):
        load_config(p)
    with pytest.raises(ConfigError, match=r"missing\.yaml: cannot read config"):
        load_config(tmp_path / "missing.yaml")
    with pytest.raises(ConfigError, match=r"<top>: expected a mapping, got list"):
        parse_config([1, 2], base_dir=ROOT)
    assert issubclass(ConfigError, ValueError)


def test_ambiguous_frame_id_needs_extended(tmp_path):
    data = yaml.safe_load((DATA / "foreign.yaml").read_text())
    data["gyros"][1]["temperature"].pop("extended")
    with pytest.raises(ConfigError, match=r"gyros\[1\]\.temperature\.message: frame id 0x321 "
                                          r"is both a standard and an extended message"):
        parse_config(data, source="foreign.yaml", base_dir=DATA)
